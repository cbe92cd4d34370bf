"""The file formats: goal models (``goal-model/1``) and platform bindings (``binding/1``).

These pydantic models check the *shape* of a file (fields, types, bounds). Whether the
references between elements make sense (children that exist, agents that publish the
attributes an expression reads, cycles) is the job of :mod:`anunnaki.goals._model`, which
reports every such problem as a located finding.
"""

from __future__ import annotations

import math
import re
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from anunnaki.goals._relax_specs import RelaxSpec

__all__ = [
    "AgentBinding",
    "AgentSpec",
    "BindingSpec",
    "DomainPropertySpec",
    "EndpointSpec",
    "ForecastSpec",
    "GoalModelSpec",
    "GoalSpec",
    "ObstacleSpec",
    "PayloadField",
    "TopicBinding",
]

ID_PATTERN = r"^[A-Za-z][A-Za-z0-9_\-]*$"
ROS_NAME = re.compile(r"^(/[A-Za-z0-9_]+)+$")
FIELD_PATH = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")

Ident = Annotated[str, Field(pattern=ID_PATTERN, max_length=64)]


class _Strict(BaseModel):
    model_config = ConfigDict(
        extra="forbid", frozen=True, str_strip_whitespace=True, allow_inf_nan=False
    )


# The bus keeps services under ``<namespace>/srv/…`` (anunnaki.bus, ``SERVICE_SEGMENT``), so
# a topic may not start with this segment: the bus would refuse to publish or subscribe it.
_SERVICE_SEGMENT = "srv"


def _ros_name(value: str) -> str:
    if not ROS_NAME.match(value):
        raise ValueError(
            f"'{value}' is not a ROS-style name: it must start with '/' and use "
            "letters, digits and '_' in '/'-separated parts, e.g. /utu/oracle/output"
        )
    return value


def _topic_name(value: str) -> str:
    _ros_name(value)
    if value.split("/")[1] == _SERVICE_SEGMENT:
        raise ValueError(
            f"'{value}' cannot be a topic: the first part '/{_SERVICE_SEGMENT}' is reserved "
            "for services on the bus; rename the topic"
        )
    return value


class TopicBinding(_Strict):
    """A topic an agent publishes, and which message fields become its attributes.

    ``attributes`` maps attribute names to dotted field paths in the message
    (``{category: category, conf: assessment.confidence}``); a list ``[mode, buzzer]`` is
    shorthand for fields of the same name.
    """

    topic: str
    attributes: dict[str, str] = Field(default_factory=dict)

    @field_validator("topic")
    @classmethod
    def _check_topic(cls, v: str) -> str:
        return _topic_name(v)

    @field_validator("attributes", mode="before")
    @classmethod
    def _list_shorthand(cls, v: Any) -> Any:
        if isinstance(v, list):
            return {str(x): str(x) for x in v}
        return v

    @field_validator("attributes")
    @classmethod
    def _check_attributes(cls, v: dict[str, str]) -> dict[str, str]:
        for name, path in v.items():
            if not re.match(r"^[A-Za-z_][A-Za-z0-9_]*$", name):
                raise ValueError(f"attribute name '{name}' must be an identifier")
            if not FIELD_PATH.match(path):
                raise ValueError(
                    f"field path '{path}' of attribute '{name}' must be dotted identifiers, "
                    "e.g. assessment.category"
                )
        return v


class AgentSpec(_Strict):
    """A KAOS agent: a component (or person) responsible for goals; it publishes state.

    ``node`` names the bus node whose liveliness vouches for the agent: when that node's
    liveliness token disappears (its process died), the agent's values become unknown at
    once instead of at their staleness deadline.
    """

    id: Ident
    description: str = ""
    kind: Literal["software", "hardware", "human", "environment"] | None = None
    topics: list[TopicBinding] = Field(default_factory=list)
    staleness: Annotated[float, Field(gt=0)] | None = None
    node: str | None = None


class GoalSpec(_Strict):
    """A KAOS goal: refined into children, or a leaf with a utility function."""

    id: Ident
    description: str = ""
    objective: Literal["achieve", "maintain", "avoid"] = "achieve"
    refinement: Literal["and", "or"] | None = None
    children: list[Ident] = Field(default_factory=list)
    utility: str | None = None
    relax: RelaxSpec | None = None
    threshold: Annotated[float, Field(gt=0, le=1)] | None = None
    agents: list[Ident] = Field(default_factory=list)

    @model_validator(mode="after")
    def _shape(self) -> GoalSpec:
        if self.children and self.refinement is None:
            raise ValueError("a goal with children needs 'refinement: and' or 'refinement: or'")
        if self.refinement is not None and not self.children:
            raise ValueError("a refined goal needs at least one child in 'children'")
        if self.children and self.utility is not None:
            raise ValueError(
                "a refined goal takes its utility from its children; move 'utility' to a leaf goal"
            )
        if self.relax is not None and self.children:
            raise ValueError("'relax' applies to leaf goals with a utility, not to refined goals")
        if getattr(self.relax, "operator", None) == "may_or" and self.utility is not None:
            raise ValueError(
                "a may_or goal takes its utility from 'alternatives'; remove 'utility'"
            )
        if self.relax is not None and self.threshold is None:
            raise ValueError(
                "a RELAX-ed goal states its satisfaction 'threshold' (e.g. 0.5): "
                "the utility at which the relaxed requirement counts as met"
            )
        return self


