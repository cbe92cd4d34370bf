"""ROS 2 robots on the bus: natively on rclpy, or over zenoh with no ROS 2 install.

**Native (rclpy).** ``python -m anunnaki.ros2 BRIDGE.yaml --connect EP`` runs
:class:`Ros2Bridge`, a ROS 2 node that carries a bridge file's topics (per-topic QoS:
``sensor`` best effort, ``reliable``) and services (both ways) between the ROS 2 graph and
the bus, images as the bus's ``Image``. It runs with a Python that imports rclpy: the
separate ROS 2 environment scripts/setup-ros2.sh builds (ROS 2 Jazzy from PyPI, no root), or
a sourced ROS 2 install. Nothing else in Anunnaki imports rclpy.

**Over zenoh.** ROS 2 speaks zenoh through zenoh-bridge-ros2dds (any ROS 2 with DDS) or
rmw_zenoh (ROS 2 Jazzy on), and Anunnaki's bus is zenoh already. :class:`Ros2ZenohBridge`
reads and writes their samples (CDR, :func:`decode_cdr` / :func:`encode_cdr`, with the type
store of the robot's distribution, :func:`resolve_distro`) on their key expressions
(:func:`ros2_key`, :func:`dds_type_name`), through the same bridge files
(:func:`anunnaki.rosbridge.load_bridge`), and publishes on the bus what the native bridge
publishes::

    from anunnaki.rosbridge import load_bridge
    from anunnaki.ros2 import Ros2ZenohBridge

    with Ros2ZenohBridge(load_bridge("bridge.yaml"), bus, session, flavour="rmw_zenoh"):
        ...

A launch file runs either as the managed-system kind ``ros2`` (:mod:`anunnaki.managed`); see
docs/ros.md, "ROS 2".
"""

from __future__ import annotations

from anunnaki.ros2._bridge import (
    Flavour,
    Ros2ZenohBridge,
    dds_type_name,
    decode_cdr,
    encode_cdr,
    rmw_zenoh_attachment,
    ros2_key,
    type_hash,
)
from anunnaki.ros2._distro import installed_distro, resolve_distro, type_store
from anunnaki.ros2._native import Ros2Bridge, Ros2Unavailable, import_rclpy
from anunnaki.ros2._rclpy_convert import fill_ros2_message, ros2_message_to_dict

__all__ = [
    "Flavour",
    "Ros2Bridge",
    "Ros2Unavailable",
    "Ros2ZenohBridge",
    "dds_type_name",
    "decode_cdr",
    "encode_cdr",
    "fill_ros2_message",
    "import_rclpy",
    "installed_distro",
    "resolve_distro",
    "rmw_zenoh_attachment",
    "ros2_key",
    "ros2_message_to_dict",
    "type_hash",
    "type_store",
]
