"""Utu as nodes: the five MAPE-K services on the bus, in one process or one process each.

The paper runs Utu as ROS nodes (§4.1.4, Fig. 13): ``/utu_monitor``, ``/utu_analyze``,
``/utu_plan``, ``/utu_execute`` and ``/utu_knowledge``. Here each service is a node class
built from the same parts as :class:`~anunnaki.utu.AutonomicManager` (``Monitor``,
``Analyzer``, ``Planner``, ``Executor``, ``Knowledge``), so a node runs alone (``anunnaki
node plan``), with others in one process, or each in its own process over zenoh.

Why a cycle travels the way it does
    One :meth:`AutonomicManager.step` is: take the inputs, evaluate, apply operator calls,
    check the tactics in flight (postconditions, escalation), plan, start. Split across
    processes, the same step becomes one *cycle* that visits the nodes in that order::

        monitor ─ /utu/monitor/input ─▶ analyze ─ /utu/analyze/state ─▶ execute: ops, check
           ▲                              ▲                                │
        agent topics               /utu/execute/done              /utu/execute/status
                                          │                                ▼
                                       execute: start ◀─ /utu/plan/start ─ plan: update

    The analyze node owns the cycle: it starts cycle *k+1* only when the execute node
    reports cycle *k* done (or, if the execute node is absent or silent, after a timeout),
    so plan and execute see exactly the analyses, times and tactic states the composed
    manager would, and the same inputs give the same decisions. The tactic state is split
    by owner: the plan node owns selection (eligible since, queued, pending approval), the
    execute node owns what happens in flight (running, awaiting, deadline, cooldown,
    attempts); each cycle carries the other's half across.

    All nodes share ONE knowledge base, the SQLite file of the configuration (WAL mode lets
    several processes write it): the analyze node records inputs and verdicts, plan and
    execute record decisions and tactic state, the knowledge node answers queries and
    publishes new decisions. It stays the single source of truth (guideline N8).

What every node has
    * a liveliness token ``/utu_<name>`` while it runs;
    * a readiness service ``/utu/<name>/ready``, declared last: it answers only once the
      node is fully up (guideline C9);
    * a bring-up that fails explicitly on bad configuration, naming file and line (B5);
    * its own processing rate (C5, B2): at most ``rate`` cycles per second of its clock;
      inputs that arrive meanwhile are taken together in the next cycle;
    * a ``/utu/run_stop`` subscription (S4): plan and execute stop starting tactics at once;
      the monitor turns it into an operator input so the run-stop is recorded and the
      managed system commanded to stop, exactly as the composed manager does.

``step``/``step_nodes`` drive nodes deterministically (tests, replay); ``spin`` runs live.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import secrets
import sqlite3
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Literal, Protocol, cast

from anunnaki import topics
from anunnaki._findings import Finding
from anunnaki.bus import Bus, RunStop, Sample, Subscriber, body_of
from anunnaki.check import check_tactics
from anunnaki.clock import Clock, SimClock, WallClock
from anunnaki.errors import AnunnakiError, ModelFileError
from anunnaki.goals import GoalModel, parse_binding, parse_goal_model
from anunnaki.tactics import TacticSet
from anunnaki.utu._config import UtuConfig
from anunnaki.utu._knowledge import Decision, Knowledge
from anunnaki.utu._manager import AutonomicManager, BusActuator, load_tactics_text
from anunnaki.utu._mape import Actuator, Analyzer, Executor, Monitor, Planner, TacticRuntime

__all__ = [
    "DECISIONS_TOPIC",
    "DONE_TOPIC",
    "INPUT_TOPIC",
    "NODE_NAMES",
    "RUN_STOP_TOPIC",
    "START_TOPIC",
    "STATE_TOPIC",
    "STATUS_TOPIC",
    "AnalyzeNode",
    "ComposedUtu",
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

NodeName = Literal["monitor", "analyze", "plan", "execute", "knowledge"]
#: The five Utu nodes, in the order a cycle visits them (knowledge last).
NODE_NAMES: tuple[NodeName, ...] = ("monitor", "analyze", "plan", "execute", "knowledge")

INPUT_TOPIC = topics.MONITOR_INPUT
STATE_TOPIC = topics.ANALYSIS
STATUS_TOPIC = topics.EXECUTE_STATUS
START_TOPIC = topics.PLAN_START
DONE_TOPIC = topics.CYCLE_DONE
DECISIONS_TOPIC = topics.DECISIONS
RUN_STOP_TOPIC = topics.RUN_STOP
QUERY_SERVICE = topics.QUERY
OPERATOR_SERVICES = ("run_stop", "pause", "resume", "approve")

# What the manager writes into the inputs table (kept identical so a replay cannot tell).
TICK = "__tick__"
OPERATOR = "__operator__"

_STATUS_OF_NAME: dict[str, bool | None] = {"satisfied": True, "unsatisfied": False}


def ready_service(name: str) -> str:
    """The readiness service of a node: ``/utu/<name>/ready``."""
    return f"/utu/{name}/ready"


def node_token(name: str) -> str:
    """The liveliness token of a node: ``/utu_<name>``."""
    return f"/utu_{name}"


class NodeConfigError(AnunnakiError):
    """A node cannot be brought up with the configuration it was given."""


class _Closable(Protocol):
    def close(self) -> None: ...


# -- loading -----------------------------------------------------------------------------
@dataclass(frozen=True)
class UtuParts:
    """A Utu configuration with its files loaded and checked (what every node needs).

    Attributes:
        config: The configuration (paths absolute).
        sources: ``goal_model``/``binding``/``tactics`` -> (path, text), as recorded in
            the knowledge base.
        model: The goal model with its binding applied.
        tactics: The tactics.
        warnings: Warning-level findings of the tactics check (not fatal).

    """

    config: UtuConfig
    sources: dict[str, tuple[str | None, str]]
    model: GoalModel
    tactics: TacticSet
    warnings: list[Finding] = field(default_factory=list)


def load_parts(config: UtuConfig) -> UtuParts:
    """Load and check the goal model, binding and tactics of ``config`` (guideline B5).

    Raises:
        ModelFileError: A file is missing or invalid, or a tactic names an unknown goal,
            endpoint or the fail-safe is not a tactic; the message names file and line.

    """
    sources: dict[str, tuple[str | None, str]] = {}
    for kind in ("goal_model", "binding", "tactics"):
        path = getattr(config, kind)
        if path is None:
            continue
        try:
            sources[kind] = (path, Path(path).read_text(encoding="utf-8"))
        except OSError as exc:
            raise ModelFileError(
                f"cannot read the {kind.replace('_', ' ')}: {exc.strerror}",
                path=path,
                hint="check the path in the Utu configuration (relative to its file)",
            ) from exc
    b = sources.get("binding")
    binding = parse_binding(b[1], source=b[0] or "<binding>") if b else None
    gpath, gtext = sources["goal_model"]
    model = parse_goal_model(gtext, source=gpath or "<goal-model>", binding=binding)
    t = sources.get("tactics")
    tactics = load_tactics_text(t[1], t[0]) if t else TacticSet(tactics=[])
    findings = check_tactics(model, tactics, t[0] if t else None)
    errors = [f for f in findings if f.severity == "error"]
    if errors:
        raise errors[0].to_error()
    names = {tac.name for tac in tactics.tactics}
    if config.failsafe is not None and config.failsafe not in names:
        known = ", ".join(sorted(names)) or "none"
        raise ModelFileError(
            f"the fail-safe tactic {config.failsafe!r} is not in the tactics file",
            path=t[0] if t else None,
            element="failsafe",
            hint=f"name one of the tactics ({known})",
        )
    return UtuParts(config, sources, model, tactics, [f for f in findings if f not in errors])


def open_knowledge(path: str) -> Knowledge:
    """Open (or create) a knowledge base, or say clearly why it cannot be.

    Raises:
        NodeConfigError: SQLite cannot open the file (missing folder, no permission, …).

    """
    try:
        return Knowledge(path)
    except sqlite3.Error as exc:
        raise NodeConfigError(
            f"cannot open the knowledge base {path}: {exc} (check that its folder exists "
            "and is writable)"
        ) from exc


# -- the node base ---------------------------------------------------------------------------
class UtuNode:
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
        rate: At most this many cycles per second of the clock (default: the
            configuration's ``rate``).
        timeout: Seconds to wait for a partner node's answer before going on without it.

    """

    name: ClassVar[NodeName]
    needs_knowledge: ClassVar[bool] = True
    #: Whether the node reads the clock (monitor and analyze; plan and execute take the
    #: time of each cycle from the analysis).
    uses_clock: ClassVar[bool] = False
    #: Take the simulation time in ``step`` (pull) rather than on the bus's thread.
    pull_clock: ClassVar[bool] = False

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
        self.bus = bus
        self.rate = float(rate if rate is not None else self.config.rate)
        if not 0 < self.rate <= 10_000:
            raise NodeConfigError(f"{self.name}: rate must be in (0, 10000] Hz, got {rate!r}")
        self.timeout = float(timeout)
        self.clock: Clock = clock or (SimClock() if self.config.clock == "sim" else WallClock())
        self.run_stopped = False
        self.cycles = 0
        self.ready = False
        self._declared: list[_Closable] = []
        self._wake = threading.Event()
        self._closed = False
        self._next_cycle = 0.0
        self._lock = threading.Lock()
        self._kb: Knowledge | None = knowledge
        self._own_kb = False
        try:
            if self.needs_knowledge and knowledge is None:
                if self.config.knowledge == ":memory:":
                    raise NodeConfigError(
                        f"the {self.name} node needs the knowledge base shared by all nodes, "
                        "but the configuration says knowledge: ':memory:' (private to one "
                        "process); give a file (e.g. knowledge: run.db or --knowledge run.db)"
                    )
                self._kb = open_knowledge(self.config.knowledge)
                self._own_kb = True
            self._clock_sub: Subscriber | None = None
            if isinstance(self.clock, SimClock) and self.uses_clock:
                topic = self.config.clock_topic
                if self.pull_clock:
                    self._clock_sub = self._pull(topic, 16)
                else:
                    self._declare(self.bus.subscribe(topic, self._on_clock, queue=64))
            self._declare(self.bus.subscribe(RUN_STOP_TOPIC, self._on_run_stop_sample, queue=16))
            self._bring_up()
            self._declare(self.bus.liveliness_token(node_token(self.name)))
            self.ready = True
            self._declare(self.bus.service(ready_service(self.name), self._ready_reply))
        except BaseException:
            self.close()
            raise

    # -- helpers for subclasses
    @property
    def knowledge(self) -> Knowledge:
        """The knowledge base this node reads and writes."""
        if self._kb is None:
            raise NodeConfigError(f"the {self.name} node has no knowledge base")
        return self._kb

    def _declare(self, obj: Any) -> Any:
        self._declared.append(obj)
        return obj

    def _pull(self, topic: str, queue: int) -> Subscriber:
        """A pull subscriber (drained by ``step``) whose doorbell wakes ``spin``."""
        return cast(
            Subscriber, self._declare(self.bus.subscribe(topic, queue=queue, on_ready=self._ring))
        )

    def _ring(self) -> None:
        if not self._wake.is_set():
            self._wake.set()

    def _on_clock(self, sample: Sample) -> None:
        t = getattr(sample.message, "time", None)
        if isinstance(t, int | float) and isinstance(self.clock, SimClock):
            self.clock.update(float(t))
            self._wake.set()

    def _take_clock(self) -> None:
        """Apply the simulation times queued since the last call (pull clock)."""
        sub = self._clock_sub
        if sub is None or not isinstance(self.clock, SimClock):
            return
        while (sample := sub.try_recv()) is not None:
            t = getattr(sample.message, "time", None)
            if isinstance(t, int | float):
                self.clock.update(float(t))

    def _on_run_stop_sample(self, sample: Sample) -> None:
        body = body_of(sample.message)
        caller = str(body.get("caller") or sample.sender)
        if caller.startswith(f"utu:{self.config.name}"):
            return  # Utu's own announcement of a run-stop it already performs
        log.warning("%s: run-stop from %s: %s", self.name, caller, body.get("reason"))
        self.run_stopped = True
        self._on_run_stop(caller, str(body.get("reason", "run-stop topic")))
        self._wake.set()

    def _on_run_stop(self, caller: str, reason: str) -> None:
        """Hook: a run-stop arrived on ``/utu/run_stop`` (from anyone but Utu itself)."""

    def _ready_reply(self, message: Any) -> dict[str, Any]:
        return {
            "ready": self.ready and not self._closed,
            "node": node_token(self.name),
            "utu": self.config.name,
            "pid": os.getpid(),
            "rate": self.rate,
            "cycles": self.cycles,
            "run_stopped": self.run_stopped,
        }

    def _period(self) -> float:
        """Seconds of wall time between two cycles at ``rate`` (scaled by the sim speed)."""
        period = 1.0 / self.rate
        if isinstance(self.clock, SimClock) and self.clock.speed > 0:
            return min(period / max(self.clock.speed, 0.05), 0.5)
        return period

    def _gate(self) -> float:
        """Seconds until the rate allows the next cycle (0: now).

        On wall time the rate caps the cycles per second. On simulation time the simulator
        sets the pace (a lockstep replay even waits for Utu), so a cap in wall seconds
        would only slow the simulation down; there the rate paces what is time-driven, in
        simulated seconds: the monitor's watermarks and the analyze node's own ticks.
        """
        if isinstance(self.clock, SimClock):
            return 0.0
        return max(0.0, self._next_cycle - time.monotonic())

    def _mark_cycle(self) -> None:
        self._next_cycle = time.monotonic() + self._period()

    # -- hooks
    def _bring_up(self) -> None:
        """Hook: declare what the node needs (called by the constructor)."""

    def _spin_once(self) -> float:
        """Hook: do what can be done now; return how long to wait for a wake-up."""
        return 0.5

    # -- running
    def wake(self) -> None:
        """Wake ``spin`` (e.g. after setting its stop event)."""
        self._wake.set()

    def spin(self, stop: threading.Event | None = None) -> None:
        """Run live until ``stop`` is set or the node is closed."""
        stop = stop or threading.Event()
        while not stop.is_set() and not self._closed:
            self._wake.clear()
            try:
                wait = self._spin_once()
            except Exception:  # one bad cycle must not kill the node (DESIGN: log, go on)
                log.exception("%s: a cycle failed; going on", self.name)
                wait = self._period()
            if wait > 0 and not stop.is_set():
                self._wake.wait(min(wait, 0.5))

    def close(self) -> None:
        """Withdraw readiness and token first, then everything else; close own knowledge."""
        if self._closed:
            return
        self._closed = True
        self.ready = False
        for obj in reversed(self._declared):
            try:
                obj.close()
            except Exception as exc:  # best effort at shutdown
                log.debug("%s: closing %r: %r", self.name, obj, exc)
        self._declared.clear()
        self._close_extra()
        if self._own_kb and self._kb is not None:
            self._kb.close()

    def _close_extra(self) -> None:
        """Hook: release what the subclass holds besides declared bus objects."""

    def __enter__(self) -> UtuNode:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


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

    It subscribes the topics the goal model's binding names (bounded queues, guideline S1),
    and at most ``rate`` times a second publishes what arrived as one batch on
    ``/utu/monitor/input``: ``{seq, t, inputs: [{topic, msg}], ops: [...]}`` with ``t`` the
    time of taking (its arrival time). When nothing arrives it still publishes an empty
    batch whenever its clock has moved on by ``1/rate``: a watermark that tells the analyze
    node how far time has passed *with no input*, so that staleness and rates are never
    judged ahead of the inputs (on sim time the clock is read in the same thread, before
    the inputs, so no input is stamped later than the instant it belongs to).

    It also offers the operator services of Utu (``/utu/run_stop``, ``/utu/pause``,
    ``/utu/resume``, ``/utu/approve``), and turns run-stops published on ``/utu/run_stop``
    and vanished agent nodes (liveliness) into operator inputs, so that they enter the
    cycle at a defined point, as in the composed manager.
    """

    name = "monitor"
    needs_knowledge = False
    uses_clock = True
    pull_clock = True

    def _bring_up(self) -> None:
        self.topics: list[str] = []
        for agent in self.parts.model.agents.values():
            for tb in agent.topics:
                if tb.topic not in self.topics:
                    self.topics.append(tb.topic)
        self._subs = {t: self._pull(t, self.config.queue) for t in self.topics}
        self._fed: list[tuple[str, dict[str, Any]]] = []
        self._ops: list[dict[str, Any]] = []
        self._seq = 0
        self._last_t = -float("inf")
        for op in OPERATOR_SERVICES:
            self._declare(self.bus.service(f"/utu/{op}", self._op_handler(op)))
        if any(a.node for a in self.parts.model.agents.values()):
            self._declare(self.bus.watch_liveliness(self._on_liveliness))

    def feed(self, topic: str, msg: Mapping[str, Any]) -> None:
        """Queue one input as if it had arrived on ``topic`` (tests, replay)."""
        with self._lock:
            self._fed.append((topic, dict(msg)))
        self._wake.set()

    def _enqueue_op(self, op: dict[str, Any]) -> None:
        with self._lock:
            self._ops.append(op)
        self._wake.set()

    def _op_handler(self, op: str) -> Callable[[Any], dict[str, Any]]:
        return lambda message: self._op_service(op, message)

    def _op_service(self, op: str, message: Any) -> dict[str, Any]:
        body = body_of(message)
        caller = str(body.get("caller") or "unknown")
        entry: dict[str, Any] = {"op": op, "caller": caller}
        if op == "approve":
            tactic = body.get("tactic")
            if not isinstance(tactic, str):
                return {"ok": False, "error": "give 'tactic': the name of a pending tactic"}
            entry["tactic"] = tactic
            entry["approve"] = bool(body.get("approve", True))
        if op == "run_stop":
            entry["reason"] = str(body.get("reason", "operator"))
            self.run_stopped = True
        if op == "resume":
            self.run_stopped = False
        self._enqueue_op(entry)
        return {"ok": True, "queued": op, "caller": caller}

    def _on_run_stop(self, caller: str, reason: str) -> None:
        self._enqueue_op({"op": "run_stop", "caller": caller, "reason": reason})

    def _on_liveliness(self, node: str, alive: bool) -> None:
        if not alive:
            self._enqueue_op({"op": "node_lost", "node": node, "caller": "liveliness"})

    def input_queues(self) -> list[Subscriber]:
        """The bounded queues of the monitored topics (empty: everything was taken)."""
        return list(self._subs.values())

    def step(self, now: float | None = None) -> bool:
        """Publish what arrived since the last step as one batch; returns whether it did.

        A batch goes out when something arrived, or as a watermark when the time moved on
        by at least ``1/rate`` since the last batch. The inputs are taken first, then the
        simulation time: a message published after its instant's ``/clock`` is never
        stamped with an earlier time.
        """
        inputs: list[dict[str, Any]] = []
        with self._lock:
            inputs += [{"topic": topic, "msg": msg} for topic, msg in self._fed]
            self._fed.clear()
            for topic, sub in self._subs.items():
                while (sample := sub.try_recv()) is not None:
                    inputs.append({"topic": topic, "msg": body_of(sample.message)})
            ops, self._ops = self._ops, []
        if now is None:
            self._take_clock()
        t = self.clock.now() if now is None else float(now)
        if not inputs and not ops and t < self._last_t + 1.0 / self.rate:
            return False
        self._last_t = max(t, self._last_t)
        self._seq += 1
        self.bus.publish(INPUT_TOPIC, {"seq": self._seq, "t": t, "inputs": inputs, "ops": ops})
        self.cycles += 1
        return True

    def _spin_once(self) -> float:
        gate = self._gate()
        if gate > 0:
            return gate
        if self.step():
            self._mark_cycle()
        return self._period() if isinstance(self.clock, WallClock) else 0.5


# -- analyze -----------------------------------------------------------------------------------
@dataclass
class _Cycle:
    seq: int
    t: float
    marked: bool
    since: float


class AnalyzeNode(UtuNode):
    """``/utu_analyze``: evaluates the goal model and owns the cycle.

    Each cycle takes the monitor's batches, records them in the knowledge base (inputs,
    verdicts: exactly the rows the composed manager writes), evaluates the goal model
    incrementally and publishes ``/utu/analyze/state``: the manager's state message
    (``t``, ``root``, ``nodes``: utility and status per goal, ``violated``, ``tactics``)
    plus what plan and execute need: ``eligible`` (in file order), ``postconditions``
    (tactic -> whether they hold), ``ops``, ``seq`` and ``taken`` (inputs taken so far).
    Each input is observed at the time the monitor took it. Its time comes from the
    monitor's batches (watermarks included) while ``/utu_monitor`` is alive; without a
    monitor it cycles ``rate`` times a second of its own clock, so inputs going stale are
    noticed even when the monitor is gone.

    Args:
        pace: Wait for the execute node to finish each cycle before starting the next:
            ``True``, ``False``, or ``None`` (default) while ``/utu_execute`` is alive.
        **kwargs: As :class:`UtuNode`.

    """

    name = "analyze"
    uses_clock = True

    def __init__(self, utu: UtuConfig | UtuParts, *, pace: bool | None = None, **kwargs: Any):
        self._pace = pace
        super().__init__(utu, **kwargs)

    def _bring_up(self) -> None:
        kb = self.knowledge
        self.monitor = Monitor(self.parts.model, kb)
        self.analyzer = Analyzer(self.parts.model, self.parts.tactics, kb)
        self.now = 0.0
        self._started_at: float | None = None
        if kb.tactics():  # resuming after a restart: time goes on from the last decision
            last = kb.decisions(limit=1)
            if last:
                self.now = last[-1].t
        self.origin = secrets.token_hex(4)
        self.taken = 0  # inputs taken since bring-up
        # execute itself waits up to ``timeout`` for plan: give it time to say so
        self._ack_timeout = 2 * self.timeout
        self._seq = 0
        self._awaiting: _Cycle | None = None
        self._unpaced = False
        self._last_seq = -1
        self.timeouts = 0
        self._batches = self._pull(INPUT_TOPIC, max(self.config.queue, 64))
        self._done = self._pull(DONE_TOPIC, 64)
        self._presence = _Presence(self.bus, self._wake.set)
        self._declare(self._presence.watch)

    def _expects_execute(self) -> bool:
        if self._pace is not None:
            return self._pace
        return self._presence.alive("execute")

    def _paced(self) -> bool:
        return self._expects_execute() and not self._unpaced

    def settle(self) -> bool:
        """Take the execute node's reports; finish the cycle it reports done."""
        finished = False
        while (sample := self._done.try_recv()) is not None:
            body = body_of(sample.message)
            if body.get("origin") != self.origin:
                continue
            seq = body.get("seq")
            if self._awaiting is not None and seq == self._awaiting.seq:
                n = body.get("decisions")
                self._finish(n if isinstance(n, int) else None)
                finished = True
            if seq == self._last_seq:
                self._unpaced = False
        return finished

    def _finish(self, decisions: int | None) -> None:
        cycle, self._awaiting = self._awaiting, None
        if cycle is None:
            return
        if cycle.marked or (decisions or 0) > 0:
            # Mark the end of this step, so a replay steps at the same instants.
            self.knowledge.record_input(cycle.t, TICK, {})
        self.cycles += 1

    def waiting(self) -> bool:
        """Whether the current cycle waits for the execute node (and has not timed out)."""
        if self._awaiting is None or not self._paced():
            return False
        return time.monotonic() - self._awaiting.since < self._ack_timeout

    def step(self, now: float | None = None) -> bool:
        """Run one cycle at ``now`` (default: the clock's) unless the last one is unfinished.

        Returns:
            Whether a cycle ran (``False`` while the previous cycle waits for execute).

        """
        self.settle()
        if self._awaiting is not None:
            if self.waiting():
                return False
            if self._paced():
                self.timeouts += 1
                self._unpaced = True
                log.warning(
                    "analyze: execute did not finish cycle %d within %.1f s; going on "
                    "without waiting until it answers again",
                    self._awaiting.seq,
                    self._ack_timeout,
                )
            self._finish(None)
        batches = []
        while (sample := self._batches.try_recv()) is not None:
            batches.append(body_of(sample.message))
        if now is not None:
            t = float(now)
        elif self._presence.alive("monitor"):
            t = self.now  # the monitor's batches say how far time has gone
        else:
            t = self.clock.now()
        inputs: list[tuple[float, str, dict[str, Any]]] = []
        for b in batches:
            stamp = b.get("t")
            at = max(float(stamp), self.now) if isinstance(stamp, int | float) else self.now
            t = max(t, at)
            inputs += [
                (at, str(i["topic"]), dict(i["msg"]))
                for i in b.get("inputs", [])
                if isinstance(i, dict) and isinstance(i.get("msg"), dict)
            ]
        ops = [dict(op) for b in batches for op in b.get("ops", []) if isinstance(op, dict)]
        self._cycle(max(t, self.now), inputs, ops)
        return True

    def _cycle(
        self, t: float, inputs: list[tuple[float, str, dict[str, Any]]], ops: list[Any]
    ) -> None:
        a, kb = self.analyzer, self.knowledge
        if self._started_at is None:
            self._started_at = min([t, *(at for at, _, _ in inputs)])
        a.warming_up = t - self._started_at < self.config.warmup
        for at, topic, msg in inputs:
            if self.monitor.take(topic, msg, at):
                a.observe(topic, msg, at)
        self.taken += len(inputs)
        self.now = t
        ticked = a.tick(t)
        changed = a.record_changes(t)
        out_ops = []
        for op in ops:
            kb.record_input(t, OPERATOR, op)
            out = dict(op)
            if op.get("op") == "node_lost":
                node = str(op.get("node"))
                agents = [ag for ag in self.parts.model.agents.values() if ag.node == node]
                for agent in agents:
                    for tb in agent.topics:
                        a.evaluator.expire(tb.topic, t)
                a.record_changes(t)
                # A dead publisher is a known fact, not data still arriving: end the warm-up.
                self._started_at = min(self._started_at, t - self.config.warmup)
                a.warming_up = False
                out["agents"] = [ag.id for ag in agents]
            elif op.get("op") == "resume":
                self.run_stopped = False
            out_ops.append(out)
        eligible = a.eligible()
        post = {
            tac.name: a.postconditions_hold(tac)
            for tac in self.parts.tactics.tactics
            if tac.postconditions
        }
        self._seq += 1
        msg = a.state_message(t, eligible)
        msg.update(
            seq=self._seq,
            origin=self.origin,
            eligible=eligible,
            postconditions=post,
            ops=out_ops,
            warming_up=a.warming_up,
            changed=changed,
            run_stopped=self.run_stopped,
            taken=self.taken,
        )
        marked = bool(not self.cycles or inputs or ticked or changed or ops)  # first: always
        self._awaiting = _Cycle(self._seq, t, marked, time.monotonic())
        self._last_seq = self._seq
        self.bus.publish(STATE_TOPIC, msg)
        if not self._paced():
            self._finish(None)

    def _tick_due(self) -> bool:
        if self._presence.alive("monitor"):
            return False  # its watermarks drive the time
        return self._started_at is None or self.clock.now() >= self.now + 1.0 / self.rate

    def _spin_once(self) -> float:
        self.settle()
        if self.waiting():
            assert self._awaiting is not None
            return self._ack_timeout - (time.monotonic() - self._awaiting.since)
        gate = self._gate()
        if gate > 0:
            return gate
        if self._batches.pending or self._awaiting is not None or self._tick_due():
            self.step()
            self._mark_cycle()
            return 0.0
        return self._period()


