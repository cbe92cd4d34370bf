"""Utu as nodes: the five MAPE-K services on the bus, in one process or one process each.

The paper runs Utu as ROS nodes (§4.1.4, Fig. 13): ``/utu_monitor``, ``/utu_analyze``,
``/utu_plan``, ``/utu_execute`` and ``/utu_knowledge``. Each node here hosts one stage of
:mod:`anunnaki.utu.cycle` — the very code :class:`~anunnaki.utu.AutonomicManager` calls
directly — and carries the stage's typed messages over the bus, so a node runs alone
(``anunnaki node plan``), with others in one process, or each in its own process over
zenoh, and every grouping decides as the manager does.

How a cycle travels::

    monitor ─ /utu/monitor/input ─▶ analyze ─ /utu/analyze/state ─▶ execute: ops, check
       ▲                              ▲                                │
    agent topics               /utu/execute/done              /utu/execute/status
                                      │                                ▼
                                   execute: start ◀─ /utu/plan/start ─ plan: update

The analyze node owns the cycle: it starts cycle *k+1* only when the execute node reports
cycle *k* done (or, if execute is absent or silent, after a timeout), so plan and execute
see exactly the analyses, times and tactic states the composed manager would.

Event-driven: every node acts on a message the moment it arrives (its subscribers' doorbell
wakes it); nothing on the path of a violation waits for a rate tick. A node's ``rate``
bounds only what is time-driven — the monitor's watermarks (an empty batch telling analyze
how far time has gone with no input), the analyze node's own ticks when no monitor is up,
the knowledge node's decision publications — and, since a busy node takes everything
queued in one round, the load under a flood.

All nodes share ONE knowledge base, the SQLite file of the configuration (WAL mode lets
several processes write it); each stage commits what it wrote before handing on.

What every node has (the node kit, :class:`anunnaki.bus.Node`)
    a liveliness token ``/utu_<name>``; a readiness service ``/utu/<name>/ready``, declared
    last; a bring-up that fails explicitly on bad configuration, naming file and line (B5);
    a ``/utu/run_stop`` subscription (S4): plan and execute stop starting tactics at once,
    the monitor turns it into an operator input so the run-stop is recorded and the
    managed system commanded to stop, exactly as the composed manager does.

``step``/``step_nodes`` drive nodes deterministically (tests, replay); ``spin`` runs live.
"""

from __future__ import annotations

import logging
import secrets
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar, cast

from anunnaki import topics
from anunnaki.bus import Bus, Node, Sample, Subscriber
from anunnaki.clock import Clock, WallClock
from anunnaki.errors import AnunnakiError
from anunnaki.messages import (
    MAX_BATCH,
    AnalysisState,
    CycleDone,
    ExecuteStatus,
    MonitorBatch,
    PlanStart,
    body_of,
)
from anunnaki.plugins import Registry
from anunnaki.topics import UTU_NODES as NODE_NAMES
from anunnaki.topics import UtuNodeName as NodeName
from anunnaki.topics import node_token, ready_service
from anunnaki.utu._config import UtuConfig
from anunnaki.utu.cycle._analyze import AnalyzeStage
from anunnaki.utu.cycle._entries import end_step
from anunnaki.utu.cycle._execute import ExecuteStage
from anunnaki.utu.cycle._knowledge import Knowledge
from anunnaki.utu.cycle._knowledge_stage import DecisionTail, KnowledgeStage
from anunnaki.utu.cycle._mape import Actuator
from anunnaki.utu.cycle._monitor import MonitorStage
from anunnaki.utu.cycle._parts import (
    NodeConfigError,
    UtuParts,
    load_parts,
    open_knowledge,
    record_run,
)
from anunnaki.utu.cycle._plan import PlanStage
from anunnaki.utu.host._desk import DecisionFeed, OperatorDesk, listen_run_stop
from anunnaki.utu.host._host import (
    ExecuteSide,
    host_clock,
    idle_wait,
    ready_fields,
    take_up,
    watched,
)
from anunnaki.utu.host._intake import (
    MonitoredTopics,
    SimStamps,
    clock_feed,
    stamp_inputs,
    take_clock,
)

