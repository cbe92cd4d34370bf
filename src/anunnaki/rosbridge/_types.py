"""The ROS message and service types the bridges convert, described without rospy or rclpy.

The tables below are the ROS 1 (Noetic) definition of each supported type
(:data:`MESSAGE_TYPES`, :data:`SERVICE_TYPES`) and the ROS 2 (Jazzy) one
(:data:`ROS2_MESSAGE_TYPES`, :data:`ROS2_SERVICE_TYPES`: Header without ``seq``, Range with
``variance``, and ``diagnostic_msgs`` and ``lifecycle_msgs``), written out so a bridge file
can be checked — every type known, every field path real — on a machine with no ROS
installed (``anunnaki check``-style, at load time). ``tests/ros1`` compares the ROS 1 table
with Debian's generated message classes whenever rospy can be imported, ``tests/ros2`` the
ROS 2 one with rclpy's in the ROS 2 environment.

Field types are ROS's: ``bool``, ``int8``…``uint64``, ``float32``/``float64``, ``string``,
``time``/``duration`` (seconds as a float on the bus), a nested message type, or an array
``T[]``/``T[N]`` (a list on the bus; ``uint8[]`` is bytes and only images carry it).
"""

from __future__ import annotations

from typing import Final

__all__ = [
    "IMAGE_TYPES",
    "MESSAGE_TYPES",
    "ROS2_MESSAGE_TYPES",
    "ROS2_SERVICE_TYPES",
    "SENSOR_TYPES",
    "SERVICE_TYPES",
    "SET_STRING_SRV",
    "field_type",
    "leaf_fields",
]

_HEADER = (("seq", "uint32"), ("stamp", "time"), ("frame_id", "string"))

#: Message type → ``((field, type), ...)`` in ROS order.
MESSAGE_TYPES: Final[dict[str, tuple[tuple[str, str], ...]]] = {
    "std_msgs/Header": _HEADER,
    "std_msgs/Bool": (("data", "bool"),),
    "std_msgs/String": (("data", "string"),),
    "std_msgs/Int32": (("data", "int32"),),
    "std_msgs/Int64": (("data", "int64"),),
    "std_msgs/Float32": (("data", "float32"),),
    "std_msgs/Float64": (("data", "float64"),),
    "sensor_msgs/Image": (
        ("header", "std_msgs/Header"),
        ("height", "uint32"),
        ("width", "uint32"),
        ("encoding", "string"),
        ("is_bigendian", "uint8"),
        ("step", "uint32"),
        ("data", "uint8[]"),
    ),
    "sensor_msgs/CompressedImage": (
        ("header", "std_msgs/Header"),
        ("format", "string"),
        ("data", "uint8[]"),
    ),
    "sensor_msgs/Range": (
        ("header", "std_msgs/Header"),
        ("radiation_type", "uint8"),
        ("field_of_view", "float32"),
        ("min_range", "float32"),
        ("max_range", "float32"),
        ("range", "float32"),
    ),
    "sensor_msgs/BatteryState": (
        ("header", "std_msgs/Header"),
        ("voltage", "float32"),
        ("temperature", "float32"),
        ("current", "float32"),
        ("charge", "float32"),
        ("capacity", "float32"),
        ("design_capacity", "float32"),
        ("percentage", "float32"),
        ("power_supply_status", "uint8"),
        ("power_supply_health", "uint8"),
        ("power_supply_technology", "uint8"),
        ("present", "bool"),
        ("cell_voltage", "float32[]"),
        ("cell_temperature", "float32[]"),
        ("location", "string"),
        ("serial_number", "string"),
    ),
    "sensor_msgs/NavSatStatus": (("status", "int8"), ("service", "uint16")),
    "sensor_msgs/NavSatFix": (
        ("header", "std_msgs/Header"),
        ("status", "sensor_msgs/NavSatStatus"),
        ("latitude", "float64"),
        ("longitude", "float64"),
        ("altitude", "float64"),
        ("position_covariance", "float64[9]"),
        ("position_covariance_type", "uint8"),
    ),
    "geometry_msgs/Vector3": (("x", "float64"), ("y", "float64"), ("z", "float64")),
    "geometry_msgs/Point": (("x", "float64"), ("y", "float64"), ("z", "float64")),
    "geometry_msgs/Quaternion": (
        ("x", "float64"),
        ("y", "float64"),
        ("z", "float64"),
        ("w", "float64"),
    ),
    "geometry_msgs/Twist": (
        ("linear", "geometry_msgs/Vector3"),
        ("angular", "geometry_msgs/Vector3"),
    ),
    "geometry_msgs/Pose": (
        ("position", "geometry_msgs/Point"),
        ("orientation", "geometry_msgs/Quaternion"),
    ),
    "geometry_msgs/PoseStamped": (("header", "std_msgs/Header"), ("pose", "geometry_msgs/Pose")),
}

#: The types that become (or come from) the bus's ``Image`` message.
IMAGE_TYPES: Final = frozenset({"sensor_msgs/Image", "sensor_msgs/CompressedImage"})

