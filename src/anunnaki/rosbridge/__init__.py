"""What the ROS 1 and ROS 2 bridges share, with no ROS imported (``anunnaki[ros]`` for bags).

* **The bridge file** (:func:`load_bridge`; ``anunnaki: ros1-bridge/1`` or ``ros2-bridge/1``,
  docs/ros.md): ROS topics with their type, direction, bus name, field mapping and (ROS 2)
  QoS; services; checked against the message tables of :mod:`anunnaki.rosbridge._types`
  (ROS 1 Noetic's and ROS 2 Jazzy's) on a machine with no ROS installed.
* **The converters** (:mod:`anunnaki.rosbridge._convert`): a ROS message as plain data and
  back, field mappings, camera frames to and from the bus's ``Image`` (PNG written with zlib).
* **What the bus gets** of a ROS message (:class:`ToBus`): a frame, or the mapped fields,
  several ROS topics feeding one bus topic merged; one ``/diagnostics`` status as flat
  fields (:func:`diagnostic_fields`: SUAVE-style observers read by a binding).
* **Rosbags** (:func:`read_bag`, :func:`write_bag`; ``rosbags``, pure Python).

The ROS 1 bridge (:mod:`anunnaki.ros1`, rospy) and the ROS 2 bridges (:mod:`anunnaki.ros2`:
native on rclpy, or over zenoh) both build on it.
"""

from __future__ import annotations

from anunnaki.rosbridge._bags import (
    BagStorage,
    bag_message_to_dict,
    bag_storage,
    is_bag,
    read_bag,
    write_bag,
)
from anunnaki.rosbridge._convert import (
    ConversionError,
    bus_image_to_compressed,
    bus_image_to_raw,
    coerce_value,
    compressed_to_image,
    encode_png,
    fill_message,
    image_size,
    message_to_dict,
    raw_to_image,
    ros_reply,
    to_bus_fields,
    to_ros_fields,
)
from anunnaki.rosbridge._process import add_bus_arguments, bus_options, stop_event
from anunnaki.rosbridge._schema import (
    DISTROS,
    FORMAT_TAG,
    HEARTBEAT_LEASE,
    HEARTBEAT_RANGE,
    ROS2_FORMAT_TAG,
    BridgeSpec,
    Distro,
    QosName,
    ServiceBridge,
    TopicBridge,
    load_bridge,
    parse_bridge,
)
from anunnaki.rosbridge._tobus import ToBus, diagnostic_fields
from anunnaki.rosbridge._types import (
    IMAGE_TYPES,
    MESSAGE_TYPES,
    ROS2_MESSAGE_TYPES,
    ROS2_SERVICE_TYPES,
    SENSOR_TYPES,
    SERVICE_TYPES,
    SET_STRING_SRV,
)

__all__ = [
    "DISTROS",
    "FORMAT_TAG",
    "HEARTBEAT_LEASE",
    "HEARTBEAT_RANGE",
    "IMAGE_TYPES",
    "MESSAGE_TYPES",
    "ROS2_FORMAT_TAG",
    "ROS2_MESSAGE_TYPES",
    "ROS2_SERVICE_TYPES",
    "SENSOR_TYPES",
    "SERVICE_TYPES",
    "SET_STRING_SRV",
    "BagStorage",
    "BridgeSpec",
    "ConversionError",
    "Distro",
    "QosName",
    "ServiceBridge",
    "ToBus",
    "TopicBridge",
    "add_bus_arguments",
    "bag_message_to_dict",
    "bag_storage",
    "bus_image_to_compressed",
    "bus_image_to_raw",
    "bus_options",
    "coerce_value",
    "compressed_to_image",
    "diagnostic_fields",
    "encode_png",
    "fill_message",
    "image_size",
    "is_bag",
    "load_bridge",
    "message_to_dict",
    "parse_bridge",
    "raw_to_image",
    "read_bag",
    "ros_reply",
    "stop_event",
    "to_bus_fields",
    "to_ros_fields",
    "write_bag",
]