__all__ = [
    "NODE_NAMES",
    "AnalyzeNode",
    "DecisionTail",
    "ExecuteNode",
    "KnowledgeNode",
    "MonitorNode",
    "NodeConfigError",
    "NodeName",
    "PlanNode",
    "UtuNode",
    "UtuParts",
    "build_node",
    "load_parts",
    "node_token",
    "open_knowledge",
    "ready_service",
    "step_nodes",
]

log = logging.getLogger("anunnaki.utu.nodes")


# -- the node base ---------------------------------------------------------------------------
class UtuNode(Node):
    """One Utu service as a node on the bus (see the module docstring).

    The constructor is the whole bring-up: it loads and checks the files, opens the
    knowledge base, declares subscriptions and services, and *last* the liveliness token
    and the readiness service. A node that could not come up raises and leaves nothing
    declared.

    Args:
        utu: The Utu configuration, or its loaded :class:`UtuParts`.
        bus: The bus to use (the node does not close it).
        knowledge: A knowledge base shared with other nodes of this process; default: the
            node opens the configuration's file (and closes it on :meth:`close`).
        clock: The node's clock; default wall time, or the simulation time of
            ``clock_topic`` when the configuration says ``clock: sim``.
        rate: At most this many time-driven rounds per second (default: the
            configuration's ``rate``).
        timeout: Seconds to wait for a partner node's answer before going on without it.

    """

    name: ClassVar[NodeName]
    needs_knowledge: ClassVar[bool] = True
    #: Whether the node reads the clock (monitor, and analyze when no monitor is up).
    uses_clock: ClassVar[bool] = False

    def __init__(
        self,
        utu: UtuConfig | UtuParts,
        *,
        bus: Bus,
        knowledge: Knowledge | None = None,
        clock: Clock | None = None,
        rate: float | None = None,
        timeout: float = 2.0,
    ) -> None:
        self.parts = utu if isinstance(utu, UtuParts) else load_parts(utu)
        self.config = self.parts.config
        self.rate = float(rate if rate is not None else self.config.rate)
        if not 0 < self.rate <= 10_000:
            raise NodeConfigError(f"{self.name}: rate must be in (0, 10000] Hz, got {rate!r}")
        self.timeout = float(timeout)
        self.clock: Clock = clock or host_clock(self.config)
        self.run_stopped = False
        self._lock = threading.Lock()
        self._kb: Knowledge | None = knowledge
        self._own_kb = False
        self._clock_sub: Subscriber | None = None
        #: The ``/clock`` heard, to stamp inputs on simulation time (the monitor's).
        self._stamps: SimStamps | None = None
        self._origins: dict[str, str] = {}  # peer node -> the origin its cycles carry
        self.foreign = 0  # cycle messages refused as not from the peer they claim
        if self.needs_knowledge and knowledge is None:
            if self.config.knowledge == ":memory:":
                raise NodeConfigError(
                    f"the {self.name} node needs the knowledge base shared by all nodes, "
                    "but the configuration says knowledge: ':memory:' (private to one "
                    "process); give a file (e.g. knowledge: run.db or --knowledge run.db)"
                )
            self._kb = open_knowledge(self.config.knowledge)
            self._own_kb = True
        super().__init__(bus, token=node_token(self.name), ready=ready_service(self.name))

    def declare(self) -> None:
        """Declare the run-stop subscription, the clock, then the node's own (:meth:`bring_up`)."""
        if self.uses_clock:
            topic = self.config.clock_topic
            self._clock_sub = clock_feed(self.clock, topic, lambda t, q: self.pull(t, queue=q))
            self._stamps = SimStamps() if self._clock_sub is not None else None
        self.own(listen_run_stop(self.bus, self.config.name, self.name, self._heard_run_stop))
        self.bring_up()

    def bring_up(self) -> None:
        """Hook: declare what the node needs (called by the constructor)."""

    @property
    def knowledge(self) -> Knowledge:
        """The knowledge base this node reads and writes."""
        if self._kb is None:
            raise NodeConfigError(f"the {self.name} node has no knowledge base")
        return self._kb

    def _take_clock(self) -> None:
        """Apply the simulation times queued since the last call."""
        take_clock(self.clock, self._clock_sub, self._stamps)

    def _heard_run_stop(self, caller: str, reason: str) -> None:
        self.run_stopped = True
        self.on_run_stop(caller, reason)
        self.wake()

    def on_run_stop(self, caller: str, reason: str) -> None:
        """Hook: a run-stop arrived on ``/utu/run_stop`` (from anyone but Utu itself)."""

    def ready_info(self) -> dict[str, Any]:
        """Readiness: the Utu's name, the rate, whether a run-stop is in force, its origin."""
        info = ready_fields(self.config.name, self.rate, self.run_stopped)
        origin = getattr(getattr(self, "stage", None), "origin", None)
        if isinstance(origin, str):
            info["origin"] = origin  # what its cycle messages carry (see from_peer)
        return info

    def from_peer(self, peer: str, origin: str) -> bool:
        """Whether a cycle message stamped ``origin`` comes from the ``peer`` node.

        A new origin is checked once against the peer's readiness reply (a restarted peer
        has a new one) and then remembered; a message from anyone else on the bus — a forged
        cycle, a stale one — is refused, counted in :attr:`foreign` and logged once.
        """
        known = self._origins.get(peer)
        if origin and origin == known:
            return True
        try:
            reply = body_of(
                self.bus.request(ready_service(peer), {}, timeout=1.0, wait_for_service=False)
            )
        except AnunnakiError:
            reply = {}
        if origin and reply.get("origin") == origin:
            self._origins[peer] = origin
            return True
        self.foreign += 1
        if self.foreign == 1:
            log.warning(
                "%s: refused a cycle message that claims to come from the %s node (origin "
                "%r); further refusals are counted, not logged",
                self.name, peer, origin,
            )  # fmt: skip
        return False

    def _period(self) -> float:
        """Seconds of wall time between two time-driven rounds (scaled by the sim speed)."""
        return idle_wait(self.clock, 1.0 / self.rate)

    def _flush(self) -> None:
        if self._kb is not None:
            self._kb.flush()

    def spin(self, stop: threading.Event | None = None) -> None:
        """Run live; a watchdog run-stops the platform if a round takes ``watchdog`` s."""
        # An idle node's round waits up to 0.5 s for work (Node.spin): never less than 1 s.
        floor = max(2 * self._period(), 1.0)
        with watched(
            self.bus, self.config, what=f"node {self.name}", name=self.name, floor=floor
        ) as beat:
            self.on_round = beat
            try:
                super().spin(stop)
            finally:
                self.on_round = None

    def release(self) -> None:
        """Close the knowledge base the node opened itself."""
        self.release_extra()
        if self._own_kb and self._kb is not None:
            self._kb.close()

    def release_extra(self) -> None:
        """Hook: release what the subclass holds besides declared bus objects."""


