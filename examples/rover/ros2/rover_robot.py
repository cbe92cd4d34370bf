#!/usr/bin/env python3
"""The rover of the paper's Fig. 13 as ROS 2 nodes (rclpy): run it with the ROS 2 environment.

    .venv-ros2/bin/python examples/rover/ros2/rover_robot.py --dim-at 15

(scripts/setup-ros2.sh builds .venv-ros2; any Python that imports rclpy, e.g. after sourcing a
ROS 2 install's setup.bash, works too). One process, three nodes, as a real rover's drivers:

* ``rover_controller``: the controller state on ``/rover/controller/mode``
  (std_msgs/String), ``/rover/controller/buzzer_on``, ``/rover/controller/bumper``,
  ``/rover/controller/lights`` (std_msgs/Bool), which the bridge merges into the bus topic
  ``/rover/controller/state``; the services ``/rover/controller/manual`` (std_srvs/SetBool:
  true → manual, false → autonomous) and ``/rover/controller/stop`` (std_srvs/Trigger); the
  buzzer command ``/rover/controller/buzzer`` (std_msgs/Bool); and its own fail-safe: it
  subscribes to the manager's bridge's heartbeat ``/<--manager>/heartbeat`` with a
  liveliness lease (``--lease``, 1 s, the bridge's default) and, once it has seen the bridge
  alive, puts itself in manual mode (the robot's safe state) when the heartbeat's
  ``alive_count`` falls to 0: the bridge stopped, hung or was killed (``kill -9`` too), a
  lease after its last heartbeat;
* ``rover_camera``: ``/camera/image_raw`` (sensor_msgs/Image, 320×240 ``rgb8``, sensor-data
  QoS): a synthetic scene with a box that moves, dimmed after ``--dim-at`` seconds;
* ``rover_ultrasonic``: ``/ultrasonic/range`` (sensor_msgs/Range, ULTRASOUND, sensor-data
  QoS): 3 m, or 0.5 m between ``--near-from`` and ``--near-until``.

Each node reports on ``/diagnostics`` (diagnostic_msgs/DiagnosticArray) once a second, as ROS
2 drivers do: a status per node (``rover/controller``, ``rover/camera``,
``rover/ultrasonic``) with key/value pairs (mode, buzzer; luma, frames; range). The rover
prints one line per command, and ``rover ready`` once up; it stops on SIGINT/SIGTERM.
"""

from __future__ import annotations

import argparse
import signal
import threading
import time
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.duration import Duration
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import Image, Range
from std_msgs.msg import Bool, Empty, String
from std_srvs.srv import SetBool, Trigger

RELIABLE = QoSProfile(depth=4)


def diagnostics(node: Node, name: str, level: int, message: str, values: dict[str, Any]) -> Any:
    """One node's DiagnosticArray with one status and its key/value pairs."""
    array = DiagnosticArray()
    array.header.stamp = node.get_clock().now().to_msg()
    status = DiagnosticStatus(name=name, message=message, hardware_id=node.get_name())
    status.level = bytes([level])
    status.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
    array.status = [status]
    return array


class Controller(Node):
    """The controller: state, mode services, the buzzer, and the fail-safe on a lost manager."""

    def __init__(self, args: argparse.Namespace) -> None:
        super().__init__("rover_controller")
        self.args = args
        self.lock = threading.Lock()
        self.mode = "autonomous"
        self.buzzer = False
        self.manager_seen = False
        self.pubs = {
            name: self.create_publisher(cls, topic, RELIABLE)
            for name, cls, topic in (
                ("mode", String, "/rover/controller/mode"),
                ("buzzer_on", Bool, "/rover/controller/buzzer_on"),
                ("bumper", Bool, "/rover/controller/bumper"),
                ("lights", Bool, "/rover/controller/lights"),
            )
        }
        self.diag = self.create_publisher(DiagnosticArray, "/diagnostics", RELIABLE)
        self.create_service(SetBool, "/rover/controller/manual", self.on_manual)
        self.create_service(Trigger, "/rover/controller/stop", self.on_stop)
        self.create_subscription(Bool, "/rover/controller/buzzer", self.on_buzzer, RELIABLE)
        self.create_timer(1.0 / args.rate, self.tick)
        self.create_timer(1.0, self.report)
        if args.manager:
            # the bridge offers liveliness MANUAL_BY_TOPIC with its lease; asking for a lease
            # no shorter than it matches, and Fast DDS then counts the bridge dead this lease
            # after its last heartbeat
            heartbeat = QoSProfile(
                depth=1,
                reliability=ReliabilityPolicy.BEST_EFFORT,
                liveliness_lease_duration=Duration(seconds=args.lease),
            )
            events = SubscriptionEventCallbacks(
                liveliness=self.on_manager_liveliness, incompatible_qos=self.on_incompatible
            )
            topic = f"/{args.manager}/heartbeat"
            self.create_subscription(
                Empty, topic, lambda _msg: None, heartbeat, event_callbacks=events
            )

    def on_manual(self, request: Any, response: Any) -> Any:
        mode = "manual" if request.data else "autonomous"
        with self.lock:
            self.mode = mode
        print(f"set_mode {mode}: accepted", flush=True)
        response.success, response.message = True, mode
        return response

    def on_stop(self, _request: Any, response: Any) -> Any:
        print("stop", flush=True)
        response.success, response.message = True, "stopped"
        return response

    def on_buzzer(self, msg: Any) -> None:
        with self.lock:
            self.buzzer = bool(msg.data)
        print(f"buzzer {msg.data}", flush=True)

    def on_manager_liveliness(self, event: Any) -> None:
        if event.alive_count > 0:
            if not self.manager_seen:
                print(f"manager {self.args.manager} alive", flush=True)
            self.manager_seen = True
        elif self.manager_seen:
            self.manager_seen = False
            with self.lock:
                self.mode = "manual"
            print(f"manager {self.args.manager} gone: safe state manual", flush=True)

    def on_incompatible(self, _event: Any) -> None:
        print(
            f"manager {self.args.manager}'s heartbeat does not match: its lease is longer than "
            f"--lease {self.args.lease:g} s (the bridge file's 'heartbeat')",
            flush=True,
        )

    def tick(self) -> None:
        with self.lock:
            mode, buzzer = self.mode, self.buzzer
        self.pubs["mode"].publish(String(data=mode))
        self.pubs["buzzer_on"].publish(Bool(data=buzzer))
        self.pubs["bumper"].publish(Bool(data=False))
        self.pubs["lights"].publish(Bool(data=True))

    def report(self) -> None:
        with self.lock:
            values = {"mode": self.mode, "buzzer": self.buzzer}
        self.diag.publish(diagnostics(self, "rover/controller", 0, "running", values))


