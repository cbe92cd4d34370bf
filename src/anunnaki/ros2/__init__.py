"""ROS 2 over zenoh: a ROS 2 robot's topics on the bus, with no ROS 2 install (``anunnaki[ros]``).

ROS 2 speaks zenoh through zenoh-bridge-ros2dds (any ROS 2 with DDS) or rmw_zenoh (ROS 2
Jazzy on), and Anunnaki's bus is zenoh already. :class:`Ros2ZenohBridge` reads and writes
their samples (CDR, :func:`decode_cdr` / :func:`encode_cdr`, with ``rosbags``' ROS 2 type
store) on their key expressions (:func:`ros2_key`, :func:`dds_type_name`), through the same
bridge files as the ROS 1 bridge (:func:`anunnaki.ros1.load_bridge`, ROS 1 type names), and
publishes on the bus what the ROS 1 bridge publishes::

    from anunnaki.ros1 import load_bridge
    from anunnaki.ros2 import Ros2ZenohBridge

    with Ros2ZenohBridge(load_bridge("bridge.yaml"), bus, session, flavour="rmw_zenoh"):
        ...

A launch file runs it as the managed-system kind ``ros2`` (:mod:`anunnaki.managed`); see
docs/ros.md, "ROS 2 over zenoh".
"""

from __future__ import annotations

from anunnaki.ros2._bridge import (
    Flavour,
    Ros2ZenohBridge,
    dds_type_name,
    decode_cdr,
    encode_cdr,
    ros2_key,
)

__all__ = [
    "Flavour",
    "Ros2ZenohBridge",
    "dds_type_name",
    "decode_cdr",
    "encode_cdr",
    "ros2_key",
]