class _Presence:
    """Which Utu nodes hold a liveliness token now (from a liveliness watch)."""

    def __init__(self, bus: Bus, on_change: Callable[[], None]) -> None:
        self._alive: set[str] = set()
        self._lock = threading.Lock()
        self._on_change = on_change
        self.watch = bus.watch_liveliness(self._changed)

    def _changed(self, node: str, alive: bool) -> None:
        with self._lock:
            (self._alive.add if alive else self._alive.discard)(node.lstrip("/"))
        self._on_change()

    def alive(self, name: str) -> bool:
        """Whether node ``name`` (e.g. ``execute``) is up."""
        with self._lock:
            return node_token(name).lstrip("/") in self._alive


# -- monitor -----------------------------------------------------------------------------------
class MonitorNode(UtuNode):
    """``/utu_monitor``: takes the managed system's messages and operator calls.

    It subscribes the topics the goal model's binding names (bounded queues, guideline S1)
    and publishes what arrived as one :class:`~anunnaki.messages.MonitorBatch` on
    ``/utu/monitor/input`` the moment it can. When nothing arrives it still publishes an
    empty batch whenever its clock has moved on by ``1/rate``: a watermark that tells the
    analyze node how far time has passed *with no input*.

    It also offers Utu's operator services (``/utu/run_stop``, ``/utu/pause``,
    ``/utu/resume``, ``/utu/approve``, ``/utu/reload``) and turns run-stops published on
    ``/utu/run_stop`` and vanished agent nodes (liveliness) into operator inputs, so that
    they enter the cycle at a defined point, as in the composed manager.
    """

    name = "monitor"
    needs_knowledge = False
    uses_clock = True

    def bring_up(self) -> None:
        """Subscribe the monitored topics; offer the operator services."""
        self.stage = MonitorStage(self.parts, origin=secrets.token_hex(4))
        self._subs = MonitoredTopics(lambda topic: self.pull(topic, queue=self.config.queue))
        self._subs.watch(self.stage.topics)
        self._fed: list[tuple[str, dict[str, Any], float | None]] = []
        #: Operator calls, run-stops heard and lost nodes, queued for the next batch.
        self.desk = OperatorDesk(self.stage, wake=self.wake, watch=self._subs.watch)
        for declared in self.desk.declare(self.bus):
            self.own(declared)

    def feed(self, topic: str, msg: Mapping[str, Any]) -> None:
        """Queue one input as if it had arrived on ``topic`` (tests, replay)."""
        with self._lock:
            self._fed.append((topic, dict(msg), None))
        self.wake()

    def on_run_stop(self, caller: str, reason: str) -> None:
        """A run-stop heard on the topic enters the cycle as an operator call."""
        self.desk.heard_run_stop(caller, reason)

    def ready_info(self) -> dict[str, Any]:
        """Readiness, with whether a run-stop was asked (before the cycle applies it)."""
        info = super().ready_info()
        info["run_stopped"] = self.desk.stopping(info["run_stopped"])
        return info

    def input_queues(self) -> list[Subscriber]:
        """The bounded queues of the monitored topics (empty: everything was taken)."""
        return self._subs.queues()

    def step(self, now: float | None = None) -> bool:
        """Publish what arrived since the last step as one batch; returns whether it did.

        A batch goes out when something arrived, or as a watermark when the time moved on
        by at least ``1/rate`` since the last batch. The inputs are taken first, then the
        simulation time: a message published after its instant's ``/clock`` is never
        stamped with an earlier time. On simulation time each input is stamped with the
        instant it was published in (:class:`~anunnaki.utu.host._intake.SimStamps`), or with
        the step's time when that is not known or ``now`` is given.
        """
        wall = isinstance(self.clock, WallClock) and now is None
        with self._lock:
            inputs, self._fed = self._fed, []
            # At most ``intake`` per topic per step (a flood must not hold the step), and
            # never more than a batch may carry.
            limit = min(
                self.config.queue,
                self.config.intake,
                MAX_BATCH // max(1, len(self._subs) + 1),
            )
            taken = self._subs.take(limit)
        ops = self.desk.take()
        if now is None:
            self._take_clock()
        inputs += stamp_inputs(taken, wall=wall, stamps=self._stamps if now is None else None)
        t = self.clock.now() if now is None else float(now)
        if not inputs and not ops and t < self.stage.last_t + 1.0 / self.rate:
            return False
        batch = self.stage.batch(t, inputs, ops)
        self.bus.publish(topics.MONITOR_INPUT, batch)
        self.cycles += 1
        return True

    def spin_once(self) -> float:
        """Publish what arrived at once; otherwise a watermark every ``1/rate``."""
        self.step()
        return self._period()