# -- plan --------------------------------------------------------------------------------------
# Who owns which part of a tactic's runtime: the plan node selects (when it became eligible,
# the last "deferred" reason, whether it fired in this episode, queued/pending/rejected);
# the execute node owns everything that happens once it starts (every other field).
_PLAN_FIELDS = frozenset({"tactic", "state", "eligible_since", "blocked_logged", "fired"})
_EXEC_FIELDS = tuple(
    f.name for f in dataclasses.fields(TacticRuntime) if f.name not in _PLAN_FIELDS
)


def _runtime_row(rt: TacticRuntime) -> dict[str, Any]:
    return {"state": rt.state, **{f: getattr(rt, f) for f in _EXEC_FIELDS}}


class PlanNode(UtuNode):
    """``/utu_plan``: the priority-sorted queue of tactics (the :class:`Planner`).

    For each cycle the execute node reports (``/utu/execute/status``: eligibility from the
    analysis, the tactics' in-flight state after their postconditions were checked, the
    operator's approvals), it updates the queue (dwell, cooldown, conflicts, approval) and
    publishes ``/utu/plan/start``: the tactics to start now, each tactic's selection state
    and the queue.
    """

    name = "plan"

    def _bring_up(self) -> None:
        kb = self.knowledge
        self.planner = Planner(self.parts.tactics, kb, dwell=self.config.dwell)
        rows = kb.tactics()
        if rows:
            self.planner.restore(rows)
        self._statuses = self._pull(STATUS_TOPIC, 64)

    def step(self) -> bool:
        """Plan every cycle the execute node reported; returns whether there was one."""
        worked = False
        while (sample := self._statuses.try_recv()) is not None:
            self._plan(body_of(sample.message))
            worked = True
        return worked

    def _plan(self, st: dict[str, Any]) -> None:
        kb = self.knowledge
        t = float(st["t"])
        before = kb.decisions_written
        runtimes = self.planner.runtimes
        for name, row in dict(st.get("runtimes", {})).items():
            rt = runtimes.get(name)
            if rt is None or not isinstance(row, dict):
                continue
            if isinstance(row.get("attempt"), int) and row["attempt"] > rt.attempt:
                rt.fired = True  # started by execute (escalation) since we last heard
            for f in _EXEC_FIELDS:
                if f in row:
                    setattr(rt, f, row[f])
            if row.get("state") in ("running", "awaiting") or rt.in_flight:
                rt.state = row["state"]
        for name, state in st.get("approvals", []):
            if name in runtimes:
                runtimes[name].state = state
        if any(op.get("op") == "resume" for op in st.get("ops", [])):
            self.run_stopped = False
        halted = bool(st.get("paused") or st.get("run_stopped") or self.run_stopped)
        start = [] if halted else self.planner.update(list(st.get("eligible", [])), t)
        states = {name: rt.state for name, rt in runtimes.items()}
        for rt in start:
            rt.state = "running"  # the execute node starts it now; its report confirms
            rt.fired = True
        self.bus.publish(
            START_TOPIC,
            {
                "origin": st.get("origin"),
                "seq": st.get("seq"),
                "t": t,
                "start": [rt.name for rt in start],
                "states": states,
                "queue": self.planner.queue(),
                "decisions": kb.decisions_written - before,
            },
        )
        self.cycles += 1

    def _spin_once(self) -> float:
        gate = self._gate()
        if gate > 0:
            return gate
        if self.step():
            self._mark_cycle()
        return 0.5


