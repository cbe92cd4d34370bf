#!/usr/bin/env python3
"""The ROS 2 side of benchmarks/ros2.py, as plain rclpy (run with the ROS 2 environment).

``echo``: republish /bench/direct/ping (String) on /bench/direct/pong, and
/bench/direct/image (Image) on /bench/direct/image_back — the plain rclpy round trip.
``measure``: send pings and frames through both paths (direct: via the echo node; bridged:
ROS 2 → bridge → bus → echo on the bus → bridge → ROS 2) and print the round trips as JSON.
``react``: the robot of the reaction trials: publish a violating ``/bench/level``
(std_msgs/Float64) and time until Utu's tactic calls its ``/bench/set_safe``
(std_srvs/Trigger) through the bridge; then publish a nominal level and let the manager see
it; print the times as JSON (the first trial's apart: it includes the service's discovery).
Both stamps are this process's.
Everything reliable, keep last 100 (the bridge reads the frames best effort, as sensor data).
"""

from __future__ import annotations

import argparse
import functools
import json
import threading
import time
from typing import Any

import rclpy
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import Float64, String
from std_srvs.srv import Trigger

QOS = QoSProfile(depth=100)


#: The executors ``--executor`` picks from: ``multi`` (MultiThreadedExecutor, 2 threads),
#: ``single`` (SingleThreadedExecutor), ``events`` (rclpy.experimental.EventsExecutor).
#: ``single``, as the bridge: benchmarks/ros2_probe.py measured it fastest (docs/results.md).
EXECUTORS = ("multi", "single", "events")
EXECUTOR = "single"


def make_executor(kind: str) -> Any:
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor()
    if kind == "single":
        return SingleThreadedExecutor()
    return MultiThreadedExecutor(num_threads=2)


def spin(node: Node, kind: str) -> Any:
    executor = make_executor(kind)
    executor.add_node(node)
    threading.Thread(target=executor.spin, daemon=True).start()
    return executor


def echo(args: argparse.Namespace) -> None:
    node = rclpy.create_node("bench_echo")
    pong = node.create_publisher(String, "/bench/direct/pong", QOS)
    back = node.create_publisher(Image, "/bench/direct/image_back", QOS)
    node.create_subscription(String, "/bench/direct/ping", pong.publish, QOS)
    node.create_subscription(Image, "/bench/direct/image", back.publish, QOS)
    spin(node, args.executor)
    stop = threading.Event()
    node.context.on_shutdown(stop.set)  # SIGINT/SIGTERM: rclpy's handlers shut the context
    print("echo ready", flush=True)
    stop.wait()


