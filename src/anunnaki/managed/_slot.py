"""The managed-system slot: one plugin per ``kind``, a :class:`~anunnaki.plugins.Registry`.

A launch file names the system Utu adapts in its ``managed:`` section::

    managed: {kind: scripted, trace: trace.jsonl, speed: 5}     # the general form
    managed: {scripted: {trace: trace.jsonl, speed: 5}}         # the same, older form

``kind`` picks a plugin from :data:`MANAGED`: the built-ins ``scripted`` (a trace replayed
onto the bus), ``sim`` (a simulated platform with its detector and oracle), ``ros1`` and
``ros2`` (a real robot through a bridge), imported only when a launch file names them;
third parties register more under the ``anunnaki.managed`` entry-point group. A plugin is
a class with

* ``name`` and ``Options`` (a pydantic model: the section's other keys, validated with file
  and line like the rest of the launch file; an optional ``Options.removed``, option →
  what to do instead, turns a removed option into that advice at its line);
* ``__init__(options, *, base)`` — paths are relative to ``base`` (the launch file's folder);
* what :class:`ManagedKind` lists: ``speed``, ``check`` (bring-up checks, guideline B5),
  ``notes`` and ``start``, which returns a :class:`ManagedRun`; ``deterministic`` (optional,
  default false) says that the kind drains the run's executor (:class:`ManagedContext`).

Optional hooks are typed Protocols: :class:`WritesReports` for kinds that can keep the run
as data and a picture (``anunnaki run --report/--plot``); :class:`ServesModels` for kinds
whose camera chain runs a model manager, so that the launch checks the tactics' model swaps
against its registry before the run.

This layer sits below Utu: a kind sees Utu's settings through :class:`UtuSettings` (which
``anunnaki.utu.UtuConfig`` satisfies) and Utu's decisions as :class:`DecisionLike`.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol, runtime_checkable

from pydantic import BaseModel

from anunnaki.bus import Bus, Executor
from anunnaki.errors import ModelFileError
from anunnaki.plugins import Registry

__all__ = [
    "MANAGED",
    "DecisionLike",
    "DrawsScenarios",
    "ManagedContext",
    "ManagedKind",
    "ManagedRun",
    "ServesModels",
    "UtuSettings",
    "WritesReports",
]


class UtuSettings(Protocol):
    """What a kind reads of Utu's configuration (``anunnaki.utu.UtuConfig`` has it)."""

    @property
    def clock(self) -> str:
        """``wall`` or ``sim`` (time from ``/clock``)."""
        ...


class DecisionLike(Protocol):
    """What a kind reads of one of Utu's decisions (``anunnaki.utu.Decision`` has it)."""

    @property
    def t(self) -> float:
        """When it was taken (Utu's clock, s)."""
        ...

    @property
    def kind(self) -> str:
        """What happened: ``started``, ``action``, ``postcondition_ok`` and so on."""
        ...

    @property
    def tactic(self) -> str | None:
        """The tactic it concerns, if any."""
        ...


@dataclass
class ManagedContext:
    """What a managed system gets from the launch when it starts.

    Attributes:
        bus: The launch's bus.
        stop: Set when the run stops; a system's thread ends soon after.
        speed: Simulated or replayed seconds per wall second.
        until: Stop at this time of the system's own clock (``None``: at its end).
        say: Print one line of the launch's output.
        executor: The run's one thread of delivery, when it is one deterministic program
            (a simulated run in one process, :mod:`anunnaki.bus._executor`): a kind whose
            ``deterministic`` is true binds it to its thread, drains it after each instant
            (every node takes that instant's messages, Utu acts on them) and moves its
            clock on only then; ``None``: the bus's own threads deliver, and nothing
            waits for Utu (a live run: Utu takes whatever has arrived at each cycle).

    """

    bus: Bus
    stop: threading.Event
    speed: float
    until: float | None
    say: Callable[[str], None]
    executor: Executor | None = None


class ManagedRun(Protocol):
    """A managed system started by a launch."""

    #: The thread that drives it; the run ends (after ``linger``) once it has finished.
    thread: threading.Thread
    #: Why it finished by itself, e.g. ``trace ended``.
    ended: str

    def finish(self, decisions: Sequence[DecisionLike], ran: float) -> None:
        """Called once after the run stopped: print what it has to say (reports)."""
        ...

    def close(self) -> None:
        """Release everything it declared on the bus."""
        ...


class ManagedKind(Protocol):
    """A kind of managed system a launch file can name (``managed: {kind: NAME, …}``)."""

    name: ClassVar[str]
    Options: ClassVar[type[BaseModel]]
    #: The default speed (``anunnaki run --speed`` overrides it).
    speed: float

    def check(self, utu: UtuSettings) -> None:
        """Bring-up checks (B5): load what it needs now, raise a ModelFileError if it can't."""
        ...

    def notes(self, utu: UtuSettings, speed: float) -> list[str]:
        """Warnings about this combination of settings, printed at start."""
        ...

    def start(self, ctx: ManagedContext) -> ManagedRun:
        """Build the system on ``ctx.bus`` and start driving it in a thread."""
        ...


@runtime_checkable
class WritesReports(Protocol):
    """Optional: a kind that can keep its run as data (JSON) and draw it (``--report/--plot``)."""

    def with_reports(self, *, report: str | None, plot: str | None) -> None:
        """Write the run's report and plot to these files at the end."""
        ...


@runtime_checkable
class DrawsScenarios(Protocol):
    """Optional: a kind whose scenario a seed draws again, and that can end at a landing.

    ``anunnaki run --seed N --until-landed`` (and benchmarks/case_studies.py) use it.
    """

    def with_scenario(self, *, seed: int | None = None, until_landed: bool = False) -> None:
        """Draw the scenario from ``seed`` (its ``vary:``); end the run at the touch-down."""
        ...


@runtime_checkable
class ServesModels(Protocol):
    """Optional: a kind that runs a model manager (the LEC node answering ``/lm_manager/swap``).

    The launch loads the registry it names and checks every ``swap_model`` action of the
    tactics against it (the model ids and domains it has, the LEC it serves) at bring-up.
    """

    def model_registry(self) -> str | None:
        """The model registry file its model manager serves (``None``: it runs no detector)."""
        ...


def _check_kind(cls: Any) -> Any:
    options = getattr(cls, "Options", None)
    if not (isinstance(options, type) and issubclass(options, BaseModel)):
        raise ModelFileError(
            f"managed-system plugin {getattr(cls, '__name__', cls)!r} has no Options model",
            hint="give the class an 'Options' pydantic model for its launch-file section",
        )
    if not callable(getattr(cls, "start", None)):
        raise ModelFileError(f"managed-system plugin {cls.__name__!r} has no start(ctx)")
    return cls


#: The managed-system kinds: built-ins ``scripted``, ``sim``, ``ros1``, ``ros2``; plugins by
#: entry point (group ``anunnaki.managed``).
MANAGED: Registry[ManagedKind] = Registry(
    "managed system",
    group="anunnaki.managed",
    check=_check_kind,
    error=ModelFileError,
)
MANAGED.register_lazy("scripted", "anunnaki.managed._kinds:ScriptedKind")
MANAGED.register_lazy("sim", "anunnaki.managed._kinds:SimKind")
MANAGED.register_lazy("ros1", "anunnaki.managed._ros1:Ros1Kind")
MANAGED.register_lazy("ros2", "anunnaki.managed._ros2:Ros2Kind")