# -- execute -----------------------------------------------------------------------------------
class _NodeStatus:
    __slots__ = ("status",)

    def __init__(self, status: bool | None) -> None:
        self.status = status


class _StatusView:
    """The part of an Evaluator that :meth:`Executor.check` reads, from an analysis."""

    def __init__(self) -> None:
        self.index: dict[str, bool | None] = {}

    def state(self, node: str) -> _NodeStatus:
        return _NodeStatus(self.index.get(node))


class _AnalysisView:
    """What :meth:`Executor.check` reads from an :class:`Analyzer`, from an analysis message."""

    def __init__(self) -> None:
        self.post: dict[str, bool] = {}
        self.evaluator = _StatusView()

    def update(self, state: Mapping[str, Any]) -> None:
        self.post = {str(k): bool(v) for k, v in dict(state.get("postconditions", {})).items()}
        nodes = state.get("nodes", {})
        if isinstance(nodes, dict):
            self.evaluator.index = {
                str(n): _STATUS_OF_NAME.get(str(v[1])) if isinstance(v, list) else None
                for n, v in nodes.items()
            }

    def postconditions_hold(self, tactic: Any) -> bool:
        return self.post.get(tactic.name, False)


@dataclass
class _Pending:
    origin: Any
    seq: Any
    t: float
    since: float
    before: int