# -- analyze -----------------------------------------------------------------------------------
class AnalyzeNode(UtuNode):
    """``/utu_analyze``: evaluates the goal model and owns the cycle.

    Each cycle takes the monitor's batches, records inputs, verdicts and step ends in the
    knowledge base (exactly the rows the composed manager writes) and publishes the
    :class:`~anunnaki.messages.AnalysisState` on ``/utu/analyze/state``. Its time comes from the
    monitor's batches (watermarks included) while ``/utu_monitor`` is alive; without a
    monitor it cycles ``rate`` times a second of its own clock, so inputs going stale are
    noticed even when the monitor is gone.

    Args:
        pace: Wait for the execute node to finish each cycle before starting the next:
            ``True``, ``False``, or ``None`` (default) while ``/utu_execute`` is alive.
        expect: Nodes (e.g. ``("plan", "execute")``) that must all have come up before the
            first cycle: the batches wait for them. A launch passes the other nodes of its
            run, so that a platform that runs first does not have inputs analysed (and
            recorded) by a loop that cannot act yet — which a replay, with every part there
            from the start, would act on.
        **kwargs: As :class:`UtuNode`.

    """

    name = "analyze"
    uses_clock = True

    def __init__(
        self,
        utu: UtuConfig | UtuParts,
        *,
        pace: bool | None = None,
        expect: Sequence[str] = (),
        **kwargs: Any,
    ):
        self._pace = pace
        self._expect = tuple(expect)
        self._complete = not self._expect  # every expected node has been seen up
        super().__init__(utu, **kwargs)

    def _loop_complete(self) -> bool:
        if not self._complete and all(self._presence.alive(n) for n in self._expect):
            self._complete = True
            log.info("analyze: %s up: cycles start", ", ".join(self._expect))
        return self._complete

    def bring_up(self) -> None:
        """Subscribe the batches and the execute node's reports; watch who is alive."""
        origin = secrets.token_hex(4)
        self.stage = take_up(
            self.knowledge,
            self.name,
            lambda: AnalyzeStage(self.parts, self.knowledge, origin=origin),
        )
        # execute itself waits up to ``timeout`` for plan: give it time to say so
        self._ack_timeout = 2 * self.timeout
        self._awaiting: tuple[AnalysisState, float] | None = None  # (the cycle, since)
        self._unpaced = False
        self.timeouts = 0
        self._batches = self.pull(
            topics.MONITOR_INPUT, queue=max(self.config.queue, 64), expect=MonitorBatch
        )
        self._done = self.pull(topics.CYCLE_DONE, queue=64, expect=CycleDone)
        self._presence = _Presence(self.bus, self.wake)
        self.own(self._presence.watch)

    def execute_up(self) -> bool:
        """Whether the execute node is up (its liveliness token is seen)."""
        return self._presence.alive("execute")

    def _end_step(self, state: AnalysisState, done: CycleDone | None) -> None:
        """End the step of ``state``: as execute reported it, or unreported.

        Unreported while execute is gone, the marker says so: a replay analyses the step
        only, as nothing acted on it.
        """
        gone = done is None and not self.execute_up()
        decisions = done.decisions if done is not None else 0
        end_step(
            self.knowledge, float(state.t or 0.0), took=bool(state.took),
            decisions=decisions, executed=not gone,
        )  # fmt: skip
        self._flush()

    def _paced(self) -> bool:
        expects = self._pace if self._pace is not None else self._presence.alive("execute")
        return expects and not self._unpaced

    def settle(self) -> bool:
        """Take the execute node's reports; finish the cycle it reports done."""
        finished = False
        while (sample := self._done.try_recv()) is not None:
            done = cast(CycleDone, sample.message)
            if done.origin != self.stage.origin:
                continue
            if self._awaiting is not None and done.seq == self._awaiting[0].seq:
                state, self._awaiting = self._awaiting[0], None
                self._end_step(state, done)
                self.cycles += 1
                finished = True
            if done.seq == self.stage.seq:
                self._unpaced = False
        return finished

    def waiting(self) -> bool:
        """Whether the current cycle waits for the execute node (and has not timed out)."""
        if self._awaiting is None or not self._paced():
            return False
        return time.monotonic() - self._awaiting[1] < self._ack_timeout

    def step(self, now: float | None = None) -> bool:
        """Run one cycle at ``now`` (default: the batches' or the clock's time).

        Returns:
            Whether a cycle ran (``False`` while the previous cycle waits for execute).

        """
        self.settle()
        if not self._loop_complete():
            return False  # the batches wait in their queue until the loop can act
        if self._awaiting is not None:
            if self.waiting():
                return False
            if self._paced():
                self.timeouts += 1
                self._unpaced = True
                log.warning(
                    "analyze: execute did not finish cycle %d within %.1f s; going on "
                    "without waiting until it answers again",
                    self._awaiting[0].seq,
                    self._ack_timeout,
                )
            self._end_step(self._awaiting[0], None)
            self._awaiting = None
        batches: list[MonitorBatch] = []
        while (sample := self._batches.try_recv()) is not None:
            b = cast(MonitorBatch, sample.message)
            if self.from_peer("monitor", b.origin) and self.stage.plausible(b):
                batches.append(b)  # a forged batch is refused alone, not with others
        if now is not None:
            t = float(now)
        elif self._presence.alive("monitor"):
            t = self.stage.now  # the monitor's batches say how far time has gone
        else:
            self._take_clock()
            t = self.clock.now()
        t = max([t, *(b.t for b in batches)])
        batch = MonitorBatch.trusted(
            origin=batches[-1].origin if batches else "",
            seq=batches[-1].seq if batches else 0,
            t=t,
            inputs=[i for b in batches for i in b.inputs],
            ops=[op for b in batches for op in b.ops],
        )
        state = self.stage.analyze(batch, full=True)
        if state is None:  # refused (an implausible time given as ``now``)
            return False
        self._flush()
        self.bus.publish(topics.ANALYSIS, state)
        if self._paced():
            self._awaiting = (state, time.monotonic())
        else:
            self._end_step(state, None)
            self.cycles += 1
        return True

    def _tick_due(self) -> bool:
        if self._presence.alive("monitor"):
            return False  # its watermarks drive the time
        return self.stage.started_at is None or self.clock.now() >= self.stage.now + 1.0 / self.rate

    def spin_once(self) -> float:
        """A cycle as soon as a batch arrives and the last cycle is done.

        The simulation time is taken every round, with a monitor up or not: its queue must
        not fill (the bus would drop and log every further tick).
        """
        self._take_clock()
        self.settle()
        if not self._loop_complete():
            return self._period()  # woken when a node comes up (the presence watch)
        if self.waiting():
            assert self._awaiting is not None
            return self._ack_timeout - (time.monotonic() - self._awaiting[1])
        if self._batches.pending or self._awaiting is not None or self._tick_due():
            self.step()
            return 0.0
        return self._period()


