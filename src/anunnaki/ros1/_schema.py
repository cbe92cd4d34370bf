"""The bridge file (``anunnaki: ros1-bridge/1``): which ROS topics and services meet the bus.

Validated in two passes, both naming file, line and element: the shape (pydantic: unknown
keys, wrong kinds, bad names), then the meaning — every ROS type is one the bridge converts
(:mod:`anunnaki.ros1._types`), every field path exists in that type, a bus topic fed by
several ROS topics gets each field from one of them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal, TypeVar

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from anunnaki._safeyaml import LineMap, load_yaml, read_text_limited, validation_error
from anunnaki.errors import ModelFileError
from anunnaki.ros1._types import (
    IMAGE_TYPES,
    MESSAGE_TYPES,
    SERVICE_TYPES,
    field_type,
    leaf_fields,
)

__all__ = [
    "FORMAT_TAG",
    "BridgeSpec",
    "ServiceBridge",
    "TopicBridge",
    "load_bridge",
    "parse_bridge",
]

FORMAT_TAG = "ros1-bridge/1"

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
        queue: Messages waiting on either side before the oldest is dropped.

    """

    ros: RosName
    type: str
    direction: Literal["to_bus", "to_ros"]
    bus: RosName | None = None
    fields: dict[FieldPath, FieldPath] = Field(default_factory=dict)
    queue: Annotated[int, Field(ge=1, le=1000)] = 4

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

    """

    bus: RosName
    ros: RosName | None = None
    type: str
    fields: dict[FieldPath, FieldPath] = Field(default_factory=dict)
    timeout: Annotated[float, Field(gt=0, le=600)] = 2.0

    @property
    def ros_service(self) -> str:
        """The ROS service (the bus name unless ``ros`` is given)."""
        return self.ros or self.bus


class BridgeSpec(_Strict):
    """A bridge file."""

    anunnaki: Literal["ros1-bridge/1"]
    name: Annotated[str, Field(pattern=r"^[A-Za-z][A-Za-z0-9_]*$", max_length=64)] = (
        "anunnaki_bridge"
    )
    description: str = ""
    topics: list[TopicBridge] = Field(default_factory=list)
    services: list[ServiceBridge] = Field(default_factory=list)


def parse_bridge(text: str, *, source: str | Path = "<bridge>") -> BridgeSpec:
    """Read and check a bridge file's text.

    Raises:
        ModelFileError: The first problem, with file, line, element and a hint.

    """
    data, lines = load_yaml(source, text=text)
    if not isinstance(data, dict):
        raise ModelFileError("a bridge file is a YAML mapping", path=source, line=1)
    if data.get("anunnaki") != FORMAT_TAG:
        raise ModelFileError(
            f"not a bridge file: 'anunnaki' is {data.get('anunnaki')!r}",
            path=source,
            line=lines.line(("anunnaki",)) or 1,
            element="anunnaki",
            hint=f"start the file with 'anunnaki: {FORMAT_TAG}'",
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


def _check_meaning(spec: BridgeSpec, lines: LineMap, path: str) -> None:
    f = _File(path, lines)
    merged: dict[str, dict[str, int]] = {}  # bus topic → bus field → topic entry
    for i, t in enumerate(spec.topics):
        element = f"topics[{t.ros}]"
        at = ("topics", i)
        fields = _known(f, MESSAGE_TYPES, t.type, at=at, element=element, kind="message")
        _check_fields(f, t.type, fields, t.fields, at=at, element=element)
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
        request, _ = _known(f, SERVICE_TYPES, s.type, at=at, element=element, kind="service")
        _check_fields(f, f"{s.type} request", request, s.fields, at=at, element=element)


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
    *,
    at: tuple[str, int],
    element: str,
) -> None:
    """Every ROS field an entry's mapping names is one of its type's (not the image bytes)."""
    for bus_field, ros_field in mapping.items():
        where, name = (*at, "fields", bus_field), f"{element}.fields.{bus_field}"
        _check_field(f, type_name, fields, ros_field, where, element=name)


def _check_field(
    f: _File,
    type_name: str,
    /,
    fields: tuple[tuple[str, str], ...],
    ros_field: str,
    where: tuple[str | int, ...],
    *,
    element: str,
) -> None:
    found = field_type(fields, ros_field)
    if found is None:
        known = ", ".join(leaf_fields(fields)) or "none"
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