class ExecuteNode(UtuNode):
    """``/utu_execute``: performs tactics and checks their postconditions (the :class:`Executor`).

    Each analysis it receives is one cycle: it applies the operator calls (pause, resume,
    approve, run-stop), runs resumed actions, checks the postconditions of tactics in flight
    against the analysis (escalating to another tactic, the fail-safe or a run-stop when
    one fails), reports on ``/utu/execute/status``, starts what the plan node answers on
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

    def _bring_up(self) -> None:
        kb, config = self.knowledge, self.config
        self._notifier: Any = None
        actuator = self._actuator_arg
        if actuator is None:
            if config.notify:
                from anunnaki.utu._notify import Notifier, NotifyConfig

                self._notifier = Notifier(NotifyConfig.model_validate(config.notify))
            actuator = BusActuator(self.bus, self._notifier, on_notified=self._notified)
        self.actuator: Actuator = actuator
        # The planner here only holds the tactic runtimes (and knows the conflicts); the
        # plan node runs the selection.
        self.planner = Planner(self.parts.tactics, kb, dwell=config.dwell)
        self.executor = Executor(self.actuator, kb, on_failure=self._escalate)
        self.paused = False
        self.stopped = False
        self.now = 0.0
        self._view = _AnalysisView()
        self._eligible: list[str] = []
        self._approvals: list[list[str]] = []
        self._pending: _Pending | None = None
        self.timeouts = 0
        rows = kb.tactics()
        if rows:
            resumed = self.planner.restore(rows)
            last = kb.decisions(limit=1)
            if last:
                self.now = last[-1].t
            for rt in resumed:
                kb.record_decision(
                    self.now,
                    "resumed",
                    rt.name,
                    state=rt.state,
                    deadline=rt.deadline,
                    next_action=rt.next_action,
                )
        self._states = self._pull(STATE_TOPIC, max(self.config.queue, 64))
        self._starts = self._pull(START_TOPIC, 64)
        self._presence = _Presence(self.bus, self._wake.set) if self._expect_plan is None else None
        if self._presence is not None:
            self._declare(self._presence.watch)

    def _close_extra(self) -> None:
        if self._notifier is not None:
            self._notifier.close()

    def _notified(self, tactic: str, result: Any) -> None:
        # From the notifier's worker thread (Knowledge is thread-safe), as the manager does.
        if self._closed:
            return
        self.knowledge.record_decision(
            self.now,
            "notify_result",
            tactic,
            ok=bool(getattr(result, "ok", False)),
            channel=getattr(result, "channel", None),
            to=getattr(result, "to", None),
            error=getattr(result, "error", None),
        )

    @property
    def halted(self) -> bool:
        """Whether adaptation is halted (paused, run-stopped, or a run-stop was heard)."""
        return self.paused or self.stopped or self.run_stopped

    def _expects_plan(self) -> bool:
        if self._expect_plan is not None:
            return self._expect_plan
        return self._presence is not None and self._presence.alive("plan")

    # -- the cycle
    def step(self) -> bool:
        """Advance through every cycle that can be advanced now; returns whether any did."""
        return self._advance(gated=False)

    def _advance(self, *, gated: bool) -> bool:
        worked = False
        while True:
            if self._pending is not None:
                start = self._take_start()
                if start is None:
                    waited = time.monotonic() - self._pending.since
                    if self._expects_plan() and waited < self.timeout:
                        return worked
                    if self._expects_plan():
                        self.timeouts += 1
                        log.warning(
                            "execute: plan did not answer cycle %s within %.1f s; "
                            "starting nothing this cycle",
                            self._pending.seq,
                            self.timeout,
                        )
                self._complete(start)
                worked = True
                continue
            if gated and self._gate() > 0:
                return worked
            sample = self._states.try_recv()
            if sample is None:
                return worked
            self._begin(body_of(sample.message))
            if gated:
                self._mark_cycle()
            worked = True

    def _take_start(self) -> dict[str, Any] | None:
        assert self._pending is not None
        found = None
        while (sample := self._starts.try_recv()) is not None:
            body = body_of(sample.message)
            if body.get("origin") == self._pending.origin and body.get("seq") == self._pending.seq:
                found = body
                break
        return found

    def _begin(self, state: dict[str, Any]) -> None:
        kb = self.knowledge
        t = float(state["t"])
        self.now = t
        self._view.update(state)
        self._eligible = [str(n) for n in state.get("eligible", [])]
        self._approvals = []
        ops = [op for op in state.get("ops", []) if isinstance(op, dict)]
        for op in ops:
            self._apply_op(op, t)
        before = kb.decisions_written
        runtimes = self.planner.runtimes
        for rt in list(runtimes.values()):
            if rt.state == "running":  # resumed mid-action after a restart
                self.executor.run_actions(rt, t)
        analysis = cast(Analyzer, self._view)
        for rt in list(runtimes.values()):
            if rt.state == "awaiting":
                self.executor.check(rt, analysis, t)
        self.bus.publish(
            STATUS_TOPIC,
            {
                "origin": state.get("origin"),
                "seq": state.get("seq"),
                "t": t,
                "eligible": self._eligible,
                "runtimes": {name: _runtime_row(rt) for name, rt in runtimes.items()},
                "approvals": self._approvals,
                "ops": ops,
                "paused": self.paused,
                "run_stopped": self.stopped or self.run_stopped,
            },
        )
        self._pending = _Pending(state.get("origin"), state.get("seq"), t, time.monotonic(), before)

    def _complete(self, start: dict[str, Any] | None) -> None:
        assert self._pending is not None
        pending, kb = self._pending, self.knowledge
        runtimes = self.planner.runtimes
        planned = 0
        started: list[str] = []
        if start is not None:
            for name, st in dict(start.get("states", {})).items():
                rt = runtimes.get(name)
                if rt is not None and not rt.in_flight and isinstance(st, str):
                    rt.state = st  # type: ignore[assignment]
            n = start.get("decisions")
            planned = n if isinstance(n, int) else 0
            for name in start.get("start", []):
                rt = runtimes.get(name)
                if rt is None or self.halted:
                    break
                self.executor.start(rt, pending.t)
                started.append(rt.name)
        self.bus.publish(
            DONE_TOPIC,
            {
                "origin": pending.origin,
                "seq": pending.seq,
                "t": pending.t,
                "started": started,
                "decisions": kb.decisions_written - pending.before + planned,
            },
        )
        self._pending = None
        self.cycles += 1

    # -- what the manager does between and around the parts
    def _apply_op(self, op: Mapping[str, Any], t: float) -> None:
        kb = self.knowledge
        kind = op.get("op")
        caller = str(op.get("caller", "unknown"))
        if kind == "pause":
            self.paused = True
            kb.record_decision(t, "paused", None, caller=caller)
        elif kind == "resume":
            self.paused = False
            self.stopped = False
            self.run_stopped = False
            kb.record_decision(t, "resumed_adaptation", None, caller=caller)
        elif kind == "approve":
            tactic = str(op.get("tactic"))
            result = self.planner.approve(tactic, bool(op.get("approve", True)), caller, t)
            if result in ("approved", "rejected"):
                self._approvals.append([tactic, self.planner.runtimes[tactic].state])
            else:
                kb.record_decision(t, "operator_refused", tactic, caller=caller, reason=result)
        elif kind == "node_lost":
            agents = op.get("agents", [])
            kb.record_decision(
                t, "liveliness_lost", None, node=str(op.get("node")), agents=list(agents)
            )
        elif kind == "run_stop":
            self._do_run_stop(t, caller=caller, reason=str(op.get("reason", "operator")))
        else:
            kb.record_decision(
                t, "operator_refused", None, caller=caller, reason=f"unknown operation {kind!r}"
            )

    def _escalate(self, failed: TacticRuntime, now: float) -> None:
        kb, planner = self.knowledge, self.planner
        if self.halted:
            return
        eligible = [
            planner.runtimes[n]
            for n in self._eligible
            if n != failed.name and n in planner.runtimes
        ]
        eligible.sort(key=lambda rt: -rt.tactic.priority)
        for rt in eligible:
            if rt.state == "idle" and not any(
                o.in_flight and planner.conflicts(rt.name, o.name)
                for o in planner.runtimes.values()
            ):
                kb.record_decision(now, "escalated", failed.name, to=rt.name)
                self.executor.start(rt, now, reason=f"escalation from {failed.name}")
                return
        fs = planner.runtimes.get(self.config.failsafe or "")
        if fs is not None and fs.name != failed.name and not fs.in_flight:
            kb.record_decision(now, "escalated", failed.name, to=fs.name)
            self.executor.start(fs, now, reason=f"escalation from {failed.name} (fail-safe)")
            return
        if self.config.escalate_to_run_stop:
            kb.record_decision(now, "escalated", failed.name, to="run-stop")
            self._do_run_stop(
                now, caller=f"escalation:{failed.name}", reason="postcondition failed"
            )
        else:
            kb.record_decision(now, "escalation_exhausted", failed.name)

    def _do_run_stop(self, t: float, *, caller: str, reason: str) -> None:
        self.stopped = True
        self.paused = True
        service = self.config.run_stop.service
        outcome = None
        if service is not None:
            outcome = self.actuator.request(service, self.config.run_stop.payload, 2.0)
        self.knowledge.record_decision(
            t,
            "run_stop",
            None,
            caller=caller,
            reason=reason,
            service=service,
            ok=None if outcome is None else outcome.ok,
        )
        try:
            self.bus.publish(
                RUN_STOP_TOPIC,
                RunStop(reason=f"{reason} (asked by {caller})", caller=f"utu:{self.config.name}"),
            )
        except AnunnakiError as exc:  # pragma: no cover - closed bus at shutdown
            log.warning("could not announce run-stop: %s", exc)

    def _spin_once(self) -> float:
        self._advance(gated=True)
        if self._pending is not None and self._expects_plan():
            return max(0.0, self.timeout - (time.monotonic() - self._pending.since))
        gate = self._gate()
        return gate if gate > 0 and self._states.pending else 0.5


# -- knowledge ---------------------------------------------------------------------------------
def _decision_dict(d: Decision) -> dict[str, Any]:
    return {"id": d.id, "t": d.t, "kind": d.kind, "tactic": d.tactic, "data": d.data}


class DecisionTail:
    """The decisions written to a knowledge base since the last read, by any writer.

    Args:
        knowledge: The knowledge base (another process may be writing it).
        from_start: Read the decisions already there too (default: only new ones).

    """

    def __init__(self, knowledge: Knowledge, *, from_start: bool = False) -> None:
        self.knowledge = knowledge
        last = [] if from_start else knowledge.decisions(limit=1)
        self.last_id = last[-1].id if last else 0
        self._last_t: float | None = last[-1].t if last else None

    def read(self) -> list[Decision]:
        """Return the decisions written since the last call, in order."""
        rows = [d for d in self.knowledge.decisions(since=self._last_t) if d.id > self.last_id]
        if rows:
            self.last_id = rows[-1].id
            self._last_t = min(d.t for d in rows) if self._last_t is None else self._last_t
            self._last_t = max(self._last_t, min(d.t for d in rows))
        return rows


class KnowledgeNode(UtuNode):
    """``/utu_knowledge``: the dedicated node for the knowledge base (guidelines N8, P3).

    At bring-up it records the goal model, binding and tactics texts in force (if the
    knowledge base has none yet). It answers ``/utu/knowledge/query``
    (``{what: decisions|queue|state, limit}``, the same answers as the composed manager)
    and publishes new decisions on ``/utu/knowledge/decisions`` at its rate
    (``{decisions: [{id, t, kind, tactic, data}]}``), for dashboards and logs.
    """

    name = "knowledge"

    def _bring_up(self) -> None:
        kb, config = self.knowledge, self.config
        kb.set_meta(
            "settings",
            {
                "dwell": config.dwell,
                "warmup": config.warmup,
                "failsafe": config.failsafe,
                "escalate_to_run_stop": config.escalate_to_run_stop,
                "run_stop_service": config.run_stop.service,
            },
        )
        if not kb.models_at():
            for kind, (path, text) in self.parts.sources.items():
                kb.record_model(0.0, kind, path, text)
        self.tail = DecisionTail(kb)
        self._state: dict[str, Any] = {}
        self._queue: list[Any] = []
        self._flags = {"paused": False, "run_stopped": False}
        self._declare(self.bus.subscribe(STATE_TOPIC, self._on_state, queue=64))
        self._declare(self.bus.subscribe(START_TOPIC, self._on_start, queue=64))
        self._declare(self.bus.subscribe(STATUS_TOPIC, self._on_status, queue=64))
        self._declare(self.bus.service(QUERY_SERVICE, self._query))

    def _on_state(self, sample: Sample) -> None:
        body = body_of(sample.message)
        with self._lock:
            self._state = {k: body.get(k) for k in ("t", "root", "nodes", "violated", "tactics")}

    def _on_start(self, sample: Sample) -> None:
        queue = body_of(sample.message).get("queue")
        if isinstance(queue, list):
            with self._lock:
                self._queue = queue

    def _on_status(self, sample: Sample) -> None:
        body = body_of(sample.message)
        with self._lock:
            self._flags = {
                "paused": bool(body.get("paused")),
                "run_stopped": bool(body.get("run_stopped")),
            }
        self.run_stopped = self._flags["run_stopped"]  # as the execute node has it

    def _query(self, message: Any) -> dict[str, Any]:
        body = body_of(message)
        what = body.get("what", "state")
        limit = body.get("limit", 100)
        if not isinstance(limit, int) or limit < 1:
            limit = 100
        if what == "decisions":
            rows = self.knowledge.decisions(limit=min(limit, 10_000))
            return {
                "ok": True,
                "decisions": [
                    {"t": d.t, "kind": d.kind, "tactic": d.tactic, "data": d.data} for d in rows
                ],
            }
        with self._lock:
            if what == "queue":
                return {"ok": True, "queue": list(self._queue)}
            if what == "state":
                state = self._state or {
                    "t": None,
                    "root": self.parts.model.root,
                    "nodes": {},
                    "violated": [],
                    "tactics": [],
                }
                return {"ok": True, **state, "queue": list(self._queue), **self._flags}
        return {"ok": False, "error": f"unknown query {what!r}; ask decisions, queue or state"}

    def step(self) -> bool:
        """Publish the decisions written since the last step; returns whether there were any."""
        rows = self.tail.read()
        if rows:
            self.bus.publish(DECISIONS_TOPIC, {"decisions": [_decision_dict(d) for d in rows]})
        self.cycles += 1
        return bool(rows)

    def _spin_once(self) -> float:
        gate = self._gate()
        if gate > 0:
            return gate
        self.step()
        self._mark_cycle()
        return 1.0 / self.rate  # wall seconds: it only tails the database


# -- composition -------------------------------------------------------------------------------
_NODE_CLASSES: dict[str, type[UtuNode]] = {
    "monitor": MonitorNode,
    "analyze": AnalyzeNode,
    "plan": PlanNode,
    "execute": ExecuteNode,
    "knowledge": KnowledgeNode,
}


def build_node(name: str, utu: UtuConfig | UtuParts, **kwargs: Any) -> UtuNode:
    """Bring up the node called ``name`` with the keyword arguments of :class:`UtuNode`.

    The names are ``monitor``, ``analyze``, ``plan``, ``execute`` and ``knowledge``.

    Raises:
        NodeConfigError: An unknown name (the message lists the valid ones).

    """
    cls = _NODE_CLASSES.get(name)
    if cls is None:
        raise NodeConfigError(f"unknown Utu node {name!r}; the nodes are: {', '.join(NODE_NAMES)}")
    return cls(utu, **kwargs)


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


class ComposedUtu:
    """All five services in one process: the :class:`AutonomicManager`, seen as five nodes.

    The manager composes monitor, analyze, plan, execute and knowledge with no bus hops in
    between (guideline C12: one process when the traffic between nodes is high). On the bus
    it looks like the separate nodes: a token ``/utu_<name>`` and a readiness service
    ``/utu/<name>/ready`` for each, the operator services and ``/utu/knowledge/query`` of
    the manager, and new decisions on ``/utu/knowledge/decisions``.

    Args:
        utu: The configuration or its loaded parts.
        bus: The bus.
        knowledge: The knowledge base (default: the configuration's file or memory);
            closed with the manager.
        clock: The clock (default as the configuration says).
        rates: Per-node rates; the manager steps at the highest, decisions are published
            at the knowledge node's.
        actuator: How actions reach the managed system (default: over the bus).

    """

    def __init__(
        self,
        utu: UtuConfig | UtuParts,
        *,
        bus: Bus,
        knowledge: Knowledge | None = None,
        clock: Clock | None = None,
        rates: Mapping[str, float] | None = None,
        actuator: Actuator | None = None,
    ) -> None:
        self.parts = utu if isinstance(utu, UtuParts) else load_parts(utu)
        config = self.parts.config
        self.bus = bus
        rates = dict(rates or {})
        self.rate = max(rates.values(), default=config.rate)
        self._kb_period = 1.0 / rates.get("knowledge", config.rate)
        self.manager = AutonomicManager.from_config(
            config, bus=bus, clock=clock, knowledge=knowledge, actuator=actuator
        )
        self.knowledge = self.manager.knowledge
        self.run_stopped = False
        self.tail = DecisionTail(self.knowledge)
        self._next_publish = 0.0
        self._declared: list[_Closable] = []
        self._closed = False
        try:
            for name in NODE_NAMES:
                self._declared.append(bus.liveliness_token(node_token(name)))
            for name in NODE_NAMES:
                self._declared.append(bus.service(ready_service(name), self._ready_handler(name)))
        except BaseException:
            self.close()
            raise

    def _ready_handler(self, name: str) -> Callable[[Any], dict[str, Any]]:
        return lambda message: self._ready(name)

    def _ready(self, name: str) -> dict[str, Any]:
        m = self.manager
        return {
            "ready": not self._closed,
            "node": node_token(name),
            "utu": m.name,
            "pid": os.getpid(),
            "rate": self.rate,
            "composed": True,
            "run_stopped": m.run_stopped,
        }

    def _on_step(self, manager: AutonomicManager) -> None:
        now = time.monotonic()
        if now < self._next_publish:
            return
        self._next_publish = now + self._kb_period
        rows = self.tail.read()
        if rows:
            self.bus.publish(DECISIONS_TOPIC, {"decisions": [_decision_dict(d) for d in rows]})

    def wake(self) -> None:
        """Wake ``spin`` (e.g. after setting its stop event)."""
        self.manager._wake.set()

    def input_queues(self) -> list[Subscriber]:
        """The manager's bounded input queues (empty: every input was taken)."""
        return list(self.manager._pull.values())

    def spin(self, stop: threading.Event | None = None) -> None:
        """Run the manager live until ``stop`` is set."""
        self.manager.spin(stop, rate=self.rate, on_step=self._on_step)

    def close(self) -> None:
        """Withdraw the tokens and services, close the manager (and its knowledge base)."""
        if self._closed:
            return
        self._closed = True
        for obj in reversed(self._declared):
            try:
                obj.close()
            except Exception as exc:  # best effort at shutdown
                log.debug("closing %r: %r", obj, exc)
        self._declared.clear()
        if hasattr(self, "manager"):
            self.manager.close()
