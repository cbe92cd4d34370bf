"""Play a rosbag2 to a real rclpy subscriber, and read it with the MCAP reference reader.

Run in the ROS 2 environment: ``python bag_player.py BAG``. A ``player`` node publishes each
message of the bag, as the serialized CDR bytes the bag holds, on its topic with its type
(what ``ros2 bag play`` does), in the bag's order; a ``listener`` node subscribes to every
topic and keeps what arrives. Prints one JSON line: ``{"received": {topic: [data, ...]},
"mcap": {topic: count}}`` (``mcap`` only for an MCAP bag).
"""

from __future__ import annotations

import importlib
import json
import sys
import threading
import time
from pathlib import Path
from typing import Any

import rclpy
from rclpy.executors import MultiThreadedExecutor
from rclpy.qos import QoSProfile
from rosbags.highlevel import AnyReader

QOS = QoSProfile(depth=1000)


def message_class(msgtype: str) -> Any:
    package, _, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{package}.msg"), name)


def main() -> int:
    bag = Path(sys.argv[1])
    rclpy.init()
    player, listener = rclpy.create_node("bag_player"), rclpy.create_node("bag_listener")
    received: dict[str, list[str]] = {}
    lock = threading.Lock()
    with AnyReader([bag]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        messages = [(c.topic, raw) for c, _t, raw in reader.messages()]
    pubs: dict[str, Any] = {}
    for topic, msgtype in types.items():
        cls = message_class(msgtype)
        pubs[topic] = player.create_publisher(cls, topic, QOS)

        def on(msg: Any, topic: str = topic) -> None:
            with lock:
                received.setdefault(topic, []).append(msg.data)

        listener.create_subscription(cls, topic, on, QOS)
    executor = MultiThreadedExecutor(num_threads=2)
    executor.add_node(player)
    executor.add_node(listener)
    threading.Thread(target=executor.spin, daemon=True).start()
    end = time.monotonic() + 60
    while any(p.get_subscription_count() == 0 for p in pubs.values()):
        if time.monotonic() > end:
            raise SystemExit("the listener never matched the player")
        time.sleep(0.05)
    for topic, raw in messages:
        pubs[topic].publish(raw)  # the bag's serialized bytes, as ros2 bag play sends them
    while sum(len(v) for v in received.values()) < len(messages):
        if time.monotonic() > end:
            break
        time.sleep(0.05)
    out: dict[str, Any] = {"received": received}
    files = list(bag.glob("*.mcap"))
    if files:
        from mcap.reader import make_reader

        counts: dict[str, int] = {}
        with files[0].open("rb") as f:
            for _schema, channel, _message in make_reader(f).iter_messages():
                counts[channel.topic] = counts.get(channel.topic, 0) + 1
        out["mcap"] = counts
    print(json.dumps(out), flush=True)
    executor.shutdown(timeout_sec=5.0)
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
