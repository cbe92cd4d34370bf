"""Tactics' value types and where an element was written: what every part of a tactic uses."""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Annotated, Any, Final, Literal, NamedTuple

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    JsonValue,
    PrivateAttr,
)
from pydantic_core import PydanticCustomError

from anunnaki._safeyaml import element_path

__all__ = [
    "ACTION_TYPES",
    "FORMAT_TAG",
    "GOAL_STATES",
    "MAX_DEPTH",
    "MAX_PAYLOAD_DEPTH",
    "NOTIFY_CHANNELS",
    "EndpointReference",
    "ExpressionReference",
    "GoalReference",
    "SourceRef",
]


FORMAT_TAG: Final = "tactics/1"
"""The format tag (and version) a YAML tactics file starts with: ``anunnaki: tactics/1``."""

GOAL_STATES: Final = ("satisfied", "unsatisfied", "unknown")
"""The states a goal can be required to be in."""

ACTION_TYPES: Final = ("publish", "request", "change_mode", "swap_model", "notify")
"""The built-in action types, in the order the docs present them (others register in
:data:`~anunnaki.tactics.ACTIONS`)."""

NOTIFY_CHANNELS: Final = ("email", "webhook", "log")
"""Where a :class:`NotifyAction` sends its message."""

MAX_DEPTH: Final = 32
"""Deepest element nesting accepted in a tactics file (XML elements, YAML nodes)."""

MAX_PAYLOAD_DEPTH: Final = 16
"""Deepest nesting accepted inside one action payload."""

_ID = re.compile(r"[A-Za-z][A-Za-z0-9_\-]*")
_ROS_NAME = re.compile(r"(/[A-Za-z0-9_]+)+")
_LOGICAL_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
_EMAIL = re.compile(r"[^@\s]+@[^@\s]+\.[^@\s]+")
_URL = re.compile(r"https?://[^\s/?#]+\S*")
# Control characters (C0 but tab and newline, DEL, C1) and what XML 1.0 cannot hold: they
# cannot be written to one form or the other (or would be normalised away on reading).
_BAD_CHARS = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f\ud800-\udfff\ufffe\uffff]")
_BAD_LINE_CHARS = re.compile(r"[\x00-\x1f\x7f-\x9f\ud800-\udfff\ufffe\uffff]")

STATE_HINT: Final = "valid states: " + ", ".join(GOAL_STATES)
CHANNEL_HINT: Final = "valid channels: " + ", ".join(NOTIFY_CHANNELS)
ROS_HINT: Final = (
    "a ROS-style name starts with '/' and uses letters, digits and '_' in '/'-separated "
    "parts, e.g. /rover/set_mode"
)
ENDPOINT_HINT: Final = (
    "name the endpoint by its logical name (letters, digits and '_', e.g. set_mode), which "
    "the binding maps to a topic or service, or by a ROS-style name such as /rover/set_mode"
)


def _error(kind: str, message: str, *, hint: str | None = None, **ctx: Any) -> PydanticCustomError:
    """Build a pydantic error whose context carries a hint (and, in ``where``, a sub-path)."""
    context: dict[str, Any] = dict(ctx)
    if hint is not None:
        context["hint"] = hint
    # Braces would be read as placeholders by pydantic; messages here never need them.
    return PydanticCustomError(kind, message.replace("{", "(").replace("}", ")"), context)


# --------------------------------------------------------------------------- value types


def _no_control(value: str, bad_chars: re.Pattern[str], where: str, hint: str) -> str:
    bad = bad_chars.search(value)
    if bad:
        message = f"control character U+{ord(bad.group()):04X} is not allowed{where}"
        raise _error("control_character", message, hint=hint)
    return value


def _check_text(value: str) -> str:
    hint = "use plain text; tabs and newlines are the only control characters allowed"
    return _no_control(value, _BAD_CHARS, "", hint)


def _check_line(value: str) -> str:
    return _no_control(value, _BAD_LINE_CHARS, " here", "this value is one line of plain text")


def _check_token(value: str) -> str:
    if not value or any(c.isspace() for c in value) or _BAD_LINE_CHARS.search(value):
        raise _error(
            "token",
            f"{value!r} must be a non-empty word without spaces",
            hint="e.g. manual, detector, yolo-fog-v2",
        )
    return value


def _check_id(value: str) -> str:
    if not _ID.fullmatch(value) or len(value) > 64:
        raise _error(
            "goal_id",
            f"{value!r} is not a goal id",
            hint="goal ids start with a letter and use letters, digits, '_' and '-', e.g. G3",
        )
    return value


def _check_ros_name(value: str) -> str:
    if not _ROS_NAME.fullmatch(value):
        raise _error("ros_name", f"{value!r} is not a ROS-style name", hint=ROS_HINT)
    return value


def _check_endpoint_name(value: str) -> str:
    if not (_ROS_NAME.fullmatch(value) or _LOGICAL_NAME.fullmatch(value)):
        raise _error(
            "endpoint_name",
            f"{value!r} is not a ROS-style name or a logical endpoint name",
            hint=ENDPOINT_HINT,
        )
    return value


def is_logical_name(name: str) -> bool:
    """Tell whether ``name`` is a logical endpoint name (``set_mode``), not a ROS name."""
    return not name.startswith("/")


