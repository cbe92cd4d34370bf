"""What every host of the cycle has, written once: clock, watchdog, bring-up, execute side.

Utu's cycle (:mod:`anunnaki.utu.cycle`) has two hosts: :class:`~anunnaki.utu.AutonomicManager`
calls the five stages one after the other on one thread, and the five nodes
(:mod:`anunnaki.utu.host._nodes`) carry the stages' messages over the bus. Whatever both do
stands here (and in :mod:`anunnaki.utu.host._desk` for the operator side), so a change to it
is made once:

* :func:`host_clock` — the clock a host reads when none is given, and :func:`idle_wait`,
  how long its idle loop waits on it;
* :func:`watched` — the watchdog around a host's live loop (a beat per round);
* :func:`take_up` — a stage built on a run's knowledge records that it took the run up;
* :class:`ExecuteSide` — the execute stage with what it acts through: the actuator, the
  worker threads of blocking requests, the notifier's callback, and their close-down;
* :class:`StandIn` — the liveliness token and readiness service of a node that a host in
  this process stands for (the manager, for the five nodes of a launch's ``nodes:``), and
  :func:`ready_fields`, what every host's readiness reply says of Utu.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from typing import Any, TypeVar

from anunnaki.bus import Bus, Node
from anunnaki.clock import Clock, SimClock, WallClock
from anunnaki.topics import node_token, ready_service
from anunnaki.utu._config import UtuConfig
from anunnaki.utu.cycle._actions import ActionRunner
from anunnaki.utu.cycle._entries import mark_restart, resuming
from anunnaki.utu.cycle._execute import ExecuteStage
from anunnaki.utu.cycle._knowledge import Knowledge
from anunnaki.utu.cycle._mape import Actuator, Planner
from anunnaki.utu.cycle._parts import UtuParts
from anunnaki.utu.host._actuators import BusActuator, RecordingActuator, bus_actuator
from anunnaki.utu.host._desk import execute_stage, loop_watchdog
from anunnaki.utu.host._threads import ThreadRunner, action_runner

__all__ = [
    "ExecuteSide",
    "StandIn",
    "host_clock",
    "idle_wait",
    "ready_fields",
    "take_up",
    "watched",
]

S = TypeVar("S")


def host_clock(config: UtuConfig) -> Clock:
    """The clock of a host given none: sim time (``clock: sim``), else wall time."""
    return SimClock(max_jump=config.max_time_jump) if config.clock == "sim" else WallClock()


def idle_wait(clock: Clock, period: float) -> float:
    """Seconds of wall time an idle loop waits for work.

    ``period`` on the wall clock; on a simulation clock the period scaled by its speed (at
    most 0.5 s).
    """
    if isinstance(clock, SimClock) and clock.speed > 0:
        return min(period / max(clock.speed, 0.05), 0.5)
    return period


def ready_fields(utu: str, rate: float, run_stopped: bool) -> dict[str, Any]:
    """What every host's readiness reply (``/utu/<node>/ready``) says of Utu ``utu``."""
    return {"utu": utu, "rate": rate, "run_stopped": run_stopped}


def _no_watchdog() -> None:
    """The beat of a loop without a watchdog."""


@contextlib.contextmanager
def watched(
    bus: Bus | None, config: UtuConfig, *, what: str, name: str, floor: float
) -> Iterator[Callable[[], None]]:
    """The watchdog of one host's live loop, for the length of the ``with`` block.

    Yields the beat the loop calls at the start of every round: after ``max(watchdog,
    floor)`` seconds without one (``floor``: what an idle round may wait), the platform is
    run-stopped by ``watchdog:<name>`` (:func:`~anunnaki.utu.host._desk.loop_watchdog`).
    Without a ``watchdog`` configured, or without a bus, the beat does nothing.
    """
    dog = loop_watchdog(bus, config, what=what, caller=f"watchdog:{name}", floor=floor)
    if dog is None:
        yield _no_watchdog
        return
    try:
        yield dog.beat
    finally:
        dog.close()


def take_up(
    knowledge: Knowledge, node: str, build: Callable[[], S], *, restarted: bool | None = None
) -> S:
    """Build a stage (``build()``) for ``node`` on ``knowledge``; record a restart if it is one.

    ``restarted``: whether ``node`` takes up a run (default: as the knowledge says,
    :func:`~anunnaki.utu.cycle.resuming`, asked before the stage is built); a restart is
    recorded after (:func:`~anunnaki.utu.cycle.mark_restart`), where a replay restarts the
    same part.
    """
    if restarted is None:
        restarted = resuming(knowledge, node)
    stage = build()
    if restarted:
        mark_restart(knowledge, node)
    return stage


