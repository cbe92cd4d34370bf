"""The tactics model (``tactics/1``): what a tactic is, whichever file it came from.

Both file forms (XML as in the paper's Fig. 10, and YAML) are read into the same plain data
(dicts, lists, scalars) together with a :class:`~anunnaki._safeyaml.LineMap` from element paths
to lines; :func:`build_tactic_set` validates that data with the pydantic models below and turns
the first problem into a :class:`~anunnaki.errors.ModelFileError` naming file, line and element.

Where an element was written is not part of what it *is*: every model keeps a private
:class:`SourceRef` (read it through ``.source``) that takes no part in equality or dumps, so
a tactic loaded from XML equals the same tactic loaded from YAML. Loaders set it after
validation from the same element-path → line map that locates their errors.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Final, Literal, NamedTuple

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    JsonValue,
    PrivateAttr,
    Tag,
    ValidationError,
    model_validator,
)
from pydantic_core import PydanticCustomError

from anunnaki import topics
from anunnaki._safeyaml import LineMap, element_path
from anunnaki.errors import ModelFileError

__all__ = [
    "ACTION_TYPES",
    "FORMAT_TAG",
    "GOAL_STATES",
    "MAX_DEPTH",
    "MAX_PAYLOAD_DEPTH",
    "NOTIFY_CHANNELS",
    "Action",
    "ChangeModeAction",
    "EndpointReference",
    "ExpressionCondition",
    "ExpressionReference",
    "GoalReference",
    "GoalState",
    "NotifyAction",
    "Precondition",
    "PublishAction",
    "RequestAction",
    "SourceRef",
    "SwapModelAction",
    "Tactic",
    "TacticSet",
    "build_tactic_set",
]

FORMAT_TAG: Final = "tactics/1"
"""The format tag (and version) a YAML tactics file starts with: ``anunnaki: tactics/1``."""

GOAL_STATES: Final = ("satisfied", "unsatisfied", "unknown")
"""The states a goal can be required to be in."""

ACTION_TYPES: Final = ("publish", "request", "change_mode", "swap_model", "notify")
"""The action types, in the order the docs present them."""

NOTIFY_CHANNELS: Final = ("email", "webhook", "log")
"""Where a :class:`NotifyAction` sends its message."""

MAX_DEPTH: Final = 32
"""Deepest element nesting accepted in a tactics file (XML elements, YAML nodes)."""

MAX_PAYLOAD_DEPTH: Final = 16
"""Deepest nesting accepted inside one action payload."""

_ID = re.compile(r"[A-Za-z][A-Za-z0-9_\-]*")
_ROS_NAME = re.compile(r"(/[A-Za-z0-9_]+)+")
_EMAIL = re.compile(r"[^@\s]+@[^@\s]+\.[^@\s]+")
_URL = re.compile(r"https?://[^\s/?#]+\S*")
# Control characters (C0 but tab and newline, DEL, C1) and what XML 1.0 cannot hold: they
# cannot be written to one form or the other (or would be normalised away on reading).
_BAD_CHARS = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f\ud800-\udfff\ufffe\uffff]")
_BAD_LINE_CHARS = re.compile(r"[\x00-\x1f\x7f-\x9f\ud800-\udfff\ufffe\uffff]")

ACTION_HINT: Final = "valid action types: " + ", ".join(ACTION_TYPES)
STATE_HINT: Final = "valid states: " + ", ".join(GOAL_STATES)
CHANNEL_HINT: Final = "valid channels: " + ", ".join(NOTIFY_CHANNELS)
ROS_HINT: Final = (
    "a ROS-style name starts with '/' and uses letters, digits and '_' in '/'-separated "
    "parts, e.g. /rover/set_mode"
)


def _error(kind: str, message: str, *, hint: str | None = None, **ctx: Any) -> PydanticCustomError:
    """Build a pydantic error whose context carries a hint (and, in ``where``, a sub-path)."""
    context: dict[str, Any] = dict(ctx)
    if hint is not None:
        context["hint"] = hint
    # Braces would be read as placeholders by pydantic; messages here never need them.
    return PydanticCustomError(kind, message.replace("{", "(").replace("}", ")"), context)


# --------------------------------------------------------------------------- value types


def _check_text(value: str) -> str:
    bad = _BAD_CHARS.search(value)
    if bad:
        raise _error(
            "control_character",
            f"control character U+{ord(bad.group()):04X} is not allowed",
            hint="use plain text; tabs and newlines are the only control characters allowed",
        )
    return value


def _check_line(value: str) -> str:
    bad = _BAD_LINE_CHARS.search(value)
    if bad:
        raise _error(
            "control_character",
            f"control character U+{ord(bad.group()):04X} is not allowed here",
            hint="this value is one line of plain text",
        )
    return value


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


# --------------------------------------------------------------------------- conditions


class GoalState(_Model):
    """A goal in a state: ``{goal: G3, state: unsatisfied}``.

    As a precondition it holds when the goal is in that state; as a postcondition the goal is
    expected in that state by the tactic's deadline. ``unknown`` means the goal cannot be
    evaluated (a value is missing or stale).
    """

    goal: GoalId
    state: Literal["satisfied", "unsatisfied", "unknown"]


class ExpressionCondition(_Model):
    """A precondition given as a utility expression: ``{expression: "A4.category >= 1"}``.

    The string is kept as written; :mod:`anunnaki.goals` compiles it against the goal model's
    agents, and the precondition holds when the expression is true.
    """

    expression: Annotated[Text, Filled]


def _precondition_form(value: Any) -> str | None:
    if isinstance(value, GoalState):
        return "goal"
    if isinstance(value, ExpressionCondition):
        return "expression"
    if isinstance(value, Mapping):
        if "expression" in value and "goal" not in value and "state" not in value:
            return "expression"
        if "goal" in value or "state" in value:
            return None if "expression" in value else "goal"
    return None


PRECONDITION_HINT: Final = (
    "write either goal and state (e.g. goal: G3, state: unsatisfied) or expression"
)

Precondition = Annotated[
    Annotated[GoalState, Tag("goal")] | Annotated[ExpressionCondition, Tag("expression")],
    Discriminator(
        _precondition_form,
        custom_error_type="precondition_form",
        custom_error_message="a precondition is either a goal state or an expression",
        custom_error_context={"hint": PRECONDITION_HINT},
    ),
]
"""A precondition: a :class:`GoalState` or an :class:`ExpressionCondition`."""


# --------------------------------------------------------------------------- actions


class PublishAction(_Model):
    """Publish one message on a topic of the managed system."""

    type: Literal["publish"] = "publish"
    topic: RosName
    payload: Payload

    def endpoint(self) -> tuple[Literal["topic", "service"], str, dict[str, JsonValue]]:
        """Return ``(kind, name, payload)`` of what this action sends."""
        return "topic", self.topic, dict(self.payload)


class RequestAction(_Model):
    """Call a service of the managed system and wait up to ``timeout`` seconds for the reply."""

    type: Literal["request"] = "request"
    service: RosName
    payload: Payload = Field(default_factory=dict)
    timeout: Annotated[Seconds, Field(gt=0)] = 2.0

    def endpoint(self) -> tuple[Literal["topic", "service"], str, dict[str, JsonValue]]:
        """Return ``(kind, name, payload)`` of what this action sends."""
        return "service", self.service, dict(self.payload)


class ChangeModeAction(_Model):
    """Ask the managed system to change mode: a request ``{"mode": mode}`` to ``service``."""

    type: Literal["change_mode"] = "change_mode"
    mode: Token
    service: RosName

    def endpoint(self) -> tuple[Literal["topic", "service"], str, dict[str, JsonValue]]:
        """Return ``(kind, name, payload)`` of what this action sends."""
        return "service", self.service, {"mode": self.mode}


class SwapModelAction(_Model):
    """Ask the model manager to swap the model of a learning-enabled component.

    Give exactly one of ``model`` (a model id in the registry) or ``domain`` (the manager picks
    the model robustified for that domain, e.g. ``fog``).
    """

    type: Literal["swap_model"] = "swap_model"
    lec: Token = "detector"
    model: Token | None = None
    domain: Token | None = None
    service: RosName = topics.SWAP

    @model_validator(mode="after")
    def _one_target(self) -> SwapModelAction:
        if (self.model is None) == (self.domain is None):
            both = self.model is not None
            raise _error(
                "swap_target",
                "give either 'model' or 'domain', not both"
                if both
                else "say what to swap to: 'model' or 'domain'",
                hint="model is a model id (e.g. detector-fog-v2); domain lets the manager pick "
                "(e.g. fog)",
            )
        return self

    def endpoint(self) -> tuple[Literal["topic", "service"], str, dict[str, JsonValue]]:
        """Return ``(kind, name, payload)`` of what this action sends."""
        payload: dict[str, JsonValue] = {"lec": self.lec}
        if self.model is not None:
            payload["model"] = self.model
        else:
            payload["domain"] = self.domain
        return "service", self.service, payload


class NotifyAction(_Model):
    """Tell a person: an e-mail, a webhook call, or a log record.

    ``to`` is required for ``email`` (an address) and ``webhook`` (an http(s) URL); for ``log``
    it optionally names the logger.
    """

    type: Literal["notify"] = "notify"
    channel: Literal["email", "webhook", "log"]
    to: Token | None = None
    subject: Line = ""
    message: Annotated[Text, Filled]

    @model_validator(mode="after")
    def _recipient(self) -> NotifyAction:
        if self.channel == "email" and (self.to is None or not _EMAIL.fullmatch(self.to)):
            raise _error(
                "notify_to",
                "an email notification needs 'to': an e-mail address"
                if self.to is None
                else f"{self.to!r} is not an e-mail address",
                hint="e.g. to: operator@example.com",
                where=("to",),
            )
        if self.channel == "webhook" and (self.to is None or not _URL.fullmatch(self.to)):
            raise _error(
                "notify_to",
                "a webhook notification needs 'to': an http(s) URL"
                if self.to is None
                else f"{self.to!r} is not an http(s) URL",
                hint="e.g. to: https://hooks.example.com/rover",
                where=("to",),
            )
        return self

    def endpoint(self) -> None:
        """Return ``None``: a notification uses no topic or service of the managed system."""
        return None


Action = Annotated[
    PublishAction | RequestAction | ChangeModeAction | SwapModelAction | NotifyAction,
    Field(discriminator="type"),
]
"""An action, told apart by its ``type``."""

ACTION_CLASSES: Final[dict[str, type[_Model]]] = {
    "publish": PublishAction,
    "request": RequestAction,
    "change_mode": ChangeModeAction,
    "swap_model": SwapModelAction,
    "notify": NotifyAction,
}


# --------------------------------------------------------------------------- tactics


class Tactic(_Model):
    """An adaptation tactic: when all preconditions hold, run the actions in order.

    Attributes:
        name: Unique within its set.
        description: Free text for people (dashboard, decision log).
        priority: Higher runs first when several tactics apply at once.
        preconditions: All must hold for the tactic to apply (at least one).
        actions: Run in order (at least one).
        postconditions: Goal states expected after the actions, checked by ``deadline``.
        deadline: Seconds after the last action by which the postconditions must hold.
        cooldown: Seconds after a run during which the tactic is not started again.
        requires_approval: An operator must approve each run before it starts.
        conflicts: Names of tactics that must not be in flight at the same time.

    """

    name: Annotated[Line, Filled, Field(max_length=128)]
    description: Text = ""
    priority: int = 0
    preconditions: Annotated[list[Precondition], Field(min_length=1)]
    actions: Annotated[list[Action], Field(min_length=1)]
    postconditions: list[GoalState] = Field(default_factory=list)
    deadline: Annotated[Seconds, Field(gt=0)] = 5.0
    cooldown: Annotated[Seconds, Field(ge=0)] = 0.0
    requires_approval: bool = False
    conflicts: list[Annotated[Line, Filled]] = Field(default_factory=list)

    @model_validator(mode="after")
    def _consistent(self) -> Tactic:
        seen: dict[str, int] = {}
        for i, cond in enumerate(self.preconditions):
            if isinstance(cond, GoalState):
                if cond.goal in seen:
                    raise _error(
                        "repeated_goal",
                        f"goal {cond.goal} appears twice in the preconditions",
                        hint="state each goal once",
                        where=("preconditions", i),
                    )
                seen[cond.goal] = i
        seen.clear()
        for i, cond in enumerate(self.postconditions):
            if cond.goal in seen:
                raise _error(
                    "repeated_goal",
                    f"goal {cond.goal} appears twice in the postconditions",
                    hint="state each goal once",
                    where=("postconditions", i),
                )
            seen[cond.goal] = i
        names: set[str] = set()
        for i, other in enumerate(self.conflicts):
            if other == self.name:
                raise _error(
                    "conflict_self",
                    f"tactic {self.name!r} lists itself in 'conflicts'",
                    hint="a tactic never runs twice at once anyway; remove it",
                    where=("conflicts", i),
                )
            if other in names:
                raise _error(
                    "conflict_repeated",
                    f"{other!r} appears twice in 'conflicts'",
                    hint="name each tactic once",
                    where=("conflicts", i),
                )
            names.add(other)
        return self

    def _element(self, *parts: str | int) -> str:
        return tactic_element(self.name, parts)

    def _goal_refs(self) -> Iterator[tuple[str, GoalReference]]:
        for key, conditions in (
            ("preconditions", self.preconditions),
            ("postconditions", self.postconditions),
        ):
            for i, cond in enumerate(conditions):
                if isinstance(cond, GoalState):
                    yield cond.goal, GoalReference(self._element(key, i), cond.source.line)

    def referenced_goals(self) -> dict[str, list[GoalReference]]:
        """Map each goal id this tactic names to where it names it.

        Returns:
            ``{"G3": [GoalReference("tactics[fail-safe].preconditions[0]", 9), ...]}``, in
            file order (preconditions, then postconditions).

        """
        out: dict[str, list[GoalReference]] = {}
        for goal, ref in self._goal_refs():
            out.setdefault(goal, []).append(ref)
        return out

    def referenced_endpoints(self) -> list[EndpointReference]:
        """List every topic and service the actions use, with the payload each sends.

        ``change_mode`` sends ``{"mode": mode}``; ``swap_model`` sends ``{"lec": …, "model": …}``
        or ``{"lec": …, "domain": …}``; ``notify`` uses no endpoint and is not listed.
        """
        out: list[EndpointReference] = []
        for i, action in enumerate(self.actions):
            sent = action.endpoint()
            if sent is not None:
                kind, name, payload = sent
                out.append(
                    EndpointReference(
                        kind, name, payload, self._element("actions", i), action.source.line
                    )
                )
        return out

    def expressions(self) -> list[ExpressionReference]:
        """List the expression preconditions, as written, with element and line."""
        return [
            ExpressionReference(
                cond.expression, self._element("preconditions", i), cond.source.line
            )
            for i, cond in enumerate(self.preconditions)
            if isinstance(cond, ExpressionCondition)
        ]


class TacticSet(_Model):
    """The tactics of one file.

    Attributes:
        name: Optional name of the set (e.g. the managed system).
        tactics: The tactics, names unique; ``conflicts`` must name tactics of this set.

    """

    name: Annotated[Line, Filled] | None = None
    tactics: list[Tactic]

    @model_validator(mode="after")
    def _names(self) -> TacticSet:
        first: dict[str, int] = {}
        for i, tactic in enumerate(self.tactics):
            if tactic.name in first:
                raise _error(
                    "duplicate_tactic",
                    f"tactic name {tactic.name!r} is used twice",
                    hint="give each tactic its own name",
                    where=("tactics", i, "name"),
                    other=("tactics", first[tactic.name], "name"),
                )
            first[tactic.name] = i
        for i, tactic in enumerate(self.tactics):
            for k, other in enumerate(tactic.conflicts):
                if other not in first:
                    raise _error(
                        "unknown_conflict",
                        f"tactic {tactic.name!r} conflicts with {other!r}, which is not "
                        "a tactic of this file",
                        hint="known tactics: " + ", ".join(sorted(first)),
                        where=("tactics", i, "conflicts", k),
                    )
        return self

    def tactic(self, name: str) -> Tactic:
        """Return the tactic called ``name``.

        Raises:
            KeyError: no such tactic (the message lists the known names).

        """
        for tactic in self.tactics:
            if tactic.name == name:
                return tactic
        raise KeyError(f"no tactic {name!r}; known: {', '.join(t.name for t in self.tactics)}")

    def by_priority(self) -> list[Tactic]:
        """Return the tactics highest priority first; equal priorities keep file order."""
        return sorted(self.tactics, key=lambda t: -t.priority)

    def in_conflict(self, a: str, b: str) -> bool:
        """Tell whether tactics ``a`` and ``b`` must not be in flight together.

        Conflicts are symmetric: it is enough that either tactic lists the other.
        """
        return b in self.tactic(a).conflicts or a in self.tactic(b).conflicts

    def referenced_goals(self) -> dict[str, list[GoalReference]]:
        """Map each goal id named anywhere in the set to the places that name it."""
        out: dict[str, list[GoalReference]] = {}
        for tactic in self.tactics:
            for goal, ref in tactic._goal_refs():
                out.setdefault(goal, []).append(ref)
        return out

    def referenced_endpoints(self) -> list[EndpointReference]:
        """List every topic and service used by any action, in file order."""
        return [ref for t in self.tactics for ref in t.referenced_endpoints()]

    def expressions(self) -> list[ExpressionReference]:
        """List every expression precondition in the set, in file order."""
        return [ref for t in self.tactics for ref in t.expressions()]


# --------------------------------------------------------------------------- loading


def _without_tags(loc: Sequence[str | int]) -> tuple[str | int, ...]:
    """Drop the union tag pydantic puts after ``tactics[i].actions[j]`` (and preconditions)."""
    out = tuple(loc)
    if (
        len(out) > 4
        and out[0] == "tactics"
        and isinstance(out[1], int)
        and isinstance(out[3], int)
        and (
            (out[2] == "actions" and out[4] in ACTION_CLASSES)
            or (out[2] == "preconditions" and out[4] in ("goal", "expression"))
        )
    ):
        return (*out[:4], *out[5:])
    return out


def _model_at(loc: Sequence[str | int], data: Any) -> type[BaseModel] | None:
    """Return the model class of the element at ``loc`` (for "valid fields" hints)."""
    if not loc:
        return TacticSet
    if len(loc) < 2 or loc[0] != "tactics" or not isinstance(loc[1], int):
        return None
    if len(loc) == 2:
        return Tactic
    if len(loc) != 4 or not isinstance(loc[3], int):
        return None
    node = data
    for part in loc:
        node = node[part]  # an extra field was found there, so the path exists
    if loc[2] == "postconditions":
        return GoalState
    if loc[2] == "preconditions":
        return ExpressionCondition if _precondition_form(node) == "expression" else GoalState
    if loc[2] == "actions" and isinstance(node, Mapping):
        return ACTION_CLASSES.get(str(node.get("type")))
    return None


def _data_path(data: Any, loc: Sequence[str | int]) -> tuple[str | int, ...]:
    """Follow an error location through the data as far as it goes."""
    path: list[str | int] = []
    node = data
    for part in loc:
        found = (isinstance(node, Mapping) and part in node) or (
            isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node)
        )
        if not found:
            break
        node = node[part]
        path.append(part)
    return tuple(path)


def _render(data: Any, path: Sequence[str | int]) -> str:
    """Render a data path, naming tactics by name: ``tactics[fail-safe].actions[1].to``."""
    if len(path) >= 2 and path[0] == "tactics" and isinstance(path[1], int):
        try:
            name = data["tactics"][path[1]]["name"]
        except (KeyError, IndexError, TypeError):
            name = None
        if isinstance(name, str) and name.strip():
            return tactic_element(name.strip(), path[2:])
    return element_path(path)


def _hint(err: Mapping[str, Any], loc: Sequence[str | int], data: Any) -> str | None:
    ctx = err.get("ctx") or {}
    if "hint" in ctx:
        return str(ctx["hint"])
    kind = err["type"]
    names = [p for p in loc if isinstance(p, str)]
    last = names[-1] if names else ""
    if kind in ("union_tag_invalid", "union_tag_not_found") or (
        kind == "model_attributes_type" and len(loc) == 4 and loc[2] == "actions"
    ):
        return ACTION_HINT + " (each action says which in 'type')"
    if kind == "literal_error":
        return {"state": STATE_HINT, "channel": CHANNEL_HINT, "type": ACTION_HINT}.get(last)
    if kind == "missing":
        return f"add '{last}'"
    if kind == "extra_forbidden":
        model = _model_at(loc[:-1], data)
        return None if model is None else "valid fields here: " + ", ".join(model.model_fields)
    if kind == "too_short" and last in ("preconditions", "actions"):
        return f"a tactic needs at least one entry in '{last}'"
    if kind in ("greater_than", "greater_than_equal", "finite_number") and last in (
        "deadline",
        "cooldown",
        "timeout",
    ):
        return "give seconds as a finite number" + (
            " above 0" if kind == "greater_than" else " (0 or more)"
        )
    return None


def _message(err: Mapping[str, Any], loc: Sequence[str | int]) -> str:
    kind = err["type"]
    in_actions = len(loc) == 4 and loc[2] == "actions"
    if kind == "union_tag_invalid":
        return f"unknown action type {err['ctx']['tag']!r}"
    if kind == "union_tag_not_found":
        return "the action has no 'type'"
    if kind == "model_attributes_type" and in_actions:
        return "an action is a mapping with a 'type' and its fields"
    if kind == "extra_forbidden":
        return f"unknown field {loc[-1]!r}"
    if kind == "missing":
        return f"missing field {loc[-1]!r}"
    return str(err["msg"])


def validation_error(
    exc: ValidationError, data: Any, lines: LineMap, source: str | Path | None
) -> ModelFileError:
    """Turn a pydantic error about ``data`` into a located :class:`ModelFileError`.

    Of several problems, the one written first in the file is reported, and the message says
    how many more there are.
    """
    found: list[tuple[int, int, ModelFileError]] = []
    for order, err in enumerate(exc.errors(include_url=False)):
        ctx = err.get("ctx") or {}
        loc = _without_tags((*err["loc"], *ctx.get("where", ())))
        path = _data_path(data, loc)
        line = lines.line(path)
        shown = (*path, loc[-1]) if err["type"] == "missing" and len(loc) > len(path) else path
        message = _message(err, loc)
        if "other" in ctx:
            other = lines.line(_data_path(data, tuple(ctx["other"])))
            if other is not None and line is not None:
                message += f", on lines {other} and {line}"
        problem = ModelFileError(
            message,
            path=source,
            line=line,
            element=_render(data, shown) if shown else None,
            hint=_hint(err, loc, data),
        )
        found.append((line if line is not None else 0, order, problem))
    found.sort(key=lambda item: (item[0], item[1]))
    first = found[0][2]
    if len(found) > 1:
        more = len(found) - 1
        first = ModelFileError(
            f"{first.message} (and {more} more problem{'s' if more > 1 else ''})",
            path=first.path,
            line=first.line,
            element=first.element,
            hint=first.hint,
        )
    return first


def build_tactic_set(data: Any, lines: LineMap, source: str | Path | None) -> TacticSet:
    """Validate plain data (read from either file form) into a located :class:`TacticSet`.

    Args:
        data: The file's content as dicts/lists/scalars, without the YAML format tag.
        lines: Element path → line, for error messages and for every element's ``source``.
        source: The file name for messages, or ``None``.

    Raises:
        ModelFileError: the first problem, with file, line, element and a hint.

    """
    if not isinstance(data, Mapping):
        raise ModelFileError(
            "a tactics file holds a mapping with a 'tactics' list",
            path=source,
            line=lines.line(()),
            hint=f"start the file with 'anunnaki: {FORMAT_TAG}' and a 'tactics:' list",
        )
    try:
        tactic_set = TacticSet.model_validate(data)
    except ValidationError as exc:
        raise validation_error(exc, data, lines, source) from None
    path = None if source is None else str(source)

    def at(*parts: str | int) -> SourceRef:
        return SourceRef(path, lines.line(parts))

    tactic_set._locate(at())
    for i, tactic in enumerate(tactic_set.tactics):
        tactic._locate(at("tactics", i))
        for j, cond in enumerate(tactic.preconditions):
            if isinstance(cond, ExpressionCondition):
                cond._locate(at("tactics", i, "preconditions", j, "expression"))
            else:
                cond._locate(at("tactics", i, "preconditions", j))
        for j, action in enumerate(tactic.actions):
            action._locate(at("tactics", i, "actions", j))
        for j, post in enumerate(tactic.postconditions):
            post._locate(at("tactics", i, "postconditions", j))
    return tactic_set