# -- plan --------------------------------------------------------------------------------------
class PlanNode(UtuNode):
    """``/utu_plan``: the priority-sorted queue of tactics (:class:`~anunnaki.utu.Planner`).

    For each :class:`~anunnaki.messages.ExecuteStatus` on ``/utu/execute/status`` it updates the
    queue (dwell, cooldown, conflicts, approval) and publishes a
    :class:`~anunnaki.messages.PlanStart` on ``/utu/plan/start``.
    """

    name = "plan"

    def bring_up(self) -> None:
        """Subscribe the execute node's statuses."""
        self.stage = take_up(
            self.knowledge, self.name, lambda: PlanStage(self.parts, self.knowledge)
        )
        self._statuses = self.pull(topics.EXECUTE_STATUS, queue=64, expect=ExecuteStatus)

    def on_run_stop(self, caller: str, reason: str) -> None:
        """Stop starting tactics at once (guideline S4)."""
        self.stage.run_stopped = True

    def step(self) -> bool:
        """Plan every cycle the execute node reported; returns whether there was one."""
        worked = False
        while (sample := self._statuses.try_recv()) is not None:
            status = cast(ExecuteStatus, sample.message)
            if not self.from_peer("analyze", status.origin):
                continue  # not a cycle of this Utu's analyzer
            self.stage.mirror(status)  # this process's copy takes the execute node's fields
            start = self.stage.plan(status)
            self.run_stopped = self.stage.run_stopped
            self._flush()
            self.bus.publish(topics.PLAN_START, start)
            self.cycles += 1
            worked = True
        return worked

    def spin_once(self) -> float:
        """Plan as soon as a status arrives."""
        self.step()
        return 0.5