class Camera(Node):
    """The camera: a synthetic 320×240 scene, dimmed after ``--dim-at`` seconds."""

    def __init__(self, args: argparse.Namespace, start: float) -> None:
        super().__init__("rover_camera")
        self.args, self.start = args, start
        self.frames = 0
        self.light = 200
        self.pub = self.create_publisher(Image, "/camera/image_raw", qos_profile_sensor_data)
        self.diag = self.create_publisher(DiagnosticArray, "/diagnostics", RELIABLE)
        self.create_timer(1.0 / args.rate, self.tick)
        self.create_timer(1.0, self.report)

    def tick(self) -> None:
        t = time.monotonic() - self.start
        w, h = 320, 240
        dim = self.args.dim_at is not None and t >= self.args.dim_at
        self.light = light = 60 if dim else 200
        x0 = int(40 + (t * 40) % (w - 120))
        row = bytes([light // 2, light // 2, light]) * w
        box = bytes([light, light // 4, light // 4]) * 60
        rows = [
            row[: x0 * 3] + box + row[(x0 + 60) * 3 :] if 90 <= y < 150 else row for y in range(h)
        ]
        msg = Image(height=h, width=w, encoding="rgb8", is_bigendian=0, step=w * 3)
        msg.data = b"".join(rows)
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = "camera"
        self.pub.publish(msg)
        self.frames += 1

    def report(self) -> None:
        level = 1 if self.light < 90 else 0
        values = {"light": self.light, "frames": self.frames}
        message = "dim" if level else "ok"
        self.diag.publish(diagnostics(self, "rover/camera", level, message, values))


class Ultrasonic(Node):
    """The ultrasonic sensor: 3 m, or 0.5 m between ``--near-from`` and ``--near-until``."""

    def __init__(self, args: argparse.Namespace, start: float) -> None:
        super().__init__("rover_ultrasonic")
        self.args, self.start = args, start
        self.range = 3.0
        self.pub = self.create_publisher(Range, "/ultrasonic/range", qos_profile_sensor_data)
        self.diag = self.create_publisher(DiagnosticArray, "/diagnostics", RELIABLE)
        self.create_timer(1.0 / args.rate, self.tick)
        self.create_timer(1.0, self.report)

    def tick(self) -> None:
        a, t = self.args, time.monotonic() - self.start
        near = a.near_from is not None and a.near_from <= t < (a.near_until or float("inf"))
        self.range = 0.5 if near else 3.0
        msg = Range(radiation_type=Range.ULTRASOUND, field_of_view=0.5, min_range=0.02)
        msg.max_range, msg.range = 4.0, self.range
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = "ultrasonic"
        self.pub.publish(msg)

    def report(self) -> None:
        values = {"range": self.range}
        self.diag.publish(diagnostics(self, "rover/ultrasonic", 0, "ok", values))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rate", type=float, default=10.0, help="publications per second")
    p.add_argument("--dim-at", type=float, default=None, help="dim the camera after T s")
    p.add_argument("--near-from", type=float, default=None, help="something near from T s")
    p.add_argument("--near-until", type=float, default=None, help="... until T s")
    p.add_argument(
        "--manager",
        default="anunnaki_bridge",
        help="the manager's bridge (its file's name); its heartbeat lost puts the rover in "
        "manual ('': none)",
    )
    p.add_argument(
        "--lease",
        type=float,
        default=1.0,
        help="seconds without the bridge's heartbeat before the safe state (at least the "
        "bridge file's 'heartbeat', default 1)",
    )
    args = p.parse_args()
    if not 0 < args.lease < float("inf"):
        p.error(f"--lease must be a positive number of seconds, got {args.lease:g}")
    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    start = time.monotonic()
    nodes = [Controller(args), Camera(args, start), Ultrasonic(args, start)]
    executor = SingleThreadedExecutor()
    for node in nodes:
        executor.add_node(node)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())

    def spin() -> None:
        try:
            executor.spin()
        except ExternalShutdownException:
            pass
        finally:
            stop.set()

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    print("rover ready", flush=True)
    stop.wait()
    executor.shutdown(timeout_sec=5.0)
    for node in nodes:
        node.destroy_node()
    rclpy.try_shutdown()
    spinner.join(timeout=5.0)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
