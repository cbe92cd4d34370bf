#!/usr/bin/env python3
"""The ROS side of benchmarks/ros1.py, as plain rospy (run with Debian's python3).

``echo``: republish /bench/direct/ping (String) on /bench/direct/pong, and
/bench/direct/image (Image) on /bench/direct/image_back — the plain rospy round trip.
``measure``: send pings and frames through both paths (direct: via the echo node; bridged:
ROS → bridge → bus → echo on the bus → bridge → ROS) and print the round trips as JSON.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time

try:
    import rospy
except ImportError:
    sys.path.append("/usr/lib/python3/dist-packages")
    import rospy

from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import String


def echo() -> None:
    rospy.init_node("bench_echo")
    pong = rospy.Publisher("/bench/direct/pong", String, queue_size=100)
    back = rospy.Publisher("/bench/direct/image_back", Image, queue_size=100)
    rospy.Subscriber("/bench/direct/ping", String, pong.publish, queue_size=100)
    rospy.Subscriber("/bench/direct/image", Image, back.publish, queue_size=100)
    print("echo ready", flush=True)
    rospy.spin()


class Trip:
    """Send messages on one path and time their return."""

    def __init__(self, out: str, back: str, out_type: type, back_type: type) -> None:
        self.sent: dict[str, float] = {}
        self.rtt: list[float] = []
        self.lock = threading.Lock()
        self.got = threading.Condition(self.lock)
        self.pub = rospy.Publisher(out, out_type, queue_size=100)
        self.sub = rospy.Subscriber(back, back_type, self.on_back, queue_size=100)

    def key(self, msg: String | Image | CompressedImage) -> str:
        data = getattr(msg, "data", None)
        if isinstance(data, str):
            return data
        return str(msg.header.frame_id)  # rospy numbers header.seq itself

    def on_back(self, msg: String | Image | CompressedImage) -> None:
        now = time.perf_counter()
        with self.lock:
            t0 = self.sent.pop(self.key(msg), None)
            if t0 is not None:
                self.rtt.append((now - t0) * 1000.0)
            self.got.notify_all()

    def send(self, key: str, msg: String | Image) -> None:
        with self.lock:
            self.sent[key] = time.perf_counter()
        self.pub.publish(msg)

    def wait_more(self, before: int, timeout: float) -> None:
        """Wait (``lock`` held) until more than ``before`` round trips are in."""
        self.got.wait_for(lambda: len(self.rtt) > before, timeout)

    def wait_connected(self, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.pub.get_num_connections() > 0 and self.sub.get_num_connections() > 0:
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
    """Send n frames, at ``rate`` Hz or one in flight at a time; return the seconds it took."""
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
    return time.perf_counter() - start


def measure(args: argparse.Namespace) -> None:
    rospy.init_node("bench_measure")
    paths = {
        "direct_small": Trip("/bench/direct/ping", "/bench/direct/pong", String, String),
        "bridged_small": Trip("/bench/bridge/ping", "/bench/bridge/pong", String, String),
        "direct_image": Trip("/bench/direct/image", "/bench/direct/image_back", Image, Image),
        "bridged_image": Trip(
            "/bench/bridge/image", "/bench/bridge/image_back", Image, CompressedImage
        ),
    }
    for name, trip in paths.items():
        if not trip.wait_connected(30):
            raise SystemExit(f"{name}: never connected")
    time.sleep(0.5)  # let the bus side's subscriptions settle before the first message
    out: dict[str, object] = {}
    for name in ("direct_small", "bridged_small"):
        ping_pong(paths[name], args.small, 5.0)
        out[name] = paths[name].rtt
    for name in ("direct_image", "bridged_image"):
        images(paths[name], args.images, args.rate, 10.0, one_at_a_time=True)
        out[name] = paths[name].rtt
    for name in ("direct_image", "bridged_image"):
        trip = paths[name]
        with trip.lock:
            trip.rtt, trip.sent = [], {}
        took = images(trip, args.stream, args.rate, 10.0, one_at_a_time=False, first=1_000_000)
        with trip.lock:
            out[f"{name}_stream"] = {"rtt": list(trip.rtt), "sent": args.stream, "took_s": took}
    print(json.dumps(out), flush=True)


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("mode", choices=["echo", "measure"])
    p.add_argument("--small", type=int, default=500)
    p.add_argument("--images", type=int, default=100)
    p.add_argument("--stream", type=int, default=300)
    p.add_argument("--rate", type=float, default=30.0)
    args = p.parse_args(rospy.myargv()[1:])
    if args.mode == "echo":
        echo()
    else:
        measure(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