def _clean_text(value: str) -> str:
    """Strip the text and the indentation its continuation lines share (as for docstrings).

    So indented multi-line text in XML reads as it does in a YAML block scalar; applying this
    twice changes nothing, which keeps the two forms convertible without loss.
    """
    lines = value.strip().split("\n")
    if len(lines) > 1:
        indents = [
            line[: len(line) - len(line.lstrip(" \t"))] for line in lines[1:] if line.strip()
        ]
        cut = min((len(indent) for indent in indents), default=0)
        while cut and any(indent[:cut] != indents[0][:cut] for indent in indents):
            cut -= 1
        lines[1:] = [line[cut:] if line.strip() else "" for line in lines[1:]]
    return "\n".join(lines)


Text = Annotated[str, AfterValidator(_clean_text), AfterValidator(_check_text)]
"""Free text (description, message, expression): stripped, continuation lines dedented."""

Line = Annotated[str, AfterValidator(str.strip), AfterValidator(_check_line)]
"""One line of text (subject, tactic name): surrounding whitespace is stripped."""


def _check_filled(value: str) -> str:
    if not value:
        raise _error("empty", "must not be empty", hint="write some text")
    return value


Filled = AfterValidator(_check_filled)

Token = Annotated[str, AfterValidator(_check_token)]
"""A non-empty word without whitespace (mode, model id, address)."""

GoalId = Annotated[str, AfterValidator(_check_id)]
"""A goal id as in goal models: ``G3``."""

RosName = Annotated[str, AfterValidator(_check_ros_name)]
"""A ROS-style global name: ``/rover/set_mode``."""

EndpointName = Annotated[str, AfterValidator(_check_endpoint_name)]
"""An actuation endpoint: a logical name the binding maps (``set_mode``) or a ROS name."""


def _check_payload_value(value: JsonValue, where: tuple[str | int, ...]) -> None:
    if len(where) > MAX_PAYLOAD_DEPTH:
        raise _error(
            "payload_depth",
            f"payload nested deeper than {MAX_PAYLOAD_DEPTH} levels",
            hint="flatten the payload",
            where=where[:1],
        )
    if isinstance(value, float) and not math.isfinite(value):
        raise _error(
            "payload_number",
            f"{value} is not allowed in a payload",
            hint="payload numbers must be finite (JSON has no NaN or infinity)",
            where=where,
        )
    if isinstance(value, str):
        bad = _BAD_CHARS.search(value)
        if bad:
            raise _error(
                "control_character",
                f"control character U+{ord(bad.group()):04X} is not allowed",
                hint="use plain text; tabs and newlines are the only control characters allowed",
                where=where,
            )
    elif isinstance(value, list):
        for i, item in enumerate(value):
            _check_payload_value(item, (*where, i))
    elif isinstance(value, dict):
        for key, item in value.items():
            if not key or _BAD_LINE_CHARS.search(key):
                raise _error(
                    "payload_key",
                    f"payload key {key!r} is empty or holds control characters",
                    hint="name payload fields with plain words",
                    where=where,
                )
            _check_payload_value(item, (*where, key))


def _check_payload(value: dict[str, JsonValue]) -> dict[str, JsonValue]:
    _check_payload_value(value, ())
    return value


Payload = Annotated[dict[str, JsonValue], AfterValidator(_check_payload)]
"""A message payload: JSON-like values (strings, finite numbers, booleans, null, lists, maps)."""

Seconds = Annotated[float, Field(allow_inf_nan=False)]


# --------------------------------------------------------------------------- source lines


@dataclass(frozen=True)
class SourceRef:
    """Where an element was written.

    Attributes:
        path: The file, or ``None`` for text parsed from memory without a name.
        line: 1-based line where the element starts, when known.

    """

    path: str | None = None
    line: int | None = None


class _Where:
    """Holds a :class:`SourceRef`; compares equal to every ``_Where`` (location is no content)."""

    __slots__ = ("ref",)

    def __init__(self, ref: SourceRef) -> None:
        self.ref = ref

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _Where)

    def __hash__(self) -> int:
        return 0

    def __repr__(self) -> str:
        return f"_Where({self.ref!r})"


_NOWHERE = SourceRef()


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    _where: _Where = PrivateAttr(default_factory=lambda: _Where(_NOWHERE))

    @property
    def source(self) -> SourceRef:
        """Where this element was written (``SourceRef(None, None)`` if built in code)."""
        return self._where.ref

    def _locate(self, ref: SourceRef) -> None:
        self._where = _Where(ref)


class GoalReference(NamedTuple):
    """One place a goal is named: element path and line."""

    element: str
    line: int | None


class EndpointReference(NamedTuple):
    """One topic or service an action uses, with the payload it sends."""

    kind: Literal["topic", "service"]
    name: str
    payload: dict[str, JsonValue]
    element: str
    line: int | None


class ExpressionReference(NamedTuple):
    """One utility-expression precondition, as written, with where it was written."""

    expression: str
    element: str
    line: int | None


def tactic_element(name: str, parts: Sequence[str | int]) -> str:
    """Render an element inside a tactic: ``tactics[fail-safe].actions[1].to``."""
    return f"tactics[{name}]" + ("." + element_path(parts) if parts else "")
