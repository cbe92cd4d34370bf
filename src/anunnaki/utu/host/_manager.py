"""The autonomic manager: Monitor → Analyze → Plan → Execute over Knowledge (paper Fig. 8).

:class:`AutonomicManager` is Utu in one process: the five stages of
:mod:`anunnaki.utu.cycle` called one after the other — the same code the per-node
deployment runs, here with direct calls instead of bus hops. ``step(now)`` runs one
deterministic cycle — tests, simulation and replay drive it — and ``spin()`` runs it live.
What it adds around the stages (operator desk, run-stop, the watchdog around its loop,
readiness, the execute side with its actuator, threads and notifier, the monitored topics'
queues) is the code the nodes use too (:mod:`~anunnaki.utu.host._desk`,
:mod:`~anunnaki.utu.host._host`, :mod:`~anunnaki.utu.host._intake`). Why it calls the
stages rather than the node classes: docs/architecture.md ("Where a goal update flows").

Why reaction is event-driven and rates bound only time
    In ``spin()`` a message on a monitored topic is analysed the moment it arrives: on the
    in-process bus in the very thread that delivers it (no thread hop that the GIL's
    switch interval could stretch), on another bus on the spinning thread, woken by the
    subscriber's doorbell. When the message changes a goal, an applicable tactic or comes
    with an operator call, the whole cycle runs at once — plan, execute, the first action.
    When it changes nothing, it is only recorded: the rest of the cycle waits for the next
    time-driven step. ``rate`` paces those (staleness, deadlines, dwell, temporal windows)
    and bounds the load; it never delays a reaction.

Operators and other nodes reach the manager through services on the bus (all recorded in
the decision log with their caller):

* ``/utu/run_stop`` — halt adaptation and command the managed system to stop (guideline S4);
  the same happens when any node publishes a ``RunStop`` on the ``/utu/run_stop`` topic;
* ``/utu/pause``, ``/utu/resume`` — suspend and resume adaptation (resume also clears a
  run-stop);
* ``/utu/approve`` — ``{tactic, approve: true|false, caller}`` for tactics marked
  ``requires_approval``;
* ``/utu/reload`` — ``{goal_model, binding, tactics}`` paths: checked at once (a broken file
  is refused with its error in the reply), applied at the next cycle;
* ``/utu/ready`` — readiness (guideline C9), and ``/utu/knowledge/query`` — read the
  knowledge base (decisions, verdicts, state, queue).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from anunnaki import topics
from anunnaki._closing import Closing
from anunnaki.bus import Executor as BusExecutor
from anunnaki.bus import InprocBus
from anunnaki.clock import Clock, WallClock
from anunnaki.errors import AnunnakiError
from anunnaki.goals import GoalModel
from anunnaki.messages import AnalysisState, body_of
from anunnaki.tactics import TacticSet
from anunnaki.topics import UTU_NODES as NODE_NAMES
from anunnaki.utu._config import RunStopConfig, UtuConfig
from anunnaki.utu.cycle._actions import ActionRunner
from anunnaki.utu.cycle._analyze import AnalyzeStage
from anunnaki.utu.cycle._entries import end_step
from anunnaki.utu.cycle._execute import ExecuteStage
from anunnaki.utu.cycle._knowledge import Knowledge
from anunnaki.utu.cycle._knowledge_stage import KnowledgeStage
from anunnaki.utu.cycle._mape import Actuator, Analyzer, Executor, Planner, TopicWatch
from anunnaki.utu.cycle._monitor import MonitorStage
from anunnaki.utu.cycle._parts import UtuParts, load_parts, record_run
from anunnaki.utu.cycle._plan import PlanStage
from anunnaki.utu.host._desk import DecisionFeed, OperatorDesk, listen_run_stop
from anunnaki.utu.host._host import (
    ExecuteSide,
    StandIn,
    host_clock,
    idle_wait,
    ready_fields,
    take_up,
    watched,
)
from anunnaki.utu.host._intake import (
    IntakeBudget,
    MonitoredTopics,
    SimStamps,
    clock_feed,
    stamp_inputs,
    take_clock,
)
from anunnaki.utu.host._threads import ThreadRunner

__all__ = ["AutonomicManager"]

log = logging.getLogger("anunnaki.utu")

#: The bus's own threads (service handlers, subscriber callbacks): never react inline there.
_BUS_THREADS = ("anunnaki-bus-",)


class AutonomicManager(Closing):
    """Utu: the MAPE-K loop over a goal model and tactics, in one process.

    Args:
        model: The goal model (with its binding applied).
        tactics: The tactics.
        knowledge: The knowledge base (decision log); a fresh in-memory one by default.
        bus: A bus to take inputs from and offer services on; ``None`` for a manager fed by
            :meth:`feed` (tests, replay).
        actuator: How actions reach the managed system; a :class:`BusActuator` on ``bus``
            by default, a :class:`RecordingActuator` without a bus.
        clock: Where ``spin`` reads the time (``step`` takes it as an argument).
        dwell: Seconds a tactic's preconditions must hold before it is queued (hysteresis).
        warmup: Seconds after the first step during which an *unknown* goal does not count
            by the model's unknown policy (inputs are still arriving).
        failsafe: Tactic to escalate to when a postcondition fails and no other tactic applies.
        escalate_to_run_stop: After the fail-safe itself fails, run-stop.
        run_stop_service: Service the run-stop requests on the managed system.
        publish_state: Publish the analysis on ``/utu/analyze/state`` after each step that
            changed a goal, decided something or applied an operator call.
        queue: Bound of each monitored topic's input queue (guideline S1).
        sources: ``goal_model``/``binding``/``tactics`` → (path, text) of the files, recorded
            in Knowledge (what ``replay`` and ``reload`` start from).
        name: The manager's name (its run-stop announcements say ``utu:<name>``).
        clock_topic: Where a :class:`~anunnaki.clock.SimClock` takes its time from.
        rate: Hz of the time-driven checks in :meth:`spin`.
        reload_dirs: Folders a hot reload may read from, besides those of the source files
            (a manager built from objects: the working directory).

    """

    def __init__(
        self,
        model: GoalModel,
        tactics: TacticSet,
        *,
        knowledge: Knowledge | None = None,
        bus: Any | None = None,
        actuator: Actuator | None = None,
        clock: Clock | None = None,
        dwell: float = 0.0,
        warmup: float = 0.0,
        failsafe: str | None = None,
        escalate_to_run_stop: bool = True,
        run_stop_service: str | None = None,
        run_stop_payload: Mapping[str, Any] | None = None,
        publish_state: bool = True,
        queue: int = 1024,
        sources: Mapping[str, tuple[str | None, str]] | None = None,
        name: str = "utu",
        clock_topic: str = topics.CLOCK,
        rate: float = 20.0,
        reload_dirs: Sequence[str | Path] = (),
        actions: ActionRunner | None = None,
    ) -> None:
        srcs = dict(sources or {})
        config = UtuConfig(
            anunnaki="utu/1",
            name=name,
            goal_model=(srcs.get("goal_model") or ("<goal-model>", ""))[0] or "<goal-model>",
            dwell=dwell,
            warmup=warmup,
            failsafe=failsafe,
            escalate_to_run_stop=escalate_to_run_stop,
            run_stop=RunStopConfig(
                service=run_stop_service, payload=dict(run_stop_payload or {"reason": "run-stop"})
            ),
            publish_state=publish_state,
            queue=queue,
            clock_topic=clock_topic,
            rate=rate,
            reload_dirs=[str(d) for d in reload_dirs],
        )
        self._init(
            UtuParts(config, srcs, model, tactics), knowledge, bus, actuator, clock, actions=actions
        )

    def _init(
        self,
        parts: UtuParts,
        knowledge: Knowledge | None,
        bus: Any | None,
        actuator: Actuator | None,
        clock: Clock | None,
        *,
        actions: ActionRunner | None = None,
        nodes: Mapping[str, float] | None = None,
    ) -> None:
        config = parts.config
        self.parts = parts
        self.name = config.name
        self.knowledge = knowledge or Knowledge()
        self.bus = bus
        self.clock: Clock = clock or WallClock()
        self.publish_state = config.publish_state and bus is not None
        self._nodes = dict(nodes or {}) if bus is not None else {}
        self.rate = max(self._nodes.values(), default=config.rate)
        self._closed = False
        self._live = False
        # (topic, message, arrival time or None for "now"): a step takes inputs at their own
        # times, so a burst taken by one step keeps its spacing (rates, temporal goals).
        self._inputs: deque[tuple[str, dict[str, Any], float | None]] = deque()
        self._lock = threading.Lock()  # guards the queue above
        self._step_lock = threading.Lock()  # one step at a time (spin, inline reactions)
        self._step_wanted = False  # the spinning thread waits for the lock: no inline step
        self._budget: IntakeBudget | None = None  # live on the wall clock (spin)
        self._wake = threading.Event()
        self._declared: list[Any] = []
        # the monitored topics' queues (a manager with a bus)
        self._pull = MonitoredTopics(self._subscribe_topic)
        self._clock_sub: Any = None
        #: The ``/clock`` heard, to stamp inputs on simulation time (a live manager's; one on
        #: an executor stamps each at its step, which is the instant it was published in).
        self._stamps: SimStamps | None = None
        self._stepped = False
        self._state_cache: AnalysisState | None = None
        record_run(self.knowledge, parts)
        take_up(self.knowledge, "manager", lambda: self._build_stages(actuator, actions))
        self.now = self.analyze_stage.now
        self.monitor_stage.last_t = self.now
        if bus is not None:
            self._connect(bus)

    def _build_stages(self, actuator: Actuator | None, actions: ActionRunner | None) -> None:
        parts, kb = self.parts, self.knowledge
        self.monitor_stage = MonitorStage(parts)
        #: Operator calls, run-stops heard and lost nodes, queued for the next step.
        self.desk = OperatorDesk(
            self.monitor_stage,
            wake=self.wake,
            watch=self._pull.watch if self.bus is not None else None,
        )
        self.analyze_stage = AnalyzeStage(parts, kb)
        # requests never hold the loop
        self._execute = ExecuteSide(
            parts, kb, bus=self.bus, actuator=actuator, wake=self.wake, actions=actions
        )
        # One store of tactic runtimes: plan selects among the execute stage's own.
        self.plan_stage = PlanStage(parts, kb, planner=self.execute_stage.planner)
        self.knowledge_stage = KnowledgeStage(parts, kb)
        rate = self._nodes.get("knowledge", parts.config.rate)
        self._decisions = DecisionFeed(self.bus, kb, rate) if self.bus is not None else None

    # -- construction ---------------------------------------------------------------------
    @classmethod
    def from_config(
        cls,
        config: UtuConfig | UtuParts,
        *,
        bus: Any | None = None,
        actuator: Actuator | None = None,
        clock: Clock | None = None,
        knowledge: Knowledge | None = None,
        nodes: Mapping[str, float] | None = None,
    ) -> AutonomicManager:
        """Build a manager from a :class:`UtuConfig` (files loaded and checked) or its parts.

        With ``nodes`` (Utu node name → rate, Hz) and a bus, the manager stands for the five
        nodes of a per-node run, as a launch file's ``nodes:`` has them in one process: a
        liveliness token ``/utu_<name>`` and a readiness service ``/utu/<name>/ready`` for
        each, new decisions on ``/utu/knowledge/decisions`` at the knowledge node's rate,
        and time-driven steps at the highest rate.
        """
        parts = config if isinstance(config, UtuParts) else load_parts(config)
        cfg = parts.config
        manager = cls.__new__(cls)
        manager._init(
            parts,
            knowledge or Knowledge(cfg.knowledge),
            bus,
            actuator,
            clock or host_clock(cfg),
            nodes=nodes,
        )
        return manager

    def _connect(self, bus: Any) -> None:
        self._pull.watch(self.monitor_stage.topics)
        self._clock_sub = clock_feed(self.clock, self.parts.config.clock_topic, self._subscribe)
        self._stamps = SimStamps() if self._clock_sub is not None else None
        who = f"utu:{self.name}"
        self._declared.append(listen_run_stop(bus, self.name, who, self.desk.heard_run_stop))
        self._declared += self.desk.declare(bus)
        services: dict[str, Callable[[Any], Any]] = {
            topics.READY: lambda m: {"ready": not self._closed, "node": self.name},
            topics.QUERY: self._query,
        }
        for name, handler in services.items():
            self._declared.append(bus.service(name, handler))
        if self._nodes:  # standing for the five nodes: each one's token, then its readiness
            self._declared += [StandIn(bus, node, self._ready_info) for node in NODE_NAMES]

    def _ready_info(self) -> dict[str, Any]:
        stopping = self.desk.stopping(self.run_stopped)
        return {"composed": True, **ready_fields(self.name, self.rate, stopping)}

    def _subscribe_topic(self, topic: str) -> Any:
        # ``step`` drains the queue, so a step sees exactly what arrived before it; the
        # doorbell reacts the moment a message is queued.
        return self._subscribe(topic, self.parts.config.queue, on_ready=self._arrived)

    def _subscribe(self, topic: str, queue: int, **kwargs: Any) -> Any:
        assert self.bus is not None
        sub = self.bus.subscribe(topic, queue=queue, **kwargs)
        self._declared.append(sub)
        return sub

    # -- the parts, as the tests and tools know them ----------------------------------------
    @property
    def model(self) -> GoalModel:
        """The goal model in force."""
        return self.analyze_stage.parts.model

    @property
    def execute_stage(self) -> ExecuteStage:
        """The execute stage (operator calls, postconditions, actions)."""
        return self._execute.stage

    @property
    def actuator(self) -> Actuator:
        """How actions reach the managed system."""
        return self._execute.actuator

    @property
    def actions(self) -> ActionRunner | None:
        """What runs blocking requests off the loop (``None``: they run in the step)."""
        return self._execute.actions

    @property
    def tactics(self) -> TacticSet:
        """The tactics in force."""
        return self.execute_stage.parts.tactics

    @property
    def monitor(self) -> TopicWatch:
        """What is known of each monitored topic."""
        return self.analyze_stage.topic_watch

    @property
    def analyzer(self) -> Analyzer:
        """The goal model's evaluation."""
        return self.analyze_stage.analyzer

    @property
    def planner(self) -> Planner:
        """Every tactic's runtime: selection state and what is in flight."""
        return self.execute_stage.planner

    @property
    def executor(self) -> Executor:
        """The executor of tactic actions."""
        return self.execute_stage.executor

    @property
    def failsafe(self) -> str | None:
        """The tactic a failed postcondition escalates to when no other applies."""
        return self.parts.config.failsafe

    @property
    def warmup(self) -> float:
        """Seconds at start during which an unknown goal triggers nothing."""
        return self.parts.config.warmup

    @property
    def run_stop_service(self) -> str | None:
        """The service a run-stop requests on the managed system."""
        return self.parts.config.run_stop.service

    @property
    def paused(self) -> bool:
        """Whether adaptation is paused (also during a run-stop)."""
        return self.execute_stage.paused

    @property
    def run_stopped(self) -> bool:
        """Whether a run-stop is in force."""
        return self.execute_stage.run_stopped

    # -- inputs -----------------------------------------------------------------------------
    def _arrived(self) -> None:
        """A monitored message was queued (called in the delivering thread).

        Live on the in-process bus, the step runs right here, in the publisher's thread —
        unless that thread is one of the bus's own (a service handler or a subscriber
        callback publishing): a step there could request that very service and wait on
        itself, so the spinning thread takes over. A step already running (in any thread)
        takes the message in its next round.
        """
        if (
            self._live
            and self._inline
            and not self._step_wanted  # the spinning thread would wait behind a flood's steps
            and not threading.current_thread().name.startswith(_BUS_THREADS)
            and self._step_lock.acquire(blocking=False)
        ):
            try:
                self._step(None, react=True)
            except Exception:  # a reaction must never take the publisher down
                log.exception("utu: a reaction step failed; going on")
            finally:
                self._step_lock.release()
            return
        if not self._wake.is_set():
            self._wake.set()

    def _drain(self) -> None:
        """Take what waits on each monitored topic, at most ``intake`` messages per step.

        Under a flood the producers refill a queue as fast as it is emptied: a step takes
        at most ``intake`` from each topic — a spinning loop on the wall clock only what
        fits in half a period (:class:`~anunnaki.utu.host._intake.IntakeBudget`) — and the rest
        waits for the next step (or is dropped and counted by the bus when the queue is
        full), so a step stays short and time-driven checks keep their rate.
        """
        wall = isinstance(self.clock, WallClock)
        limit = min(self.parts.config.queue, self.parts.config.intake)
        if self._budget is not None and self._live:
            limit = min(limit, self._budget.limit())  # a live step's time budget
        taken = self._pull.take(limit)
        take_clock(self.clock, self._clock_sub, self._stamps)
        self._inputs.extend(stamp_inputs(taken, wall=wall, stamps=self._stamps))

    def feed(self, topic: str, msg: Mapping[str, Any], *, t: float | None = None) -> None:
        """Queue one input message (what the bus subscription does); processed by ``step``.

        ``t`` is when it arrived (default: the time of the step that takes it); a step takes
        each input at its own time, clamped into the step's interval.
        """
        with self._lock:
            self._inputs.append((topic, dict(msg), None if t is None else float(t)))
        if not self._wake.is_set():
            self._wake.set()

    def pause(self, caller: str = "api") -> None:
        """Suspend adaptation (applied at the next step)."""
        self.desk.enqueue({"op": "pause", "caller": caller})

    def resume(self, caller: str = "api") -> None:
        """Resume adaptation, clearing a run-stop (applied at the next step)."""
        self.desk.enqueue({"op": "resume", "caller": caller})

    def approve(self, tactic: str, *, approve: bool = True, caller: str = "api") -> None:
        """Approve (or reject) a pending tactic (applied at the next step)."""
        self.desk.enqueue({"op": "approve", "caller": caller, "tactic": tactic, "approve": approve})

    def request_reload(
        self,
        *,
        goal_model: str | None = None,
        binding: str | None = None,
        tactics: str | None = None,
        caller: str = "api",
    ) -> None:
        """Ask for a hot reload at the next step (thread-safe, unlike :meth:`reload`)."""
        op: dict[str, Any] = {"op": "reload", "caller": caller}
        for key, value in (("goal_model", goal_model), ("binding", binding), ("tactics", tactics)):
            if value is not None:
                op[key] = value
        self.desk.enqueue(op)

    def run_stop(self, *, caller: str = "api", reason: str = "operator") -> None:
        """Halt adaptation and stop the managed system (applied at the next step)."""
        self.desk.enqueue({"op": "run_stop", "caller": caller, "reason": reason})

    # -- the step -----------------------------------------------------------------------------
    def step(self, now: float | None = None, *, execute: bool = True) -> None:
        """Run one deterministic cycle at time ``now`` (default: the clock's).

        Every queued input and operator call is taken in arrival order, the passing of time
        is applied, the goal model re-evaluated (incrementally), the tactics selected,
        queued, started and checked. ``execute=False`` only analyses (a replay of a step
        that a per-node run's execute node never acted on, having died): operator calls
        and tactics then stay unperformed, as they did.
        """
        self._step_wanted = True
        with self._step_lock:
            self._step_wanted = False
            self._step(now, react=False, execute=execute)

    def _step(self, now: float | None, *, react: bool, execute: bool = True) -> None:
        started = time.perf_counter()
        taken = self._cycle(now, react=react, execute=execute)
        if self._budget is not None:
            self._budget.spent(taken, time.perf_counter() - started)

    def _cycle(self, now: float | None, *, react: bool, execute: bool) -> int:
        """One step; returns how many inputs it took."""
        with self._lock:
            self._drain()
            inputs = list(self._inputs)
            self._inputs.clear()
        ops = self.desk.take()
        self._wake.clear()
        # The clock is read after draining, so no input taken here arrived after ``t``.
        t = self.clock.now() if now is None else float(now)
        batch = self.monitor_stage.batch(max(t, self.now), inputs, ops)
        self.now = batch.t
        a = self.analyze_stage
        idle = react and not any(rt.state == "running" for rt in self.planner.runtimes.values())
        state = a.analyze(batch, full=False, react=idle)
        if state is None:
            return len(inputs)  # nothing to decide now: the next time-driven step goes on from here
        kb = self.knowledge
        if not execute:
            end_step(kb, float(state.t or 0.0), took=bool(state.took), decisions=0)
            kb.flush()
            return len(inputs)
        before = kb.decisions_written
        status = self.execute_stage.begin(state)
        start = self.plan_stage.plan(status)
        done = self.execute_stage.complete(start)
        end_step(kb, float(state.t or 0.0), took=bool(state.took), decisions=done.decisions)
        self.knowledge_stage.queue = self.planner.queue()
        self.knowledge_stage.flags = {"paused": self.paused, "run_stopped": self.run_stopped}
        self._state_cache = None
        decided = kb.decisions_written != before
        if decided or not react:
            kb.flush()
        self._stepped = True
        if self.publish_state and (state.changed or ops or decided):
            self._publish_state()
        return len(inputs)

    def _display_state(self) -> AnalysisState:
        if self._state_cache is None or self._state_cache.t != self.now:
            a = self.analyze_stage
            self._state_cache = a.state(
                self.now,
                a.eligible,
                queue=self.planner.queue(),
                paused=self.paused,
                run_stopped=self.run_stopped,
            )
        return self._state_cache

    def _publish_state(self) -> None:
        try:
            self._state_cache = None
            self.bus.publish(topics.ANALYSIS, self._display_state())  # type: ignore[union-attr]
        except AnunnakiError as exc:  # pragma: no cover - closed bus at shutdown
            log.warning("could not publish the analysis: %s", exc)

    # -- queries ------------------------------------------------------------------------------
    def _query(self, message: Any) -> dict[str, Any]:
        ks = self.knowledge_stage
        if body_of(message).get("what", "state") == "state":
            with self._step_lock:
                self._state_cache = None
                ks.state = self._display_state().to_body()
        return ks.query(message)

    # -- reload -------------------------------------------------------------------------------
    def reload(
        self,
        *,
        goal_model: str | None = None,
        binding: str | None = None,
        tactics: str | None = None,
        now: float | None = None,
    ) -> list[str]:
        """Swap in new files now, in a cycle of their own; returns the problems (empty = swapped).

        The new set is checked as ``anunnaki check`` does; an invalid one is refused with
        its errors (recorded) and the old one stays active. Tactic state (in flight,
        cooldowns) carries over for tactics that keep their name; the attribute values and
        rates carry over by re-feeding the recent inputs. Not thread-safe with a spinning
        manager: use :meth:`request_reload` or ``/utu/reload`` there.
        """
        files = {"goal_model": goal_model, "binding": binding, "tactics": tactics}
        request = {"caller": "api", **{k: v for k, v in files.items() if v}}
        if self.monitor_stage.operator_token is not None:  # a call in this process is trusted
            request["token"] = self.monitor_stage.operator_token
        reply = self.desk.call("reload", request)
        if self.desk.pending:  # queued (accepted, or refused and recorded): its own cycle
            self.step(self.now if now is None else now)
        return [] if reply["ok"] else [str(reply["error"])]

    def restart_part(self, node: str) -> None:
        """Start one part of the loop again on its knowledge, as a restarted node would.

        ``node`` is ``analyze``, ``plan`` or ``execute`` (a per-node run whose node was
        killed and started again): the stage is rebuilt from this manager's knowledge —
        values, tactic state, run-stop — and a restart recorded. A replay does this where
        the run's log says a node was restarted.

        Raises:
            ValueError: Another ``node``.

        """
        kb, parts = self.knowledge, self.parts
        with self._step_lock:
            if node == "analyze":
                self.analyze_stage = take_up(
                    kb, node, lambda: AnalyzeStage(parts, kb), restarted=True
                )
            elif node == "plan":
                self.plan_stage = take_up(
                    kb, node, lambda: PlanStage(parts, kb, planner=self.planner), restarted=True
                )
            elif node == "execute":
                self._execute.restart()
            else:
                raise ValueError(f"no part {node!r} to restart: analyze, plan or execute")

    # -- live ----------------------------------------------------------------------------------
    def spin(
        self,
        stop: threading.Event | None = None,
        *,
        rate: float | None = None,
        until: float | None = None,
        on_step: Callable[[AutonomicManager], None] | None = None,
    ) -> None:
        """Run live until ``stop`` is set (or the clock passes ``until``).

        Inputs are reacted to as they arrive (see the module docstring); time-driven
        checks run ``rate`` times a second (default: the configuration's).
        """
        stop = stop or threading.Event()
        period = 1.0 / (rate or self.rate)
        self._inline = isinstance(self.bus, InprocBus)
        if isinstance(self.clock, WallClock):  # a step's inputs fit in half a period
            self._budget = IntakeBudget(period / 2, ceiling=self.parts.config.intake)
        self._live = True
        self._execute.go_live(self.clock)
        try:
            with watched(
                self.bus, self.parts.config, what=f"the manager {self.name}", name=self.name,
                floor=2 * period,
            ) as beat:  # fmt: skip
                while not stop.is_set() and not self._closed:
                    beat()
                    self._round(on_step)
                    if until is not None and self.clock.now() >= until:
                        break
                    if not self._inputs and not self.desk.pending and not self._pending():
                        self._wake.wait(idle_wait(self.clock, period))
            if self.analyze_stage.reacted and not self._closed:
                self.step()  # a normal end ends the step its last reactions began
        finally:
            self._live = False

    def run_on(self, executor: BusExecutor) -> Callable[[], None]:
        """Run on a deterministic executor (a simulated run) instead of :meth:`spin`.

        Nothing waits and no thread of the manager's runs (:mod:`anunnaki.bus._executor`):

        * a monitored message's doorbell is a work item of the executor, so the reaction
          step runs in publication order, on the executor's thread;
        * whenever the executor's queue is empty (the present instant's messages all
          delivered), the manager steps once at the present time (the simulation's
          ``/clock``), if it has not yet, and takes any input or operator call still
          waiting: the time-driven checks run at every instant the simulation passes
          through;
        * actions run in the step: their requests are answered in the same drain.

        Returns the detach call: it ends the step the last reactions began (as a normal end
        of :meth:`spin` does) and removes the idle hook. Liveliness and the watchdog are a
        live loop's (:meth:`spin`); a run on an executor has no loop that could stall.
        """
        self._execute.run_inline()
        self._stamps = None  # each input is taken in the instant it was published in
        self._inline = True
        self._live = True
        remove = executor.on_idle(self._at_present)

        def detach() -> None:
            remove()
            try:
                if self.analyze_stage.reacted and not self._closed:
                    self.step()
            finally:
                self._live = False

        return detach

    def _at_present(self) -> bool:
        """The executor's idle hook: one step at the present instant (see :meth:`run_on`)."""
        clock = self._clock_sub is not None and self._clock_sub.pending
        if self._closed or not (
            self._pull.pending
            or self._inputs
            or self.desk.pending
            or clock
            or self.now < self.clock.now()
        ):
            return False
        self._round(None)
        return True

    def _round(self, on_step: Callable[[AutonomicManager], None] | None) -> None:
        self.step()
        if self._nodes:
            self._publish_decisions()
        if on_step is not None:
            on_step(self)

    _inline = False

    def _publish_decisions(self) -> None:
        if self._decisions is not None and self._decisions.due():
            self._decisions.publish()

    def _pending(self) -> bool:
        if isinstance(self.actions, ThreadRunner) and self.actions.has_outcomes:
            return True  # an action came back: take it now
        return self._pull.pending

    def input_queues(self) -> list[Any]:
        """The bounded queues of the monitored topics (pull subscribers)."""
        return self._pull.queues()

    def wake(self) -> None:
        """Wake ``spin()`` now."""
        self._wake.set()

    def snapshot(self) -> dict[str, Any]:
        """What a display needs now: analysis, monitor, queue, flags."""
        state = self._display_state().to_body()
        state["monitor"] = self.monitor.snapshot(self.now)
        return state

    def close(self) -> None:
        """Close subscriptions and services, flush and close the knowledge base."""
        if self._closed:
            return
        self._closed = True
        for d in reversed(self._declared):
            try:
                d.close()
            except Exception as exc:  # pragma: no cover - best effort at shutdown
                log.debug("closing %r: %r", d, exc)
        self._declared.clear()
        self._execute.close()
        with self._step_lock:
            self.knowledge.close()