#: Sensor streams: a ROS 2 bridge subscribes to them best-effort by default (``qos: sensor``),
#: as ROS 2 drivers publish them; a newer reading replaces a lost one.
SENSOR_TYPES: Final = frozenset(
    {
        *IMAGE_TYPES,
        "sensor_msgs/Range",
        "sensor_msgs/BatteryState",
        "sensor_msgs/NavSatFix",
    }
)

_ROS2_HEADER = (("stamp", "time"), ("frame_id", "string"))
_KEY_VALUE = (("key", "string"), ("value", "string"))

#: ROS 2 (Jazzy) message type → fields: ROS 1's, with ROS 2's differences (Header has no
#: ``seq``; Jazzy's Range has ``variance``), and the diagnostics a SUAVE-style robot reports.
ROS2_MESSAGE_TYPES: Final[dict[str, tuple[tuple[str, str], ...]]] = {
    **MESSAGE_TYPES,
    "std_msgs/Header": _ROS2_HEADER,
    "sensor_msgs/Range": (*MESSAGE_TYPES["sensor_msgs/Range"], ("variance", "float32")),
    "diagnostic_msgs/KeyValue": _KEY_VALUE,
    "diagnostic_msgs/DiagnosticStatus": (
        ("level", "uint8"),
        ("name", "string"),
        ("message", "string"),
        ("hardware_id", "string"),
        ("values", "diagnostic_msgs/KeyValue[]"),
    ),
    "diagnostic_msgs/DiagnosticArray": (
        ("header", "std_msgs/Header"),
        ("status", "diagnostic_msgs/DiagnosticStatus[]"),
    ),
    "lifecycle_msgs/Transition": (("id", "uint8"), ("label", "string")),
    "lifecycle_msgs/State": (("id", "uint8"), ("label", "string")),
}

#: The string-in/string-out service for mode changes (no ROS package has one): a robot that
#: wants to offer it builds this ``.srv`` in a package named ``anunnaki_msgs``.
SET_STRING_SRV: Final = "string data\n---\nbool success\nstring message\n"

#: Service type → (request fields, response fields).
SERVICE_TYPES: Final[dict[str, tuple[tuple[tuple[str, str], ...], tuple[tuple[str, str], ...]]]] = {
    "std_srvs/SetBool": (
        (("data", "bool"),),
        (("success", "bool"), ("message", "string")),
    ),
    "std_srvs/Trigger": ((), (("success", "bool"), ("message", "string"))),
    "std_srvs/Empty": ((), ()),
    "anunnaki_msgs/SetString": (
        (("data", "string"),),
        (("success", "bool"), ("message", "string")),
    ),
}

#: ROS 2 service type → (request fields, response fields): std_srvs, and a lifecycle node's
#: transition (``lifecycle_msgs/ChangeState``: ``{transition: {id: 3}}`` activates).
ROS2_SERVICE_TYPES: Final[
    dict[str, tuple[tuple[tuple[str, str], ...], tuple[tuple[str, str], ...]]]
] = {
    "std_srvs/SetBool": SERVICE_TYPES["std_srvs/SetBool"],
    "std_srvs/Trigger": SERVICE_TYPES["std_srvs/Trigger"],
    "std_srvs/Empty": SERVICE_TYPES["std_srvs/Empty"],
    "lifecycle_msgs/ChangeState": (
        (("transition", "lifecycle_msgs/Transition"),),
        (("success", "bool"),),
    ),
    "lifecycle_msgs/GetState": ((), (("current_state", "lifecycle_msgs/State"),)),
}


def _base(type_: str) -> str:
    return type_.split("[", 1)[0]


def field_type(
    fields: tuple[tuple[str, str], ...],
    path: str,
    table: dict[str, tuple[tuple[str, str], ...]] = MESSAGE_TYPES,
) -> str | None:
    """The ROS type at dotted ``path`` in a message with ``fields`` (``None``: no such field).

    Paths go into nested messages (``header.seq``, ``pose.position.x``) of ``table``; an
    array is a leaf.
    """
    current = fields
    parts = path.split(".")
    for i, part in enumerate(parts):
        found = dict(current).get(part)
        if found is None:
            return None
        if i == len(parts) - 1:
            return found
        nested = table.get(found)
        if nested is None:  # a primitive or an array has no fields below it
            return None
        current = nested
    return None


def leaf_fields(
    fields: tuple[tuple[str, str], ...],
    prefix: str = "",
    table: dict[str, tuple[tuple[str, str], ...]] = MESSAGE_TYPES,
) -> list[str]:
    """Every dotted path to a primitive or array field (for hints: what exists)."""
    out: list[str] = []
    for name, type_ in fields:
        nested = table.get(type_)
        path = f"{prefix}{name}"
        if nested is None or "[" in type_:
            out.append(path)
        else:
            out.extend(leaf_fields(nested, f"{path}.", table))
    return out


def is_array(type_: str) -> bool:
    """Whether a ROS field type is an array (``float32[]``, ``float64[9]``)."""
    return "[" in type_


def base_type(type_: str) -> str:
    """The element type of an array type (``float32[]`` → ``float32``), else the type."""
    return _base(type_)
