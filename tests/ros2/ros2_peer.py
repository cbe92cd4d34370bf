"""The ROS 2 side of the live bridge tests: a plain rclpy node, run in the ROS 2 environment.

It echoes every ``/out/<name>`` topic back on ``/in/<name>`` (the bridge publishes the first
from the bus and carries the second to the bus, so one round trip tests both directions of
each mapped type), offers ``/peer/set_flag`` (``std_srvs/SetBool``) and
``/peer/change_state`` (``lifecycle_msgs/ChangeState``), and obeys ``/peer/command``:
``bad-image`` publishes an ``Image`` in an encoding the bridge does not convert on
``/in/image``; ``call-trigger`` calls the bridge's ``/bridge/trigger`` (a ROS service the
bridge answers from the bus) and publishes the reply on ``/peer/result``; ``call-chain``
calls the bridge's ``/bridge/set_flag`` (true), which the bridge answers from the bus
service that calls this peer's ``/peer/set_flag``, and publishes the reply likewise;
``incompatible`` declares a best-effort publisher on ``/in/string`` (whose bridge
subscription is reliable: the two cannot match) and says ``incompatible declared`` on
``/peer/result``. Publishers of sensor types use the sensor-data QoS (best effort), as
drivers do. It prints ``peer ready`` once everything is declared, and stops on SIGTERM.
"""

from __future__ import annotations

import signal
import sys
import threading
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, Twist
from lifecycle_msgs.srv import ChangeState
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from sensor_msgs.msg import BatteryState, CompressedImage, Image, NavSatFix, Range
from std_msgs.msg import Bool, Float32, Float64, Int32, Int64, String
from std_srvs.srv import SetBool, Trigger

#: name → (message class, whether drivers publish it best effort)
TYPES: dict[str, tuple[Any, bool]] = {
    "bool": (Bool, False),
    "string": (String, False),
    "int32": (Int32, False),
    "int64": (Int64, False),
    "float32": (Float32, False),
    "float64": (Float64, False),
    "image": (Image, True),
    "compressed": (CompressedImage, True),
    "range": (Range, True),
    "battery": (BatteryState, True),
    "fix": (NavSatFix, True),
    "twist": (Twist, False),
    "pose": (PoseStamped, False),
    "diagnostics": (DiagnosticArray, False),
}


def call(client: Any, request: Any) -> str:
    """Call a service of the bridge; its reply as ``"<success> <message>"``."""
    if not client.wait_for_service(timeout_sec=30.0):
        return f"no {client.srv_name}"
    done = threading.Event()
    future = client.call_async(request)
    future.add_done_callback(lambda _f: done.set())
    done.wait(30.0)
    reply = future.result()
    return "no reply" if reply is None else f"{reply.success} {reply.message}"


def main() -> int:
    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    node = rclpy.create_node("anunnaki_test_peer")
    group = ReentrantCallbackGroup()
    reliable = QoSProfile(depth=10)
    pubs: dict[str, Any] = {}
    for name, (cls, sensor) in TYPES.items():
        pub = node.create_publisher(
            cls, f"/in/{name}", qos_profile_sensor_data if sensor else reliable
        )
        pubs[name] = pub
        node.create_subscription(cls, f"/out/{name}", pub.publish, reliable, callback_group=group)
    result = node.create_publisher(String, "/peer/result", reliable)
    trigger = node.create_client(Trigger, "/bridge/trigger", callback_group=group)
    chain = node.create_client(SetBool, "/bridge/set_flag", callback_group=group)

    def set_flag(request: Any, response: Any) -> Any:
        response.success = bool(request.data)
        response.message = f"flag set to {request.data}"
        return response

    def change_state(request: Any, response: Any) -> Any:
        response.success = request.transition.id == 3  # activate
        return response

    kept: list[Any] = []  # what a command declared, alive until the peer stops

    def command(msg: Any) -> None:
        if msg.data == "bad-image":
            bad = Image(height=2, width=2, encoding="yuv422_16", step=8, data=b"\0" * 16)
            pubs["image"].publish(bad)
        elif msg.data == "call-trigger":
            result.publish(String(data=call(trigger, Trigger.Request())))
        elif msg.data == "call-chain":
            result.publish(String(data=call(chain, SetBool.Request(data=True))))
        elif msg.data == "incompatible":
            kept.append(node.create_publisher(String, "/in/string", qos_profile_sensor_data))
            result.publish(String(data="incompatible declared"))

    node.create_service(SetBool, "/peer/set_flag", set_flag, callback_group=group)
    node.create_service(ChangeState, "/peer/change_state", change_state, callback_group=group)
    node.create_subscription(String, "/peer/command", command, reliable, callback_group=group)
    executor = MultiThreadedExecutor(num_threads=4)
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
    print("peer ready", flush=True)
    stop.wait()
    executor.shutdown(timeout_sec=5.0)
    node.destroy_node()
    rclpy.try_shutdown()
    spinner.join(timeout=5.0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
