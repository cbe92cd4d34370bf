"""The messages between Utu's MAPE-K parts, typed and versioned like every other message.

One cycle of Utu visits its parts in this order, whatever the deployment (one process, one
process per part, or any grouping)::

    monitor ─MonitorBatch─▶ analyze ─AnalysisState─▶ execute ─ExecuteStatus─▶ plan
                               ▲                        │◀──────PlanStart────────┘
                               └────────CycleDone───────┘

In one process the parts hand these objects to each other by direct calls (built without
validation: they come from our own code); between processes they travel on the bus
(``anunnaki.topics``: ``MONITOR_INPUT``, ``ANALYSIS``, ``EXECUTE_STATUS``, ``PLAN_START``,
``CYCLE_DONE``) and are validated when decoded, so a malformed or forged body never reaches
a part: it is dropped and counted by the bus.

Every body is a JSON object; optional fields that are unset are left out of it
(``exclude_none``), so a display reading ``/utu/analyze/state`` sees only what the sender
filled in.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, Self

from pydantic import Field, JsonValue, field_validator

from anunnaki.messages._base import MESSAGES, Message

__all__ = [
    "MAX_BATCH",
    "AnalysisState",
    "CycleDone",
    "ExecuteStatus",
    "MonitorBatch",
    "MonitorInput",
    "PlanStart",
]

_Op = dict[str, JsonValue]
#: How many inputs or operator calls one batch may carry (a bound, guideline S1).
MAX_BATCH = 65_536


class _CycleMessage(Message):
    """Common ground: bodies leave unset optional fields out; trusted values build fast."""

    def to_body(self) -> dict[str, Any]:
        """The JSON body, without unset (``None``) optional fields."""
        return self.model_dump(mode="json", exclude_none=True)

    @classmethod
    def trusted(cls, **values: Any) -> Self:
        """Build from values our own code made, without validation (the in-process path).

        What pydantic's ``model_construct`` does, minus its per-call inspection of each
        default factory (about 0.5 ms for this class on this machine, the whole budget of a
        reaction). Anything that crosses the bus is validated when decoded.
        """
        plan = _DEFAULTS.get(cls)
        if plan is None:
            plan = _DEFAULTS[cls] = [
                (name, f.default_factory, f.default) for name, f in cls.model_fields.items()
            ]
        data = {
            name: (values[name] if name in values else factory() if factory else default)
            for name, factory, default in plan
        }
        obj = cls.__new__(cls)
        object.__setattr__(obj, "__dict__", data)
        object.__setattr__(obj, "__pydantic_fields_set__", set(values))
        object.__setattr__(obj, "__pydantic_extra__", None)
        object.__setattr__(obj, "__pydantic_private__", None)
        return obj


_DEFAULTS: dict[type[_CycleMessage], list[tuple[str, Any, Any]]] = {}


def _finite(value: float) -> float:
    if not math.isfinite(value):
        raise ValueError("a time must be a finite number of seconds")
    return value


class _Timed(_CycleMessage):
    """A message of one cycle: where it comes from, which cycle, at what time."""

    origin: str = Field(default="", max_length=64)
    seq: int = Field(default=0, ge=0)
    t: float

    @field_validator("t")
    @classmethod
    def _finite_t(cls, value: float) -> float:
        return _finite(value)


@MESSAGES.register
class MonitorInput(_CycleMessage):
    """One message the Monitor took: its topic, its arrival time and its JSON body."""

    topic: str = Field(min_length=1, max_length=1024)
    t: float
    msg: dict[str, JsonValue]

    @field_validator("t")
    @classmethod
    def _finite_t(cls, value: float) -> float:
        return _finite(value)


@MESSAGES.register
class MonitorBatch(_Timed):
    """Monitor → analyze: what arrived since the last batch, up to time ``t``.

    Attributes:
        t: The time of the cycle (no input is later).
        inputs: The messages, each at its own arrival time, in arrival order.
        ops: Operator calls (``{op, caller, …}``) and node losses, in arrival order.

    An empty batch is a watermark: time has passed with no input.

    """

    TYPE_NAME: ClassVar[str | None] = "MonitorBatch"

    inputs: list[MonitorInput] = Field(default_factory=list, max_length=MAX_BATCH)
    ops: list[_Op] = Field(default_factory=list, max_length=MAX_BATCH)


@MESSAGES.register
class AnalysisState(_CycleMessage):
    """The analysis (``/utu/analyze/state``): what displays show and what execute acts on.

    Display fields: ``t``, ``root``, ``nodes`` (goal → ``[utility, status]``), ``violated``,
    ``tactics`` (applicable, sorted), and — from a whole manager — ``queue``, ``paused``,
    ``run_stopped``.

    Cycle fields (set when the message carries a cycle to execute): ``origin``, ``seq``,
    ``eligible`` (applicable tactics in file order), ``postconditions`` (tactic → whether
    its postconditions hold), ``post_goals`` (status of each goal a postcondition names),
    ``ops``, ``warming_up``, ``changed`` and ``took`` (the step took something — inputs,
    time, changes, operator calls — so its end is marked in Knowledge even if nothing is
    decided).
    """

    #: 2: ``taken`` (the inputs taken so far, read only by the scripted replay's removed
    #: ``sync``) went; a version-1 sender may still send it.
    VERSION: ClassVar[int] = 2
    TYPE_NAME: ClassVar[str | None] = "AnalysisState"

    t: float | None = None
    root: str = ""
    nodes: dict[str, list[float | str | None]] = Field(default_factory=dict)
    violated: list[str] = Field(default_factory=list)
    tactics: list[str] = Field(default_factory=list)
    queue: list[dict[str, JsonValue]] | None = None
    paused: bool | None = None
    run_stopped: bool | None = None
    origin: str | None = Field(default=None, max_length=64)
    seq: int | None = Field(default=None, ge=0)
    eligible: list[str] | None = None
    postconditions: dict[str, bool] | None = None
    post_goals: dict[str, str] | None = None
    ops: list[_Op] | None = None
    warming_up: bool | None = None
    changed: list[str] | None = None
    took: bool | None = None

    @field_validator("t")
    @classmethod
    def _finite_t(cls, value: float | None) -> float | None:
        return None if value is None else _finite(value)

    @property
    def is_cycle(self) -> bool:
        """Whether this analysis carries a cycle for execute (not only a display update)."""
        return self.seq is not None and self.t is not None and self.eligible is not None


@MESSAGES.register
class ExecuteStatus(_Timed):
    """Execute → plan: the in-flight state of every tactic after checking postconditions.

    Attributes:
        eligible: The applicable tactics (from the analysis).
        runtimes: Tactic → the execute-owned fields of its runtime and its state.
        approvals: ``[tactic, state]`` for each operator approval or rejection applied.
        ops: The operator calls of this cycle.
        paused: Adaptation is paused.
        run_stopped: A run-stop is in force.

    """

    TYPE_NAME: ClassVar[str | None] = "ExecuteStatus"

    eligible: list[str] = Field(default_factory=list)
    runtimes: dict[str, dict[str, JsonValue]] = Field(default_factory=dict)
    approvals: list[list[str]] = Field(default_factory=list)
    ops: list[_Op] = Field(default_factory=list)
    paused: bool = False
    run_stopped: bool = False


@MESSAGES.register
class PlanStart(_Timed):
    """Plan → execute: the tactics to start now, each tactic's selection state, the queue.

    Attributes:
        start: Tactics to start, highest priority first.
        states: Tactic → its selection state (``idle``, ``queued``, ``pending``, …).
        queue: The priority-sorted queue, for displays.
        decisions: How many decisions the plan part wrote this cycle.

    """

    TYPE_NAME: ClassVar[str | None] = "PlanStart"

    start: list[str] = Field(default_factory=list)
    states: dict[str, str] = Field(default_factory=dict)
    queue: list[dict[str, JsonValue]] = Field(default_factory=list)
    decisions: int = Field(default=0, ge=0)


@MESSAGES.register
class CycleDone(_Timed):
    """Execute → analyze: the cycle is finished (``started`` tactics, decisions written)."""

    TYPE_NAME: ClassVar[str | None] = "CycleDone"

    started: list[str] = Field(default_factory=list)
    decisions: int = Field(default=0, ge=0)
