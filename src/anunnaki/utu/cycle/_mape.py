"""The MAPE parts of Utu: TopicWatch, Analyzer, Planner, Executor.

Each part is a plain class with its dependencies passed in; the
:class:`~anunnaki.utu.AutonomicManager` composes them with the Knowledge base and owns the
step. None of them reads a clock: every method that needs the time takes ``now``.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any, Literal, cast

from anunnaki.goals import (
    Evaluator,
    Expression,
    GoalModel,
    TopicFreshness,
    compile_expression,
    status_name,
)
from anunnaki.tactics import (
    ExpressionCondition,
    GoalState,
    Notice,
    Publication,
    Send,
    ServiceRequest,
    Tactic,
    TacticAction,
    TacticSet,
)
from anunnaki.utu.cycle._actions import ActionOutcome, ActionRunner, Actuator, Start
from anunnaki.utu.cycle._knowledge import Knowledge, TacticRow

__all__ = [
    "ActionOutcome",
    "Actuator",
    "Analyzer",
    "Executor",
    "Planner",
    "TacticRuntime",
    "TopicWatch",
]

log = logging.getLogger("anunnaki.utu")

TacticState = Literal["idle", "pending", "queued", "running", "awaiting", "rejected"]


# -- TopicWatch ----------------------------------------------------------------------------
class TopicStats(TopicFreshness):
    """What the topic watch knows of one topic: its freshness, last value and recent messages.

    Freshness (last arrival, count, rate, staleness) is :class:`~anunnaki.goals.TopicFreshness`,
    the same definition the goal model's ``rate(A)`` and staleness use.
    """

    def __init__(self, topic: str, agents: list[str], staleness: float, window: int) -> None:
        super().__init__(staleness, window=window)
        self.topic = topic
        self.agents = agents
        self.last_msg: dict[str, Any] | None = None
        self.recent: deque[tuple[float, dict[str, Any]]] = deque(maxlen=64)

    def take(self, t: float, body: dict[str, Any]) -> None:
        """Record one message arriving at ``t``."""
        self.arrive(t)
        self.last_msg = body
        self.recent.append((t, body))


class TopicWatch:
    """What is known of each monitored topic: freshness, last value, rate; inputs recorded.

    The topics come from the model (``GoalModel.topic_routes``), never from code. The analyze
    stage hands it each input of the monitor stage's batch (:class:`MonitorStage` takes what
    arrived and stamps the cycle; this keeps what the inputs say of their topics): each is
    recorded in Knowledge (every input except images) and counted for its topic's freshness.
    """

    def __init__(self, model: GoalModel, knowledge: Knowledge) -> None:
        self.knowledge = knowledge
        self.topics: dict[str, TopicStats] = {}
        self.set_model(model)

    def set_model(self, model: GoalModel) -> None:
        """Watch the topics of ``model`` (keeps what is known of topics that remain)."""
        old = self.topics
        self.topics = {}
        for agent in model.agents.values():
            for tb in agent.topics:
                ts = (
                    self.topics.get(tb.topic)
                    or old.get(tb.topic)
                    or TopicStats(tb.topic, [], agent.staleness, model.spec.rate_window)
                )
                ts.agents = (
                    sorted({*ts.agents, agent.id}) if tb.topic in self.topics else [agent.id]
                )
                ts.staleness = min(ts.staleness, agent.staleness)
                self.topics[tb.topic] = ts

    def take(self, topic: str, msg: Mapping[str, Any], now: float) -> bool:
        """Record one message; returns whether the topic is monitored."""
        ts = self.topics.get(topic)
        if ts is None:
            return False
        body = dict(msg)
        self.knowledge.record_input(now, topic, body)
        ts.take(now, body)
        return True

    def snapshot(self, now: float) -> dict[str, dict[str, Any]]:
        """Per topic: agents, last value, rate and staleness (for displays)."""
        return {
            name: {
                "agents": ts.agents,
                "last": ts.last_msg,
                "last_t": ts.last,
                "count": ts.count,
                "rate": ts.rate(now),
                "stale": ts.stale(now),
            }
            for name, ts in self.topics.items()
        }


# -- Analyzer ------------------------------------------------------------------------------
class Analyzer:
    """Evaluates the goal model on every change and selects the tactics whose preconditions hold."""

    def __init__(self, model: GoalModel, tactics: TacticSet, knowledge: Knowledge) -> None:
        self.knowledge = knowledge
        self.model = model
        self.tactics = tactics
        self._conditions: dict[str, Expression] = {}
        for tactic in tactics.tactics:
            for i, cond in enumerate(tactic.preconditions):
                if isinstance(cond, ExpressionCondition):
                    key = f"{tactic.name}#{i}"
                    self._conditions[key] = compile_expression(
                        cond.expression,
                        path=cond.source.path,
                        line=cond.source.line,
                        element=f"tactics[{tactic.name}].preconditions[{i}]",
                    )
        self.evaluator = Evaluator(model, conditions=self._conditions, on_error=self._node_error)
        self.evaluator.drain_changes()
        self.errors = 0
        # During warm-up (set by the manager) an unknown goal satisfies no precondition:
        # inputs have not all arrived yet, which is not a violation.
        self.warming_up = False

    def _node_error(self, node: str, exc: BaseException) -> None:
        self.errors += 1
        log.warning("evaluating %s raised %r; it is unknown until its inputs change", node, exc)

    def observe(self, topic: str, msg: Mapping[str, Any], now: float) -> None:
        """Feed one message."""
        self.evaluator.observe(topic, msg, now)

    def tick(self, now: float) -> bool:
        """Apply the passing of time; returns whether an input changed."""
        return self.evaluator.tick(now)

    def record_changes(self, now: float) -> list[str]:
        """Record every changed verdict in Knowledge; returns the changed nodes."""
        changed = self.evaluator.drain_changes()
        for node in changed:
            st = self.evaluator.state(node)
            self.knowledge.record_verdict(now, node, st.utility, status_name(st.status))
        return changed

    def holds(self, cond: GoalState | ExpressionCondition, key: str) -> bool:
        """Whether one precondition holds now (unknown counts by the model's policy)."""
        ev = self.evaluator
        if isinstance(cond, GoalState):
            if cond.goal not in ev.index:
                return False
            status = ev.state(cond.goal).status
            if cond.state == "unknown":
                return status is None
            if status is None:
                if self.warming_up:
                    return False
                satisfied = ev.satisfied_for_tactics(cond.goal)
                return satisfied if cond.state == "satisfied" else not satisfied
            return status is (cond.state == "satisfied")
        value = ev.condition(key)
        return value is True or (isinstance(value, int | float) and value >= 1.0)

    def eligible(self) -> list[str]:
        """Names of the tactics whose preconditions all hold now."""
        out = []
        for tactic in self.tactics.tactics:
            if all(
                self.holds(cond, f"{tactic.name}#{i}")
                for i, cond in enumerate(tactic.preconditions)
            ):
                out.append(tactic.name)
        return out

    def postconditions_hold(self, tactic: Tactic) -> bool:
        """Whether every postcondition of ``tactic`` holds now."""
        return all(self.holds(cond, "") for cond in tactic.postconditions)

    def state_message(self, now: float, eligible: Iterable[str]) -> dict[str, Any]:
        """The analysis as a message: utilities, statuses, violations, applicable tactics."""
        ev = self.evaluator
        nodes = {n: [ev.util[i], status_name(ev.stat[i])] for i, n in enumerate(ev.ids)}
        violated = [n for n in self.model.goals if ev.state(n).status is not True]
        return {
            "t": now,
            "root": self.model.root,
            "nodes": nodes,
            "violated": violated,
            "tactics": sorted(eligible),
        }


# -- Planner -------------------------------------------------------------------------------
@dataclass
class TacticRuntime:
    """A tactic's life in the loop."""

    tactic: Tactic
    state: TacticState = "idle"
    eligible_since: float | None = None
    started: float | None = None
    deadline: float | None = None
    next_action: int = 0
    cooldown_until: float | None = None
    attempt: int = 0
    reason: str | None = None
    blocked_logged: str | None = None
    fired: bool = False  # started during the current episode of its preconditions

    @property
    def name(self) -> str:
        """The tactic's name."""
        return self.tactic.name

    @property
    def in_flight(self) -> bool:
        """Whether its actions are running or its postconditions are awaited."""
        return self.state in ("running", "awaiting")

    def row(self) -> TacticRow:
        """The persistent form."""
        state = self.state if self.state in ("running", "awaiting", "pending") else "idle"
        return TacticRow(
            self.name,
            state,
            self.started,
            self.deadline,
            self.next_action,
            self.cooldown_until,
            self.attempt,
            self.reason,
        )


def _endpoints(tactic: Tactic) -> set[str]:
    return {ep.name for ep in tactic.referenced_endpoints()}


class Planner:
    """A priority-sorted queue of selected tactics.

    * a tactic becomes a candidate when its preconditions have held for ``dwell`` seconds
      (hysteresis: a flickering input does not make the system oscillate);
    * it is not queued while it is in flight, in its cooldown, or while a tactic it
      conflicts with is in flight — explicitly (``conflicts``) or because both actuate the
      same endpoint;
    * a tactic marked ``requires_approval`` waits as *pending* until an operator approves it;
    * a tactic fires once per episode of its preconditions holding; with a cooldown it may
      fire again once the cooldown has passed if they still hold (a retry);
    * queued tactics start highest priority first.
    """

    def __init__(self, tactics: TacticSet, knowledge: Knowledge, *, dwell: float = 0.0) -> None:
        self.knowledge = knowledge
        self.dwell = dwell
        self.runtimes: dict[str, TacticRuntime] = {}
        #: A baseline manager in place of the planner's choice (``anunnaki run --manager``):
        #: given the planner, the tactics it would start and the time, what starts instead.
        #: With one, the planner still keeps its queue (a baseline acts at its instants) but
        #: records none of its own choices (``selected``, ``deferred``) and asks no operator
        #: to approve a tactic: the decision log holds what the baseline did.
        self.select: Callable[[Planner, list[TacticRuntime], float], list[TacticRuntime]] | None
        self.select = None
        self.set_tactics(tactics)

    def set_tactics(self, tactics: TacticSet) -> None:
        """Use a new tactic set, keeping the runtime state of tactics that remain."""
        old = self.runtimes
        self.tactics = tactics
        self.runtimes = {}
        for t in tactics.tactics:
            rt = old.get(t.name)
            if rt is not None:
                rt.tactic = t
            self.runtimes[t.name] = rt or TacticRuntime(t)
        self._endpoints = {t.name: _endpoints(t) for t in tactics.tactics}

    def restore(self, rows: Mapping[str, TacticRow]) -> list[TacticRuntime]:
        """Take persisted state after a restart; returns the tactics that were in flight."""
        resumed = []
        for name, row in rows.items():
            rt = self.runtimes.get(name)
            if rt is None:
                continue
            rt.cooldown_until = row.cooldown_until
            rt.attempt = row.attempt
            if row.state in ("running", "awaiting"):
                rt.state = row.state  # type: ignore[assignment]
                rt.started = row.started
                rt.deadline = row.deadline
                rt.next_action = row.next_action
                resumed.append(rt)
            elif row.state == "pending":
                rt.state = "pending"
        return resumed

    def conflicts(self, a: str, b: str) -> bool:
        """Whether two tactics may not be in flight together."""
        if a == b:
            return True
        if self.tactics.in_conflict(a, b):
            return True
        return bool(self._endpoints.get(a, set()) & self._endpoints.get(b, set()))

    def blocked(self, rt: TacticRuntime, now: float) -> str | None:
        """Why ``rt`` cannot start now (cooldown, a conflicting tactic in flight), or ``None``."""
        return self._blocked(rt, now)

    def _blocked(self, rt: TacticRuntime, now: float) -> str | None:
        if rt.cooldown_until is not None and now < rt.cooldown_until:
            return f"cooldown until {rt.cooldown_until:.3f}"
        for other in self.runtimes.values():
            if other.in_flight and self.conflicts(rt.name, other.name):
                return f"conflicts with {other.name}, in flight"
        return None

    def update(self, eligible: Iterable[str], now: float) -> list[TacticRuntime]:
        """Take the tactics whose preconditions hold; return those to start now."""
        eligible_set = set(eligible)
        for name, rt in self.runtimes.items():
            if name not in eligible_set:
                rt.eligible_since = None
                rt.blocked_logged = None
                rt.fired = False
                if rt.state == "pending":
                    rt.state = "idle"
                    self._save(rt)
                    self.knowledge.record_decision(
                        now, "withdrawn", name, reason="preconditions no longer hold"
                    )
                elif rt.state in ("queued", "rejected"):
                    rt.state = "idle"
                continue
            if rt.eligible_since is None:
                rt.eligible_since = now
                if self.select is None:  # a baseline's choice is its own, not this one
                    self.knowledge.record_decision(
                        now, "selected", name, priority=rt.tactic.priority
                    )
            if rt.state != "idle" or now - rt.eligible_since < self.dwell - 1e-12:
                continue
            if rt.fired and rt.tactic.cooldown <= 0:
                continue  # once per episode: it re-arms when its preconditions clear
            if rt.tactic.requires_approval and self.select is not None:
                continue  # a baseline asks no operator: it would not start the tactic
            if rt.tactic.requires_approval:
                rt.state = "pending"
                self._save(rt)
                self.knowledge.record_decision(now, "pending_approval", name)
            else:
                rt.state = "queued"
        start = self._dispatch(now)
        return start if self.select is None else self.select(self, start, now)

    def _dispatch(self, now: float) -> list[TacticRuntime]:
        queue = sorted(
            (rt for rt in self.runtimes.values() if rt.state == "queued"),
            key=lambda rt: (-rt.tactic.priority, self.tactics.tactics.index(rt.tactic)),
        )
        start: list[TacticRuntime] = []
        for rt in queue:
            reason = self._blocked(rt, now) or next(
                (
                    f"conflicts with {s.name}, starting"
                    for s in start
                    if self.conflicts(rt.name, s.name)
                ),
                None,
            )
            if reason is not None:
                if rt.blocked_logged != reason:
                    rt.blocked_logged = reason
                    if self.select is None:  # the planner's queue, not a baseline's
                        self.knowledge.record_decision(now, "deferred", rt.name, reason=reason)
                continue
            start.append(rt)
        return start

    def queue(self, starting: Iterable[str] = ()) -> list[dict[str, Any]]:
        """The priority-sorted queue (queued, pending approval and in flight).

        ``starting``: tactics handed to execute to start now, shown as running.
        """
        rts = [rt for rt in self.runtimes.values() if rt.state != "idle"]
        rts.sort(key=lambda rt: -rt.tactic.priority)
        now_running = set(starting)
        return [
            {
                "tactic": rt.name,
                "priority": rt.tactic.priority,
                "state": "running" if rt.name in now_running else rt.state,
                "deadline": rt.deadline,
            }
            for rt in rts
        ]

    def forget_selection(self) -> None:
        """Start selecting afresh, as a restarted plan part does.

        What selection alone knew goes (when each tactic became eligible, the last
        ``deferred`` reason, whether it fired in this episode, queued or rejected); what
        Knowledge keeps stays: pending approvals, and everything of a tactic in flight.
        """
        for rt in self.runtimes.values():
            rt.eligible_since = None
            rt.blocked_logged = None
            rt.fired = False
            if rt.state in ("queued", "rejected"):
                rt.state = "idle"

    def approve(self, name: str, approve: bool, caller: str, now: float) -> str:
        """An operator approves or rejects a pending tactic; returns what happened."""
        rt = self.runtimes.get(name)
        if rt is None:
            return f"unknown tactic {name!r}"
        if rt.state != "pending":
            return f"tactic {name!r} is not pending approval (it is {rt.state})"
        rt.state = "queued" if approve else "rejected"
        self._save(rt)
        self.knowledge.record_decision(
            now, "approved" if approve else "rejected", name, caller=caller
        )
        return "approved" if approve else "rejected"

    def _save(self, rt: TacticRuntime) -> None:
        self.knowledge.save_tactic(rt.row())


# -- Executor ------------------------------------------------------------------------------
class Executor:
    """Performs a tactic's actions in order, then checks its postconditions by the deadline.

    Before each action its index is persisted (write-ahead), so a manager killed mid-action
    and restarted continues with the *next* action: an action runs at most once.
    """

    def __init__(
        self,
        actuator: Actuator,
        knowledge: Knowledge,
        *,
        on_failure: Callable[[TacticRuntime, float], None],
        runner: ActionRunner | None = None,
        resolve: Callable[[str], str] | None = None,
    ) -> None:
        self.actuator = actuator
        self.knowledge = knowledge
        self.on_failure = on_failure
        self.runner = runner
        self.waiting: dict[str, int] = {}  # tactic -> index of its action in flight
        # A tactic may name a logical endpoint (``set_mode``); the binding maps it to the
        # platform's topic or service (GoalModel.endpoint_name). A ROS name stands for itself.
        self.resolve: Callable[[str], str] = resolve or (lambda name: name)

    def start(self, rt: TacticRuntime, now: float, *, reason: str = "preconditions hold") -> None:
        """Start a tactic: persist, then run its actions."""
        rt.state = "running"
        rt.fired = True
        rt.started = now
        rt.deadline = now + rt.tactic.deadline
        rt.next_action = 0
        rt.attempt += 1
        rt.reason = reason
        self.knowledge.save_tactic(rt.row())
        self.knowledge.record_decision(
            now,
            "started",
            rt.name,
            priority=rt.tactic.priority,
            deadline=rt.deadline,
            reason=reason,
            attempt=rt.attempt,
        )
        self.run_actions(rt, now)

    def run_actions(self, rt: TacticRuntime, now: float) -> None:
        """Run the remaining actions of a running tactic (none while one is in flight).

        A request goes to the :class:`~anunnaki.utu.cycle.ActionRunner` when there is one: the
        tactic stays ``running`` and :meth:`collect` continues it when the outcome is back.
        """
        if rt.name in self.waiting:
            return
        actions = rt.tactic.actions
        while rt.next_action < len(actions):
            i = rt.next_action
            action = actions[i]
            rt.next_action = i + 1
            self.knowledge.save_tactic(rt.row())  # write-ahead: action i is dispatched
            self.knowledge.flush()  # ... and on disk, with what led to it, before it runs
            outcome = self._dispatch(action, rt.name, i, now, rt.attempt)
            if outcome is None:  # in flight: the cycle that finds it back goes on
                self.waiting[rt.name] = i
                return
            if not self._outcome(rt, i, outcome, now):
                return
        if rt.tactic.postconditions:
            rt.state = "awaiting"
            self.knowledge.save_tactic(rt.row())
        else:
            self._finish(rt, now, ok=True, note="no postconditions")

    def collect(self, runtimes: Mapping[str, TacticRuntime], now: float) -> None:
        """Take the actions that came back: record each, continue or fail its tactic."""
        if self.runner is None:
            return
        for done in self.runner.finished(now):
            rt = runtimes.get(done.tactic)
            if rt is None or self.waiting.get(done.tactic) != done.index:
                log.warning("no tactic waits for %s action %d", done.tactic, done.index)
                continue
            del self.waiting[done.tactic]
            if rt.state == "running" and self._outcome(rt, done.index, done.outcome, now):
                self.run_actions(rt, now)

    def _outcome(self, rt: TacticRuntime, i: int, outcome: ActionOutcome, now: float) -> bool:
        """Record action ``i``'s outcome; a failed one fails the tactic (returns False)."""
        action = rt.tactic.actions[i]
        self.knowledge.record_decision(
            now,
            "action",
            rt.name,
            index=i,
            attempt=rt.attempt,
            type=action.type,
            ok=outcome.ok,
            detail=outcome.detail,
            **self._describe(action, rt.name),
        )
        if not outcome.ok:  # refused, timed out or no service: failed, whatever follows
            self._finish(rt, now, ok=False, note="action failed", action=i)
            return False
        return True

    def _describe(self, action: TacticAction, tactic: str) -> dict[str, Any]:
        """What the decision log says of ``action``, as its class says it (resolved names)."""
        try:
            return dict(action.describe(self.resolve))
        except Exception as exc:  # a broken description must not cost the decision
            log.warning("the description of %s's %s action raised %r", tactic, action.type, exc)
            return {}

    def _dispatch(
        self, action: TacticAction, tactic: str, index: int, now: float, attempt: int = 0
    ) -> ActionOutcome | None:
        """Perform ``action``: on the loop, or through the runner for a request."""
        try:
            sent = action.send()
        except Exception as exc:  # an action that cannot say what it sends: failed, never fatal
            log.warning("the %s action of %s raised %r", action.type, tactic, exc)
            return ActionOutcome(False, f"{type(exc).__name__}: {exc}")
        if not isinstance(sent, ServiceRequest) or self.runner is None:
            return self._perform(sent, action, tactic, now)
        service, payload, timeout = self.resolve(sent.service), dict(sent.payload), sent.timeout
        actuator = self.actuator

        def call() -> ActionOutcome:
            return actuator.request(service, payload, timeout)

        start: Start | None = None
        request_start = getattr(actuator, "request_start", None)
        if callable(request_start):

            def start() -> Future[ActionOutcome]:
                return cast("Future[ActionOutcome]", request_start(service, payload, timeout))

        try:
            return self.runner.submit(
                tactic, index, call, timeout, now, attempt=attempt, start=start
            )
        except Exception as exc:  # a runner that cannot start it: failed, never fatal
            log.warning("action of %s could not start: %r", tactic, exc)
            return ActionOutcome(False, f"{type(exc).__name__}: {exc}")

    def _perform(self, sent: Send, action: TacticAction, tactic: str, now: float) -> ActionOutcome:
        """Hand what an action sends to the actuator, on the loop."""
        try:
            if isinstance(sent, ServiceRequest):
                return self.actuator.request(
                    self.resolve(sent.service), dict(sent.payload), sent.timeout
                )
            if isinstance(sent, Publication):
                return self.actuator.publish(self.resolve(sent.topic), dict(sent.payload))
            if isinstance(sent, Notice):
                return self.actuator.notify(sent, tactic, now)
        except Exception as exc:  # an actuator must never kill the loop
            log.warning("action of %s raised %r", tactic, exc)
            return ActionOutcome(False, f"{type(exc).__name__}: {exc}")
        return ActionOutcome(
            False,
            f"the {action.type} action sent {type(sent).__name__}, not a ServiceRequest, "
            "Publication or Notice",
        )

    def check(
        self, rt: TacticRuntime, now: float, *, verified: bool, goals: Mapping[str, str]
    ) -> None:
        """Check an awaiting tactic's postconditions: verified, still waiting, or failed.

        ``verified`` and ``goals`` are the analysis of this instant, as the
        :class:`Analyzer` gave it: whether every postcondition of the tactic holds, and the
        status name of each goal a postcondition names (what a failure records).
        """
        if rt.state != "awaiting":
            return
        if verified:
            self._finish(rt, now, ok=True, note="postconditions verified")
        elif rt.deadline is not None and now >= rt.deadline:
            states = {c.goal: goals[c.goal] for c in rt.tactic.postconditions if c.goal in goals}
            self._finish(rt, now, ok=False, note="deadline passed", goals=states)

    def _finish(self, rt: TacticRuntime, now: float, *, ok: bool, note: str, **data: Any) -> None:
        kind = "postcondition_ok" if ok else "postcondition_failed"
        if not rt.tactic.postconditions:
            kind = "completed"
        if note == "action failed":
            kind = "action_failed"
        rt.state = "idle"
        rt.cooldown_until = now + rt.tactic.cooldown
        rt.deadline = None
        self.knowledge.save_tactic(rt.row())
        self.knowledge.record_decision(now, kind, rt.name, note=note, **data)
        if not ok:
            self.on_failure(rt, now)