class ExecuteSide:
    """The execute stage of a host and what it acts through (one per host).

    Args:
        parts: The Utu parts (files and settings).
        knowledge: The knowledge base.
        bus: Where run-stops are announced and, by default, actions go; ``None``: nowhere
            (a manager fed by hand, a replay).
        actuator: How actions reach the managed system; default over ``bus`` with the
            configuration's notifier, or a :class:`RecordingActuator` without a bus.
        wake: Called when a blocking request came back (the host's loop takes it at once).
        actions: Runs blocking requests off the loop; default worker threads for a blocking
            actuator (:func:`~anunnaki.utu.host._threads.action_runner`).
        node: Build the stage as this node taking up a run (:func:`take_up`); ``None``: the
            host records its restart itself.

    """

    def __init__(
        self,
        parts: UtuParts,
        knowledge: Knowledge,
        *,
        bus: Bus | None,
        actuator: Actuator | None,
        wake: Callable[[], None],
        actions: ActionRunner | None = None,
        node: str | None = None,
    ) -> None:
        self.parts = parts
        self.knowledge = knowledge
        self.bus = bus
        if actuator is None:
            actuator = bus_actuator(bus, parts.config) if bus is not None else RecordingActuator()
        if isinstance(actuator, BusActuator) and actuator.on_notified is None:
            actuator.on_notified = self.notified
        self.actuator: Actuator = actuator
        self.actions = actions if actions is not None else action_runner(actuator, wake)
        self.closed = False
        self.stage: ExecuteStage = take_up(knowledge, node, self._build) if node else self._build()

    def _build(self, planner: Planner | None = None) -> ExecuteStage:
        return execute_stage(
            self.parts,
            self.knowledge,
            self.actuator,
            bus=self.bus,
            runner=self.actions,
            planner=planner,
        )

    def restart(self) -> None:
        """Build the stage again on the knowledge, as a restarted execute node does.

        It takes up the same store of tactic runtimes (the plan stage of this process
        selects among them, and it did not restart): what execute owns is read again from
        Knowledge.
        """
        planner = self.stage.planner
        self.stage = take_up(
            self.knowledge, "execute", lambda: self._build(planner), restarted=True
        )

    def run_inline(self) -> None:
        """Perform requests in the step itself: on an executor they are answered in its drain.

        What a manager on a deterministic executor does (:meth:`AutonomicManager.run_on`):
        a worker thread's request would wait for the very thread that waits for it.
        """
        if self.actions is not None:
            self.actions.close()
        self.actions = None
        self.stage.executor.runner = None

    def go_live(self, clock: Clock) -> None:
        """A live loop on the wall clock holds a cycle only briefly for a request's reply.

        On sim time a request is waited for up to its timeout, so a run repeats itself.
        """
        if isinstance(self.actions, ThreadRunner) and not isinstance(clock, SimClock):
            self.actions.settle = self.parts.config.action_settle

    def notified(self, tactic: str, result: Any) -> None:
        """A notification's delivery came back (the notifier's thread): record it.

        Recorded until the side is closed; delivery results arrive asynchronously, so a
        replay does not compare them.
        """
        if not self.closed:
            self.stage.notified(tactic, result)
            self.knowledge.flush()

    def close(self) -> None:
        """Abandon the action threads and stop the notifier."""
        self.closed = True
        if self.actions is not None:
            self.actions.close()
        notifier = getattr(self.actuator, "notifier", None)
        if notifier is not None:
            notifier.close()


class StandIn(Node):
    """The token ``/utu_<node>`` and readiness ``/utu/<node>/ready`` of a node stood for.

    A host that runs node ``node``'s stage itself (the manager standing for the five nodes
    of a launch) declares its presence through this, as the node would through
    :class:`~anunnaki.bus.Node`; ``info()`` gives the readiness reply's fields.
    """

    def __init__(self, bus: Bus, node: str, info: Callable[[], dict[str, Any]]) -> None:
        self._info = info
        super().__init__(bus, token=node_token(node), ready=ready_service(node))

    def ready_info(self) -> dict[str, Any]:
        """The fields of the host that stands for the node."""
        return self._info()