# -- execute -----------------------------------------------------------------------------------
class ExecuteNode(UtuNode):
    """``/utu_execute``: performs tactics and checks their postconditions.

    Each analysis it receives is one cycle (:meth:`ExecuteStage.begin`): operator calls,
    resumed actions, postconditions of the tactics in flight (escalating when one fails);
    it reports on ``/utu/execute/status``, starts what the plan node answers on
    ``/utu/plan/start``, and reports the cycle done on ``/utu/execute/done``.

    Args:
        actuator: How actions reach the managed system (default: over this bus, with the
            configuration's notifier).
        expect_plan: Wait for the plan node's answer each cycle: ``True``, ``False``, or
            ``None`` (default) while ``/utu_plan`` is alive.
        **kwargs: As :class:`UtuNode`.

    """

    name = "execute"

    def __init__(
        self,
        utu: UtuConfig | UtuParts,
        *,
        actuator: Actuator | None = None,
        expect_plan: bool | None = None,
        **kwargs: Any,
    ) -> None:
        self._actuator_arg = actuator
        self._expect_plan = expect_plan
        super().__init__(utu, **kwargs)

    def bring_up(self) -> None:
        """Build the actuator and the stage; subscribe analyses and plan's answers."""
        # requests never hold a cycle
        self.side = ExecuteSide(
            self.parts,
            self.knowledge,
            bus=self.bus,
            actuator=self._actuator_arg,
            wake=self.wake,
            node=self.name,
        )
        self.side.go_live(self.clock)
        self.actuator: Actuator = self.side.actuator
        self._flush()
        self._pending: tuple[str, int, float] | None = None  # (origin, seq, since)
        self.timeouts = 0
        self._states = self.pull(
            topics.ANALYSIS, queue=max(self.config.queue, 64), expect=AnalysisState
        )
        self._starts = self.pull(topics.PLAN_START, queue=64, expect=PlanStart)
        self._presence = _Presence(self.bus, self.wake) if self._expect_plan is None else None
        if self._presence is not None:
            self.own(self._presence.watch)

    @property
    def stage(self) -> ExecuteStage:
        """The execute stage."""
        return self.side.stage

    def release_extra(self) -> None:
        """Stop the notifier and the action threads."""
        side = getattr(self, "side", None)
        if side is not None:
            side.close()

    def on_run_stop(self, caller: str, reason: str) -> None:
        """Stop starting tactics at once (guideline S4); the monitor's op records it."""
        self.stage.heard_run_stop = True

    @property
    def halted(self) -> bool:
        """Whether adaptation is halted (paused, run-stopped, or a run-stop was heard)."""
        return self.stage.halted

    def ready_info(self) -> dict[str, Any]:
        """Readiness, with whether a run-stop is in force."""
        return {**super().ready_info(), "run_stopped": self.run_stopped or self.stage.run_stopped}

    def _expects_plan(self) -> bool:
        if self._expect_plan is not None:
            return self._expect_plan
        return self._presence is not None and self._presence.alive("plan")

    def step(self) -> bool:
        """Advance through every cycle that can be advanced now; returns whether any did."""
        worked = False
        while True:
            if self._pending is not None:
                start = self._take_start()
                if start is None:
                    waited = time.monotonic() - self._pending[2]
                    if self._expects_plan() and waited < self.timeout:
                        return worked
                    if self._expects_plan():
                        self.timeouts += 1
                        log.warning(
                            "execute: plan did not answer cycle %s within %.1f s; "
                            "starting nothing this cycle",
                            self._pending[1],
                            self.timeout,
                        )
                if start is not None:
                    self.stage.mirror(start)  # this process's copy takes the plan node's states
                done = self.stage.complete(start)
                self._flush()
                self.bus.publish(topics.CYCLE_DONE, done)
                self._pending = None
                self.cycles += 1
                worked = True
                continue
            sample = self._states.try_recv()
            if sample is None:
                return worked
            state = cast(AnalysisState, sample.message)
            if not state.is_cycle:
                continue  # a display update (e.g. from a composed manager), not a cycle
            if not self.from_peer("analyze", state.origin or ""):
                continue  # a forged or stale cycle: never executed
            status = self.stage.begin(state)
            self._flush()
            self.bus.publish(topics.EXECUTE_STATUS, status)
            self._pending = (state.origin or "", state.seq or 0, time.monotonic())
            worked = True

    def _take_start(self) -> PlanStart | None:
        assert self._pending is not None
        origin, seq, _ = self._pending
        while (sample := self._starts.try_recv()) is not None:
            start = cast(PlanStart, sample.message)
            if start.origin == origin and start.seq == seq:
                return start
        return None

    def spin_once(self) -> float:
        """Execute as soon as an analysis or plan's answer arrives."""
        self.step()
        if self._pending is not None and self._expects_plan():
            return max(0.0, self.timeout - (time.monotonic() - self._pending[2]))
        return 0.5