class Trip:
    """Send messages on one path and time their return."""

    def __init__(self, node: Node, out: str, back: str, out_type: type, back_type: type) -> None:
        self.sent: dict[str, float] = {}
        self.rtt: list[float] = []
        self.last = 0.0  # when the latest message came back (perf_counter)
        self.lock = threading.Lock()
        self.got = threading.Condition(self.lock)
        self.pub = node.create_publisher(out_type, out, QOS)
        self.sub = node.create_subscription(back_type, back, self.on_back, QOS)

    def key(self, msg: Any) -> str:
        data = getattr(msg, "data", None)
        if isinstance(data, str):
            return data
        return str(msg.header.frame_id)

    def on_back(self, msg: Any) -> None:
        now = time.perf_counter()
        with self.lock:
            t0 = self.sent.pop(self.key(msg), None)
            if t0 is not None:
                self.rtt.append((now - t0) * 1000.0)
                self.last = now
            self.got.notify_all()

    def send(self, key: str, msg: Any) -> None:
        with self.lock:
            self.sent[key] = time.perf_counter()
        self.pub.publish(msg)

    def wait_more(self, before: int, timeout: float) -> None:
        """Wait (``lock`` held) until more than ``before`` round trips are in."""
        self.got.wait_for(lambda: len(self.rtt) > before, timeout)

    def wait_connected(self, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.pub.get_subscription_count() > 0 and self.sub.get_publisher_count() > 0:
                return True
            time.sleep(0.05)
        return False


def frame(seq: int) -> Image:
    msg = Image(height=240, width=320, encoding="rgb8", is_bigendian=0, step=960)
    msg.data = bytes((seq + i) % 251 for i in range(256)) * 900
    msg.header.frame_id = str(seq)
    return msg


def ping_pong(trip: Trip, n: int, timeout: float) -> None:
    """One message in flight at a time: the round trip of a small message."""
    for i in range(n):
        with trip.lock:
            before = len(trip.rtt)
        trip.send(f"p{i}", String(data=f"p{i}"))
        with trip.lock:
            trip.wait_more(before, timeout)


def images(
    trip: Trip, n: int, rate: float, timeout: float, *, one_at_a_time: bool, first: int = 0
) -> float:
    """Send n frames, at ``rate`` Hz or one in flight at a time.

    Returns the seconds from the first frame sent to the last one back (not counting the
    wait for frames that never come back).
    """
    start = time.perf_counter()
    for k in range(n):
        i = first + k
        if one_at_a_time:
            with trip.lock:
                before = len(trip.rtt)
        else:
            delay = start + k / rate - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
        trip.send(str(i), frame(i))
        if one_at_a_time:
            with trip.lock:
                trip.wait_more(before, timeout)
    end = time.monotonic() + timeout
    with trip.lock:
        trip.got.wait_for(lambda: not trip.sent or time.monotonic() > end, timeout)
        return max(0.0, trip.last - start)


def measure(args: argparse.Namespace) -> None:
    node = rclpy.create_node("bench_measure")
    paths = {
        "direct_small": Trip(node, "/bench/direct/ping", "/bench/direct/pong", String, String),
        "direct_image": Trip(node, "/bench/direct/image", "/bench/direct/image_back", Image, Image),
    }
    if not args.direct_only:
        paths["bridged_small"] = Trip(
            node, "/bench/bridge/ping", "/bench/bridge/pong", String, String
        )
        paths["bridged_image"] = Trip(
            node, "/bench/bridge/image", "/bench/bridge/image_back", Image, CompressedImage
        )
    kinds = ("direct",) if args.direct_only else ("direct", "bridged")
    spin(node, args.executor)
    for name, trip in paths.items():
        if not trip.wait_connected(30):
            raise SystemExit(f"{name}: never connected")
    time.sleep(0.5)  # let the bus side's subscriptions settle before the first message
    out: dict[str, object] = {}
    for kind in kinds:
        name = f"{kind}_small"
        ping_pong(paths[name], args.small, 5.0)
        out[name] = paths[name].rtt
    for kind in kinds:
        name = f"{kind}_image"
        images(paths[name], args.images, args.rate, 10.0, one_at_a_time=True)
        out[name] = paths[name].rtt
    for kind in kinds:
        name = f"{kind}_image"
        trip = paths[name]
        with trip.lock:
            trip.rtt, trip.sent = [], {}
        took = images(trip, args.stream, args.rate, 10.0, one_at_a_time=False, first=1_000_000)
        with trip.lock:
            out[f"{name}_stream"] = {"rtt": list(trip.rtt), "sent": args.stream, "took_s": took}
    print(json.dumps(out), flush=True)


def _more(calls: list[int], n: int) -> bool:
    return len(calls) > n


def react(args: argparse.Namespace) -> None:
    node = rclpy.create_node("bench_robot")
    level = node.create_publisher(Float64, "/bench/level", QOS)
    lock = threading.Lock()
    called = threading.Condition(lock)
    calls: list[int] = []

    def set_safe(_request: Any, response: Any) -> Any:
        now = time.perf_counter_ns()
        with lock:
            calls.append(now)
            called.notify_all()
        response.success, response.message = True, "safe"
        return response

    node.create_service(Trigger, "/bench/set_safe", set_safe)
    spin(node, args.executor)
    end = time.monotonic() + 30
    while level.get_subscription_count() == 0 or node.count_clients("/bench/set_safe") == 0:
        if time.monotonic() > end:
            raise SystemExit("the bridge never subscribed to /bench/level nor became a client")
        time.sleep(0.05)
    pause = threading.Event()
    for _ in range(10):  # the manager sees a nominal robot before the first trial
        level.publish(Float64(data=0.0))
        pause.wait(0.05)
    pause.wait(1.0)
    latencies: list[float] = []
    lost = 0
    first: float | None = None
    # trial 0 warms up: the bridge's first call of /bench/set_safe still waits on the service's
    # discovery (its request and reply endpoints matching), so it is reported on its own
    for trial in range(args.trials + 1):
        with lock:
            before = len(calls)
        t0 = time.perf_counter_ns()
        level.publish(Float64(data=1.0))  # the violation
        with lock:
            got = called.wait_for(functools.partial(_more, calls, before), 5.0)
            t1 = calls[before] if got else None
        took = None if t1 is None else (t1 - t0) / 1e6
        if trial == 0:
            first = took
        elif took is None:
            lost += 1
        else:
            latencies.append(took)
        level.publish(Float64(data=0.0))
        pause.wait(0.3)  # the manager sees the robot nominal again before the next trial
    out = {"violation_to_call": latencies, "lost": lost, "first_call": first}
    print(json.dumps(out), flush=True)


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("mode", choices=["echo", "measure", "react"])
    p.add_argument("--trials", type=int, default=100)
    p.add_argument("--small", type=int, default=500)
    p.add_argument("--images", type=int, default=100)
    p.add_argument("--stream", type=int, default=300)
    p.add_argument("--rate", type=float, default=30.0)
    p.add_argument("--executor", choices=EXECUTORS, default=EXECUTOR)
    p.add_argument("--direct-only", action="store_true", help="measure: no bridged paths")
    args = p.parse_args()
    rclpy.init()
    try:
        if args.mode == "echo":
            echo(args)
        elif args.mode == "react":
            react(args)
        else:
            measure(args)
    finally:
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
