"""The bridge file (ros1-bridge/1, ros2-bridge/1): which ROS topics and services meet the bus.

Validated in two passes, both naming file, line and element: the shape (pydantic: unknown
keys, wrong kinds, bad names), then the meaning — every ROS type is one the bridge converts
(:mod:`anunnaki.rosbridge._types`, ROS 1's or ROS 2's table by the file's tag), every field
path exists in that type, a bus topic fed by several ROS topics gets each field from one of
them, and the ROS 2 settings (``distro``, ``qos``, ``serve: ros``) appear in ROS 2 files only.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from anunnaki._safeyaml import LineMap, load_yaml, read_text_limited, validation_error
from anunnaki.errors import ModelFileError
from anunnaki.rosbridge._convert import ConversionError, to_ros_fields
from anunnaki.rosbridge._types import (
    IMAGE_TYPES,
    MESSAGE_TYPES,
    ROS2_MESSAGE_TYPES,
    ROS2_SERVICE_TYPES,
    SENSOR_TYPES,
    SERVICE_TYPES,
    field_type,
    leaf_fields,
)

__all__ = [
    "DISTROS",
    "FORMAT_TAG",
    "HEARTBEAT_LEASE",
    "HEARTBEAT_RANGE",
    "ROS2_FORMAT_TAG",
    "BridgeSpec",
    "Distro",
    "QosName",
    "ServiceBridge",
    "TopicBridge",
    "load_bridge",
    "parse_bridge",
]

FORMAT_TAG = "ros1-bridge/1"
ROS2_FORMAT_TAG = "ros2-bridge/1"
_TAGS = (FORMAT_TAG, ROS2_FORMAT_TAG)

#: The ROS 2 distributions whose message definitions the bridges know (rosbags' type stores).
Distro = Literal["humble", "jazzy", "kilted"]
DISTROS: tuple[Distro, ...] = ("humble", "jazzy", "kilted")
#: The default lease (seconds) of the ROS 2 bridge's heartbeat (``heartbeat``), and the range
#: a bridge file may set: shorter than 0.1 s a loaded machine's scheduling alone would let it
#: lapse; longer than 60 s a dead bridge would go unnoticed for a minute.
HEARTBEAT_LEASE = 1.0
HEARTBEAT_RANGE = (0.1, 60.0)
#: A ROS 2 topic's QoS: ``sensor`` (best effort, keep last: rclpy's sensor-data profile) or
#: ``reliable`` (reliable, keep last ``queue``: commands, states, diagnostics).
QosName = Literal["sensor", "reliable"]

_T = TypeVar("_T")

_NAME_PATTERN = r"^(/[A-Za-z0-9_]+)+$"
_FIELD_PATTERN = r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$"
RosName = Annotated[str, Field(pattern=_NAME_PATTERN, max_length=256)]
FieldPath = Annotated[str, Field(pattern=_FIELD_PATTERN, max_length=256)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True)


class TopicBridge(_Strict):
    """One ROS topic carried to the bus (``to_bus``) or from it (``to_ros``).

    Attributes:
        ros: The ROS topic.
        type: Its ROS message type (``sensor_msgs/Range``).
        direction: ``to_bus`` (the bridge subscribes on ROS, publishes on the bus) or
            ``to_ros`` (subscribes on the bus, publishes on ROS).
        bus: The bus topic (default: the ROS name).
        fields: Bus field → ROS field path (``{range: range, seq: header.seq}``); empty:
            every field, nested as in ROS. A to_bus image without ``fields`` travels as the
            bus's ``Image``; with ``fields`` as those fields (never the pixels).
        queue: Messages waiting on either side before the oldest is dropped (ROS 2: the
            QoS history depth too).
        qos: (ROS 2) ``sensor`` or ``reliable``; default :attr:`effective_qos`.
        status: (``diagnostic_msgs/DiagnosticArray``, to_bus) The name of one status (a
            SUAVE-style observer's, ``rover/camera``): the bus gets its ``level``,
            ``message``, ``hardware_id`` and key/value pairs as fields (numbers and booleans
            read as such), and ``fields`` picks among those; arrays without it are skipped.

    """

    ros: RosName
    type: str
    direction: Literal["to_bus", "to_ros"]
    bus: RosName | None = None
    fields: dict[FieldPath, FieldPath] = Field(default_factory=dict)
    queue: Annotated[int, Field(ge=1, le=1000)] = 4
    qos: QosName | None = None
    status: Annotated[str, Field(min_length=1, max_length=256)] | None = None

    @property
    def effective_qos(self) -> QosName:
        """The QoS stated, else ``sensor`` for a sensor stream read from ROS, else ``reliable``.

        A best-effort reader matches a sensor driver whichever it offers; a reliable
        writer (commands, states to ROS) matches every reader.
        """
        if self.qos is not None:
            return self.qos
        return "sensor" if self.direction == "to_bus" and self.type in SENSOR_TYPES else "reliable"

    @property
    def bus_topic(self) -> str:
        """The bus topic (the ROS name unless ``bus`` is given)."""
        return self.bus or self.ros

    @property
    def as_image(self) -> bool:
        """Whether this entry carries frames as the bus's ``Image`` (not as fields)."""
        return self.type in IMAGE_TYPES and not self.fields


class ServiceBridge(_Strict):
    """A bus service (what a tactic requests) answered by calling a ROS service.

    Attributes:
        bus: The bus service Utu's tactics request (the binding's endpoint).
        ros: The robot's ROS service (default: the bus name).
        type: ``std_srvs/SetBool``, ``std_srvs/Trigger``, ``std_srvs/Empty`` or
            ``anunnaki_msgs/SetString`` (string in, success and message out).
        fields: Bus request field → ROS request field (``{mode: data}``); empty: the
            request's fields by the same names.
        timeout: Seconds to wait for the ROS service's reply.
        values: Bus field → {bus value → ROS value}: a mode's name as the value the robot's
            service takes (``{mode: {manual: true, autonomous: false}}`` for a SetBool,
            ``{state: {active: 3, inactive: 4}}`` for a lifecycle transition's id).
        serve: Where the bridge offers the service: ``bus`` (default: a tactic's request on
            the bus calls the robot's ROS service) or, ROS 2 only, ``ros`` (the bridge offers
            the ROS service, and a ROS call requests the bus service; ``fields`` then maps
            bus field → ROS request field the same way).

    """

    bus: RosName
    ros: RosName | None = None
    type: str
    fields: dict[FieldPath, FieldPath] = Field(default_factory=dict)
    timeout: Annotated[float, Field(gt=0, le=600)] = 2.0
    serve: Literal["bus", "ros"] = "bus"
    values: dict[FieldPath, dict[str, bool | int | float | str]] = Field(default_factory=dict)

    def ros_request(self, body: Mapping[str, Any]) -> dict[str, Any]:
        """The ROS request fields of a bus request: ``values`` translated, ``fields`` mapped.

        Raises:
            ConversionError: A bus value ``values`` does not list.

        """
        body = dict(body)
        for field, table in self.values.items():
            if field in body:
                key = body[field]
                key = str(key).lower() if isinstance(key, bool) else str(key)
                if key not in table:
                    known = ", ".join(sorted(table))
                    raise ConversionError(
                        f"{field} {body[field]!r} is not one of {known} ({self.ros_service})"
                    )
                body[field] = table[key]
        return to_ros_fields(body, self.fields)

    @property
    def ros_service(self) -> str:
        """The ROS service (the bus name unless ``ros`` is given)."""
        return self.ros or self.bus


class BridgeSpec(_Strict):
    """A bridge file.

    Attributes:
        heartbeat: (ROS 2) The liveliness lease, in seconds, of the bridge's heartbeat topic
            ``/<name>/heartbeat`` (``std_msgs/Empty``, liveliness ``MANUAL_BY_TOPIC``,
            published every quarter lease): a robot that subscribes with this lease (or a
            longer one) sees the bridge's ``alive_count`` fall to 0 that long after the bridge
            stops or is killed, and goes to its safe state. Default
            :data:`HEARTBEAT_LEASE`; between :data:`HEARTBEAT_RANGE`.

    """

    anunnaki: Literal["ros1-bridge/1", "ros2-bridge/1"]
    name: Annotated[str, Field(pattern=r"^[A-Za-z][A-Za-z0-9_]*$", max_length=64)] = (
        "anunnaki_bridge"
    )
    description: str = ""
    distro: Distro | None = None
    heartbeat: Annotated[float, Field(strict=True)] | None = None  # not `true`
    topics: list[TopicBridge] = Field(default_factory=list)
    services: list[ServiceBridge] = Field(default_factory=list)

    @property
    def ros2(self) -> bool:
        """Whether this is a ROS 2 bridge file (``anunnaki: ros2-bridge/1``)."""
        return self.anunnaki == ROS2_FORMAT_TAG

    @property
    def heartbeat_lease(self) -> float:
        """The heartbeat's lease in seconds: the file's ``heartbeat``, else the default."""
        return HEARTBEAT_LEASE if self.heartbeat is None else self.heartbeat

    @property
    def heartbeat_topic(self) -> str:
        """The ROS 2 topic of the bridge's heartbeat: ``/<name>/heartbeat``."""
        return f"/{self.name}/heartbeat"


def parse_bridge(text: str, *, source: str | Path = "<bridge>") -> BridgeSpec:
    """Read and check a bridge file's text.

    Raises:
        ModelFileError: The first problem, with file, line, element and a hint.

    """
    data, lines = load_yaml(source, text=text)
    if not isinstance(data, dict):
        raise ModelFileError("a bridge file is a YAML mapping", path=source, line=1)
    if data.get("anunnaki") not in _TAGS:
        raise ModelFileError(
            f"not a bridge file: 'anunnaki' is {data.get('anunnaki')!r}",
            path=source,
            line=lines.line(("anunnaki",)) or 1,
            element="anunnaki",
            hint=f"start the file with 'anunnaki: {ROS2_FORMAT_TAG}' (ROS 2) "
            f"or 'anunnaki: {FORMAT_TAG}' (ROS 1)",
        )
    try:
        spec = BridgeSpec.model_validate(data)
    except ValidationError as exc:
        raise validation_error(exc, data, lines, source, hint=_HINT) from None
    _check_meaning(spec, lines, str(source))
    return spec


def load_bridge(path: str | Path) -> BridgeSpec:
    """Load a bridge file (see :func:`parse_bridge`)."""
    data_path = Path(path)
    return parse_bridge(read_text_limited(data_path), source=str(data_path))


_HINT = "see docs/ros.md for the bridge file format"


@dataclass(frozen=True)
class _File:
    """Where a bridge file's elements are, for errors that name file, line and element."""

    path: str
    lines: LineMap

    def error(
        self, message: str, where: tuple[str | int, ...], element: str, hint: str
    ) -> ModelFileError:
        line = None
        for n in range(len(where), 0, -1):
            line = self.lines.line(where[:n])
            if line is not None:
                break
        return ModelFileError(message, path=self.path, line=line, element=element, hint=hint)


def _check_ros1_only(spec: BridgeSpec, f: _File) -> None:
    """A ROS 1 file names no ROS 2 setting (it would be silently ignored)."""
    hint = f"these are ROS 2 settings: write 'anunnaki: {ROS2_FORMAT_TAG}' for a ROS 2 robot"
    if spec.distro is not None:
        raise f.error("a ROS 1 bridge file has no 'distro'", ("distro",), "distro", hint)
    if spec.heartbeat is not None:
        raise f.error("a ROS 1 bridge file has no 'heartbeat'", ("heartbeat",), "heartbeat", hint)
    for i, t in enumerate(spec.topics):
        if t.qos is not None:
            where = ("topics", i, "qos")
            raise f.error("a ROS 1 topic has no 'qos'", where, f"topics[{t.ros}].qos", hint)
    for i, s in enumerate(spec.services):
        if s.serve != "bus":
            where = ("services", i, "serve")
            raise f.error(
                "the ROS 1 bridge serves on the bus only", where, f"services[{s.bus}].serve", hint
            )


def _check_meaning(spec: BridgeSpec, lines: LineMap, path: str) -> None:
    f = _File(path, lines)
    if not spec.ros2:
        _check_ros1_only(spec, f)
    _check_heartbeat(spec, f)
    messages = ROS2_MESSAGE_TYPES if spec.ros2 else MESSAGE_TYPES
    services = ROS2_SERVICE_TYPES if spec.ros2 else SERVICE_TYPES
    merged: dict[str, dict[str, int]] = {}  # bus topic → bus field → topic entry
    for i, t in enumerate(spec.topics):
        element = f"topics[{t.ros}]"
        at = ("topics", i)
        fields = _known(f, messages, t.type, at=at, element=element, kind="message")
        if t.status is not None:
            _check_status(f, t, at=at, element=element)
            continue  # its fields are the status's keys: known when the robot reports them
        _check_fields(f, t.type, fields, t.fields, messages, at=at, element=element)
        if t.direction == "to_bus" and not t.as_image:
            for bus_field in t.fields or dict(fields):
                first = merged.setdefault(t.bus_topic, {}).setdefault(bus_field, i)
                if first != i:
                    raise f.error(
                        f"bus field '{bus_field}' of {t.bus_topic} comes from two ROS topics "
                        f"({spec.topics[first].ros} and {t.ros})",
                        ("topics", i, "fields", bus_field),
                        f"{element}.fields.{bus_field}",
                        "several ROS topics may feed one bus topic, each with its own fields",
                    )
    for i, s in enumerate(spec.services):
        element = f"services[{s.bus}]"
        at = ("services", i)
        request, _ = _known(f, services, s.type, at=at, element=element, kind="service")
        for field in s.values:
            bus_fields = s.fields or dict(request)
            if field not in bus_fields:
                raise f.error(
                    f"'values' translates '{field}', which is no field of the bus request",
                    (*at, "values", field),
                    f"{element}.values.{field}",
                    "the bus request's fields: " + (", ".join(bus_fields) or "none"),
                )
        _check_fields(f, f"{s.type} request", request, s.fields, messages, at=at, element=element)


def _check_heartbeat(spec: BridgeSpec, f: _File) -> None:
    """``heartbeat`` is a lease in seconds, within :data:`HEARTBEAT_RANGE`."""
    lease = spec.heartbeat
    low, high = HEARTBEAT_RANGE
    if lease is None or low <= lease <= high:
        return
    raise f.error(
        f"the lease of the bridge's ROS 2 heartbeat is {lease:g} s, outside {low:g}..{high:g} s",
        ("heartbeat",),
        "heartbeat",
        f"write a lease between {low:g} and {high:g} s (default {HEARTBEAT_LEASE:g}); the "
        "robot's subscriber must ask for this lease or a longer one (docs/ros.md)",
    )


def _check_status(f: _File, t: TopicBridge, *, at: tuple[str, int], element: str) -> None:
    if t.type != _DIAGNOSTICS or t.direction != "to_bus":
        raise f.error(
            "'status' picks one status of a diagnostics array read from ROS",
            (*at, "status"),
            f"{element}.status",
            f"use it on a to_bus entry of type {_DIAGNOSTICS}",
        )


_DIAGNOSTICS = "diagnostic_msgs/DiagnosticArray"


def _known(
    f: _File,
    table: Mapping[str, _T],
    type_name: str,
    *,
    at: tuple[str, int],
    element: str,
    kind: Literal["message", "service"],
) -> _T:
    """The table's entry for an entry's ROS type, or an error listing the known ones."""
    found = table.get(type_name)
    if found is None:
        verb = "converts" if kind == "message" else "calls"
        raise f.error(
            f"unknown ROS {kind} type {type_name!r}",
            (*at, "type"),
            f"{element}.type",
            f"the bridge {verb}: " + ", ".join(sorted(table)),
        )
    return found


def _check_fields(
    f: _File,
    type_name: str,
    fields: tuple[tuple[str, str], ...],
    mapping: Mapping[str, str],
    table: dict[str, tuple[tuple[str, str], ...]],
    *,
    at: tuple[str, int],
    element: str,
) -> None:
    """Every ROS field an entry's mapping names is one of its type's (not the image bytes)."""
    for bus_field, ros_field in mapping.items():
        where, name = (*at, "fields", bus_field), f"{element}.fields.{bus_field}"
        _check_field(f, type_name, fields, ros_field, where, table=table, element=name)


def _check_field(
    f: _File,
    type_name: str,
    /,
    fields: tuple[tuple[str, str], ...],
    ros_field: str,
    where: tuple[str | int, ...],
    *,
    table: dict[str, tuple[tuple[str, str], ...]],
    element: str,
) -> None:
    found = field_type(fields, ros_field, table)
    if found is None:
        known = ", ".join(leaf_fields(fields, "", table)) or "none"
        raise f.error(
            f"{type_name} has no field '{ros_field}'", where, element, f"its fields: {known}"
        )
    if found == "uint8[]":
        raise f.error(
            f"'{ros_field}' is the image's bytes; they travel as the bus's Image, not a field",
            where,
            element,
            "leave 'fields' out to carry the frames, or map other fields (header.seq, width)",
        )