# -- knowledge ---------------------------------------------------------------------------------
class KnowledgeNode(UtuNode):
    """``/utu_knowledge``: the dedicated node for the knowledge base (guidelines N8, P3).

    At bring-up it records the goal model, binding and tactics texts in force (if the
    knowledge base has none yet). It answers ``/utu/knowledge/query``
    (``{what: decisions|queue|state, limit}``, the same answers as the composed manager)
    and publishes new decisions on ``/utu/knowledge/decisions`` at its rate
    (``{decisions: [{id, t, kind, tactic, data}]}``), for dashboards and logs.
    """

    name = "knowledge"

    def bring_up(self) -> None:
        """Record settings and model texts; follow the cycle's messages; offer queries."""
        kb = self.knowledge
        record_run(kb, self.parts)
        self.feed = DecisionFeed(self.bus, kb, self.rate)
        self.stage = KnowledgeStage(self.parts, kb)
        sub = self.bus.subscribe
        self.own(sub(topics.ANALYSIS, self._on_state, queue=64, expect=AnalysisState))
        self.own(sub(topics.PLAN_START, self._on_start, queue=64, expect=PlanStart))
        self.own(sub(topics.EXECUTE_STATUS, self._on_status, queue=64, expect=ExecuteStatus))
        self.own(self.bus.service(topics.QUERY, self._query))

    def _on_state(self, sample: Sample) -> None:
        body = cast(AnalysisState, sample.message).to_body()
        with self._lock:
            self.stage.state = {
                k: body.get(k) for k in ("t", "root", "nodes", "violated", "tactics")
            }

    def _on_start(self, sample: Sample) -> None:
        with self._lock:
            self.stage.queue = list(cast(PlanStart, sample.message).queue)

    def _on_status(self, sample: Sample) -> None:
        status = cast(ExecuteStatus, sample.message)
        with self._lock:
            self.stage.flags = {"paused": status.paused, "run_stopped": status.run_stopped}
        self.run_stopped = status.run_stopped  # as the execute node has it

    def _query(self, message: Any) -> dict[str, Any]:
        with self._lock:
            return self.stage.query(message)

    def step(self) -> bool:
        """Publish the decisions written since the last step; returns whether there were any."""
        published = self.feed.publish()
        self.cycles += 1
        return published

    def spin_once(self) -> float:
        """Publish new decisions at most ``rate`` times a second (it only tails the file)."""
        if self.feed.due():
            self.step()
        return self.feed.wait()


