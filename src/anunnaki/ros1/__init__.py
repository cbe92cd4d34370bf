"""The ROS 1 bridge: a ROS robot's topics and services on the bus (``anunnaki[ros]``).

A **bridge file** (``anunnaki: ros1-bridge/1``, docs/ros.md) lists ROS topics with their
type, direction (``to_bus``/``to_ros``), bus name and field mapping, and bus services that
call ROS services; :func:`load_bridge` checks it (unknown types, bad field paths: errors
with file, line and element) without ROS installed. The bridge runs as its own process,
``python -m anunnaki.ros1 BRIDGE.yaml --connect ENDPOINT``, which imports Debian's rospy
(:func:`import_rospy`); a launch file starts it as the managed-system kind ``ros1``
(:mod:`anunnaki.managed`).

The ROS-neutral parts (the bridge file, the converters, :class:`ToBus`, rosbags) live in
:mod:`anunnaki.rosbridge`, shared with the ROS 2 bridges, and are re-exported here.

Converters: std_msgs Bool, String, Int32/64, Float32/64,
Header; sensor_msgs Image and CompressedImage (to and from the bus's ``Image``), Range,
BatteryState, NavSatFix; geometry_msgs Twist and PoseStamped; services std_srvs SetBool,
Trigger, Empty and ``anunnaki_msgs/SetString`` (string in, success and message out) for
mode changes.

What the bus gets of a ROS message (a camera frame as the bus's ``Image``, else the mapped
fields, several ROS topics feeding one bus topic merged) is :class:`ToBus`, shared by this
bridge, the ROS 2 bridge and :func:`read_bag`.

Rosbags (``rosbags``, pure Python): :func:`read_bag` turns a ROS 1 or ROS 2 bag into trace
records through the same bridge file; :func:`write_bag` writes a run's inputs and decisions
to a ROS 1 bag.

ROS 2 over zenoh is its own package, :mod:`anunnaki.ros2`, which reads the same bridge
files; the launch kinds ``ros1`` and ``ros2`` are in :mod:`anunnaki.managed`.
"""

from __future__ import annotations

from anunnaki.ros1._light import LightOracle
from anunnaki.ros1._rospy import ROS_DIST_PACKAGES, RosUnavailable, import_rospy
from anunnaki.rosbridge import (
    FORMAT_TAG,
    IMAGE_TYPES,
    MESSAGE_TYPES,
    SERVICE_TYPES,
    SET_STRING_SRV,
    BridgeSpec,
    ConversionError,
    ServiceBridge,
    ToBus,
    TopicBridge,
    bag_message_to_dict,
    bus_image_to_compressed,
    compressed_to_image,
    encode_png,
    fill_message,
    image_size,
    is_bag,
    load_bridge,
    message_to_dict,
    parse_bridge,
    raw_to_image,
    read_bag,
    to_bus_fields,
    to_ros_fields,
    write_bag,
)

__all__ = [
    "FORMAT_TAG",
    "IMAGE_TYPES",
    "MESSAGE_TYPES",
    "ROS_DIST_PACKAGES",
    "SERVICE_TYPES",
    "SET_STRING_SRV",
    "BridgeSpec",
    "ConversionError",
    "LightOracle",
    "RosUnavailable",
    "ServiceBridge",
    "ToBus",
    "TopicBridge",
    "bag_message_to_dict",
    "bus_image_to_compressed",
    "compressed_to_image",
    "encode_png",
    "fill_message",
    "image_size",
    "import_rospy",
    "is_bag",
    "load_bridge",
    "message_to_dict",
    "parse_bridge",
    "raw_to_image",
    "read_bag",
    "to_bus_fields",
    "to_ros_fields",
    "write_bag",
]