class ObstacleSpec(_Strict):
    """A KAOS obstacle: a condition that obstructs goals, possibly resolved by other goals."""

    id: Ident
    description: str = ""
    obstructs: list[Ident] = Field(min_length=1)
    condition: str | None = None
    threshold: Annotated[float, Field(gt=0, le=1)] = 1.0
    resolutions: list[Ident] = Field(default_factory=list)
    agents: list[Ident] = Field(default_factory=list)


class DomainPropertySpec(_Strict):
    """A domain property: a fact assumed about the environment (documentation, checked refs)."""

    id: Ident
    description: str = ""
    condition: str | None = None


PayloadType = Literal["string", "number", "integer", "boolean", "object", "array", "any"]


class PayloadField(_Strict):
    """One field of an endpoint's payload."""

    type: PayloadType = "any"
    enum: list[str | int | float | bool] | None = None
    required: bool = True
    description: str = ""

    @field_validator("enum")
    @classmethod
    def _finite(cls, v: list[Any] | None) -> list[Any] | None:
        if v is not None and any(isinstance(x, float) and not math.isfinite(x) for x in v):
            raise ValueError("enum values must be finite")
        return v


LOGICAL_PATTERN = r"^[A-Za-z][A-Za-z0-9_]*$"


class EndpointSpec(_Strict):
    """An actuation endpoint of the managed system: a command topic or a service.

    ``name`` is the topic or service on the platform (``/rover/controller/set_mode``);
    ``logical`` is the platform-free name tactics use (``set_mode``), so the same tactics
    run on every binding that maps that logical name.
    """

    name: str
    kind: Literal["topic", "service"]
    logical: Annotated[str, Field(pattern=LOGICAL_PATTERN, max_length=64)] | None = None
    description: str = ""
    payload: dict[str, PayloadField] = Field(default_factory=dict)

    @field_validator("name")
    @classmethod
    def _check_name(cls, v: str) -> str:
        return _ros_name(v)

    @field_validator("payload", mode="before")
    @classmethod
    def _shorthand(cls, v: Any) -> Any:
        # ``payload: {mode: string}`` is shorthand for ``{mode: {type: string}}``.
        if isinstance(v, dict):
            return {k: ({"type": x} if isinstance(x, str) else x) for k, x in v.items()}
        return v

    @model_validator(mode="after")
    def _topic_not_reserved(self) -> EndpointSpec:
        if self.kind == "topic":
            _topic_name(self.name)
        return self


class GoalModelSpec(_Strict):
    """A goal-model file."""

    anunnaki: Literal["goal-model/1"]
    name: str
    description: str = ""
    root: Ident | None = None
    unknown_policy: Literal["unsatisfied", "satisfied"] = "unsatisfied"
    staleness: Annotated[float, Field(gt=0)] = 2.0
    rate_window: Annotated[int, Field(ge=1, le=1000)] = 10
    agents: list[AgentSpec] = Field(default_factory=list)
    goals: list[GoalSpec] = Field(min_length=1)
    obstacles: list[ObstacleSpec] = Field(default_factory=list)
    domain_properties: list[DomainPropertySpec] = Field(default_factory=list)
    endpoints: list[EndpointSpec] = Field(default_factory=list)


ATTR_REF = re.compile(r"^[A-Za-z][A-Za-z0-9_]*\.[A-Za-z_][A-Za-z0-9_]*$")


def _input(value: Any, what: str, *, positive: bool) -> Any:
    """A forecast's input: ``Agent.attribute`` (text) or a number (no expression, no eval)."""
    if isinstance(value, bool):
        raise ValueError(f"'{what}' is a number or an attribute such as A1.{what}, not {value}")
    if isinstance(value, int | float):
        if not math.isfinite(value) or value < 0 or (positive and value == 0):
            bound = "> 0" if positive else ">= 0"
            raise ValueError(f"'{what}' as a number must be finite and {bound}, not {value}")
        return float(value)
    if isinstance(value, str) and ATTR_REF.match(value.strip()):
        return value.strip()
    raise ValueError(
        f"'{what}' must be a number or an agent's attribute written Agent.attribute "
        f"(e.g. A1.{what}), not {value!r}"
    )


class ForecastSpec(_Strict):
    """An anticipatory attribute: where a monitored field will be at the end of a route.

    The field ``of`` (an attribute of the same agent) is extrapolated along its rate of
    change over the last ``window`` seconds of its samples, for the time the rest of the
    route takes: ``distance / speed``. So ``value + rate × distance / speed``; e.g. the
    battery expected at home from its drain, the metres still to fly and the cruise speed.
    ``distance`` and ``speed`` are attributes (``A1.route_m``) or numbers.
    """

    of: Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")]
    window: Annotated[float, Field(gt=0, le=3600)]
    distance: str | float
    speed: str | float
    description: str = ""

    @field_validator("distance", mode="before")
    @classmethod
    def _distance(cls, v: Any) -> Any:
        return _input(v, "distance", positive=False)

    @field_validator("speed", mode="before")
    @classmethod
    def _speed(cls, v: Any) -> Any:
        return _input(v, "speed", positive=True)


class AgentBinding(_Strict):
    """How one agent is observed on one platform, and the forecasts made from it."""

    topics: list[TopicBinding] = Field(min_length=1)
    staleness: Annotated[float, Field(gt=0)] | None = None
    node: str | None = None
    forecasts: dict[
        Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$", max_length=64)], ForecastSpec
    ] = Field(default_factory=dict)


class BindingSpec(_Strict):
    """A platform-binding file: agents → topics and fields, plus actuation endpoints."""

    anunnaki: Literal["binding/1"]
    platform: str
    description: str = ""
    agents: dict[Ident, AgentBinding] = Field(default_factory=dict)
    endpoints: list[EndpointSpec] = Field(default_factory=list)