# -- composition -------------------------------------------------------------------------------
#: The Utu node kinds, by name (``monitor``, ``analyze``, ``plan``, ``execute``, ``knowledge``).
NODE_KINDS: Registry[UtuNode] = Registry("Utu node", error=NodeConfigError)
for _kind in (MonitorNode, AnalyzeNode, PlanNode, ExecuteNode, KnowledgeNode):
    NODE_KINDS.register(_kind)


def build_node(name: str, utu: UtuConfig | UtuParts, **kwargs: Any) -> UtuNode:
    """Bring up the node called ``name`` with the keyword arguments of :class:`UtuNode`.

    The names are ``monitor``, ``analyze``, ``plan``, ``execute`` and ``knowledge``.

    Raises:
        NodeConfigError: An unknown name (the message lists the valid ones).

    """
    return NODE_KINDS.factory(name)(utu, **kwargs)


def step_nodes(nodes: Mapping[str, UtuNode], now: float) -> None:
    """Run one deterministic cycle through nodes sharing an in-process bus (tests, replay).

    Build the analyze node with ``pace=True`` and the execute node with
    ``expect_plan=True`` (an in-process bus delivers at once, so nothing waits).
    """
    monitor = cast(MonitorNode | None, nodes.get("monitor"))
    analyze = cast(AnalyzeNode | None, nodes.get("analyze"))
    plan = cast(PlanNode | None, nodes.get("plan"))
    execute = cast(ExecuteNode | None, nodes.get("execute"))
    knowledge = cast(KnowledgeNode | None, nodes.get("knowledge"))
    if monitor is not None:
        monitor.step(now)
    if analyze is not None:
        analyze.step(now)
    if execute is not None:
        execute.step()
    if plan is not None:
        plan.step()
    if execute is not None:
        execute.step()
    if analyze is not None:
        analyze.settle()
    if knowledge is not None:
        knowledge.step()
