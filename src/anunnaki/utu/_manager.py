"""The autonomic manager: Monitor → Analyze → Plan → Execute over Knowledge (paper Fig. 8).

:class:`AutonomicManager` composes the parts and owns the step. ``step(now)`` runs one
deterministic cycle — tests, simulation and replay drive it — and ``spin()`` runs it live:
event-driven (a message is processed as soon as it arrives) with time-driven checks
(staleness, deadlines, dwell) at least ``rate`` times a second.

Operators and other nodes reach the manager through services on the bus (all recorded in
the decision log with their caller):

* ``/utu/run_stop`` — halt adaptation and command the managed system to stop (guideline S4);
  the same happens when any node publishes a ``RunStop`` on the ``/utu/run_stop`` topic;
* ``/utu/pause``, ``/utu/resume`` — suspend and resume adaptation (resume also clears a
  run-stop);
* ``/utu/approve`` — ``{tactic, approve: true|false, caller}`` for tactics marked
  ``requires_approval``;
* ``/utu/ready`` — readiness (guideline C9), and ``/utu/knowledge/query`` — read the
  knowledge base (decisions, verdicts, state, queue).
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from anunnaki import topics
from anunnaki.bus import body_of
from anunnaki.clock import Clock, SimClock, WallClock
from anunnaki.errors import AnunnakiError, ModelFileError
from anunnaki.goals import GoalModel, parse_binding, parse_goal_model
from anunnaki.tactics import NotifyAction, TacticSet, parse_tactics_xml, parse_tactics_yaml
from anunnaki.utu._config import UtuConfig
from anunnaki.utu._knowledge import Knowledge
from anunnaki.utu._mape import (
    ActionOutcome,
    Actuator,
    Analyzer,
    Executor,
    Monitor,
    Planner,
    TacticRuntime,
)

__all__ = ["AutonomicManager", "BusActuator", "RecordingActuator", "load_tactics_text"]

log = logging.getLogger("anunnaki.utu")

TICK = "__tick__"
OPERATOR = "__operator__"


def load_tactics_text(text: str, path: str | None) -> TacticSet:
    """Parse a tactics file's text, XML or YAML by its look."""
    source = path or "<tactics>"
    if text.lstrip("\ufeff \t\r\n").startswith("<"):
        return parse_tactics_xml(text, source=source)
    return parse_tactics_yaml(text, source=source)


class RecordingActuator:
    """An actuator that performs nothing and records what it was asked (tests, replay)."""

    def __init__(self, replies: Mapping[str, Mapping[str, Any]] | None = None) -> None:
        self.calls: list[tuple[str, str, dict[str, Any]]] = []
        self.replies = dict(replies or {})

    def publish(self, topic: str, payload: Mapping[str, Any]) -> ActionOutcome:
        """Record a publication."""
        self.calls.append(("publish", topic, dict(payload)))
        return ActionOutcome(True, "published")

    def request(self, service: str, payload: Mapping[str, Any], timeout: float) -> ActionOutcome:
        """Record a request; reply with the configured reply or ``{}``."""
        self.calls.append(("request", service, dict(payload)))
        return ActionOutcome(True, "replied", dict(self.replies.get(service, {})))

    def notify(self, action: NotifyAction, tactic: str, now: float) -> ActionOutcome:
        """Record a notification."""
        self.calls.append(("notify", action.channel, {"to": action.to, "subject": action.subject}))
        return ActionOutcome(True, "recorded")


class BusActuator:
    """Actions over the bus: publish on topics, request services, notify through a Notifier."""

    def __init__(
        self,
        bus: Any,
        notifier: Any | None = None,
        *,
        on_notified: Callable[[str, Any], None] | None = None,
    ) -> None:
        self.bus = bus
        self.notifier = notifier
        self.on_notified = on_notified

    def publish(self, topic: str, payload: Mapping[str, Any]) -> ActionOutcome:
        """Publish ``payload`` as a Generic message on ``topic``."""
        self.bus.publish(topic, dict(payload))
        return ActionOutcome(True, f"published on {topic}")

    def request(self, service: str, payload: Mapping[str, Any], timeout: float) -> ActionOutcome:
        """Request ``service``; a timeout or an error reply is a failed action."""
        try:
            reply = self.bus.request(service, dict(payload), timeout=timeout)
        except AnunnakiError as exc:
            return ActionOutcome(False, f"{type(exc).__name__}: {exc}")
        body = body_of(reply)  # a Generic's object, or a ServiceReply's {ok, error, body}
        if body.get("ok") is False:
            return ActionOutcome(False, str(body.get("error") or "refused"), body)
        inner = body.get("body")
        if isinstance(inner, dict) and "ok" in body:
            body = inner
        return ActionOutcome(True, f"{service} replied", body)

    def notify(self, action: NotifyAction, tactic: str, now: float) -> ActionOutcome:
        """Send through the notifier in the background (the loop never waits on SMTP)."""
        if self.notifier is None:
            log.info(
                "notify (%s to %s): %s — %s",
                action.channel,
                action.to,
                action.subject,
                action.message,
            )
            return ActionOutcome(True, "logged (no notifier configured)")
        from anunnaki.utu._notify import Notification

        note = Notification(
            channel=action.channel,
            to=action.to or "",
            subject=action.subject,
            message=action.message,
            tactic=tactic,
            t=now,
            details={},
        )
        callback = self.on_notified

        def done(result: Any) -> None:
            if callback is not None:
                callback(tactic, result)

        self.notifier.send_in_background(note, done)
        return ActionOutcome(True, f"{action.channel} notification queued")


class AutonomicManager:
    """Utu: the MAPE-K loop over a goal model and tactics.

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
    ) -> None:
        self.name = name
        self.model = model
        self.tactics = tactics
        self.knowledge = knowledge or Knowledge()
        self.bus = bus
        self.clock: Clock = clock or WallClock()
        self.actuator: Actuator = actuator or (
            BusActuator(bus) if bus is not None else RecordingActuator()
        )
        self.failsafe = failsafe
        self.escalate_to_run_stop = escalate_to_run_stop
        self.run_stop_service = run_stop_service
        self.run_stop_payload = dict(run_stop_payload or {"reason": "run-stop"})
        self.publish_state = publish_state and bus is not None
        self.paused = False
        self.run_stopped = False
        self.now = 0.0
        self.warmup = warmup
        self._started_at: float | None = None
        self._stepped = False
        # (topic, message, arrival time or None for "now"): a step takes inputs at their own
        # times, so a burst taken by one step keeps its spacing (rates, temporal goals).
        self._inputs: deque[tuple[str, dict[str, Any], float | None]] = deque()
        self._ops: deque[dict[str, Any]] = deque()
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._closed = False
        self._eligible: list[str] = []
        self.monitor = Monitor(model, self.knowledge)
        self.analyzer = Analyzer(model, tactics, self.knowledge)
        self.planner = Planner(tactics, self.knowledge, dwell=dwell)
        self.executor = Executor(self.actuator, self.knowledge, on_failure=self._escalate)
        self._sources = dict(sources or {})
        self._declared: list[Any] = []
        self._pull: dict[str, Any] = {}
        self._queue_bound = queue
        if isinstance(self.actuator, BusActuator) and self.actuator.on_notified is None:
            self.actuator.on_notified = self._notified
        self.knowledge.set_meta(
            "settings",
            {
                "dwell": dwell,
                "warmup": warmup,
                "failsafe": failsafe,
                "escalate_to_run_stop": escalate_to_run_stop,
                "run_stop_service": run_stop_service,
            },
        )
        self._resume_after_restart()
        if bus is not None:
            self._connect(bus, queue)

    # -- construction ---------------------------------------------------------------------
    @classmethod
    def from_config(
        cls,
        config: UtuConfig,
        *,
        bus: Any | None = None,
        actuator: Actuator | None = None,
        clock: Clock | None = None,
        knowledge: Knowledge | None = None,
    ) -> AutonomicManager:
        """Build a manager from a :class:`UtuConfig` (files loaded and checked)."""
        sources = _read_sources(config.goal_model, config.binding, config.tactics)
        model = _model_from_sources(sources)
        tactics = _tactics_from_sources(sources)
        if clock is None:
            clock = SimClock() if config.clock == "sim" else WallClock()
        if actuator is None and bus is not None:
            notifier = None
            if config.notify:
                from anunnaki.utu._notify import Notifier, NotifyConfig

                notifier = Notifier(NotifyConfig.model_validate(config.notify))
            actuator = BusActuator(bus, notifier)
        manager = cls(
            model,
            tactics,
            knowledge=knowledge or Knowledge(config.knowledge),
            bus=bus,
            actuator=actuator,
            clock=clock,
            dwell=config.dwell,
            warmup=config.warmup,
            failsafe=config.failsafe,
            escalate_to_run_stop=config.escalate_to_run_stop,
            run_stop_service=config.run_stop.service,
            run_stop_payload=config.run_stop.payload,
            publish_state=config.publish_state,
            queue=config.queue,
            sources=sources,
            name=config.name,
        )
        if isinstance(clock, SimClock) and bus is not None:

            def on_clock(sample: Any) -> None:
                t = getattr(sample.message, "time", None)
                if isinstance(t, int | float):
                    clock.update(float(t))
                    manager._wake.set()

            manager._declared.append(bus.subscribe(config.clock_topic, on_clock, queue=4))
        return manager

    def _resume_after_restart(self) -> None:
        if not self._sources:
            self._sources = {}
        known = self.knowledge.models_at()
        if not known and self._sources:
            for kind, (path, text) in self._sources.items():
                self.knowledge.record_model(self.now, kind, path, text)
        rows = self.knowledge.tactics()
        if rows:
            resumed = self.planner.restore(rows)
            last = self.knowledge.decisions(limit=1)
            if last:
                self.now = last[-1].t
            for rt in resumed:
                self.knowledge.record_decision(
                    self.now,
                    "resumed",
                    rt.name,
                    state=rt.state,
                    deadline=rt.deadline,
                    next_action=rt.next_action,
                )

    def _connect(self, bus: Any, queue: int) -> None:
        self._queue_bound = queue
        for topic in self.monitor.topics:
            self._subscribe_topic(topic)
        self._declared.append(bus.subscribe(topics.RUN_STOP, self._on_run_stop_topic, queue=16))
        if any(a.node for a in self.model.agents.values()):
            self._declared.append(bus.watch_liveliness(self._on_liveliness))
        services: dict[str, Callable[[Any], Any]] = {
            topics.RUN_STOP: lambda m: self._op_service("run_stop", m),
            topics.PAUSE: lambda m: self._op_service("pause", m),
            topics.RESUME: lambda m: self._op_service("resume", m),
            topics.APPROVE: lambda m: self._op_service("approve", m),
            topics.RELOAD: lambda m: self._op_service("reload", m),
            topics.READY: lambda m: {"ready": True, "node": self.name},
            topics.QUERY: self._query,
        }
        for name, handler in services.items():
            self._declared.append(bus.service(name, handler))

    def _subscribe_topic(self, topic: str) -> None:
        # A pull subscriber holds the inputs (bounded: a flood on one topic cannot starve the
        # others, guideline S1) and ``step`` drains it, so a step sees exactly what arrived
        # before it; its doorbell wakes ``spin`` the moment a message is queued.
        assert self.bus is not None
        self._pull[topic] = self.bus.subscribe(
            topic, queue=self._queue_bound, on_ready=self._wake.set
        )
        self._declared.append(self._pull[topic])

    # -- inputs -----------------------------------------------------------------------------

    def _drain(self) -> None:
        for topic, sub in self._pull.items():
            while True:
                sample = sub.try_recv()
                if sample is None:
                    break
                # The sender's stamp, on the wall clock only (a sim clock is another
                # timebase); step() clamps it into (previous step, this step].
                t_in = sample.sent_at if isinstance(self.clock, WallClock) else None
                self._inputs.append((topic, body_of(sample.message), t_in))

    def _on_run_stop_topic(self, sample: Any) -> None:
        body = body_of(sample.message)
        caller = str(body.get("caller") or sample.sender)
        if caller.startswith(f"utu:{self.name}"):
            return  # our own announcement
        self._enqueue_op(
            {
                "op": "run_stop",
                "caller": caller,
                "reason": str(body.get("reason", "run-stop topic")),
            }
        )

    def _notified(self, tactic: str, result: Any) -> None:
        # Called from the notifier's worker thread; Knowledge is thread-safe. Delivery
        # results arrive asynchronously, so replay does not compare them.
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

    def _on_liveliness(self, node: str, alive: bool) -> None:
        if not alive:
            self._enqueue_op({"op": "node_lost", "node": node, "caller": "liveliness"})

    def feed(self, topic: str, msg: Mapping[str, Any], *, t: float | None = None) -> None:
        """Queue one input message (what the bus subscription does); processed by ``step``.

        ``t`` is when it arrived (default: the time of the step that takes it); a step takes
        each input at its own time, clamped into the step's interval.
        """
        with self._lock:
            self._inputs.append((topic, dict(msg), None if t is None else float(t)))
        if not self._wake.is_set():
            self._wake.set()

    def _enqueue_op(self, op: dict[str, Any]) -> None:
        with self._lock:
            self._ops.append(op)
        self._wake.set()

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
        if op == "reload":
            files = {k: body.get(k) for k in ("goal_model", "binding", "tactics")}
            if not any(isinstance(v, str) for v in files.values()):
                return {"ok": False, "error": "give goal_model, binding and/or tactics paths"}
            entry.update({k: v for k, v in files.items() if isinstance(v, str)})
        self._enqueue_op(entry)
        return {"ok": True, "queued": op, "caller": caller}

    def pause(self, caller: str = "api") -> None:
        """Suspend adaptation (applied at the next step)."""
        self._enqueue_op({"op": "pause", "caller": caller})

    def resume(self, caller: str = "api") -> None:
        """Resume adaptation, clearing a run-stop (applied at the next step)."""
        self._enqueue_op({"op": "resume", "caller": caller})

    def approve(self, tactic: str, *, approve: bool = True, caller: str = "api") -> None:
        """Approve (or reject) a pending tactic (applied at the next step)."""
        self._enqueue_op({"op": "approve", "caller": caller, "tactic": tactic, "approve": approve})

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
        self._enqueue_op(op)

    def run_stop(self, *, caller: str = "api", reason: str = "operator") -> None:
        """Halt adaptation and stop the managed system (applied at the next step)."""
        self._enqueue_op({"op": "run_stop", "caller": caller, "reason": reason})

    # -- the step -----------------------------------------------------------------------------
    def step(self, now: float | None = None) -> None:
        """Run one deterministic cycle at time ``now`` (default: the clock's).

        Every queued input and operator call is taken in arrival order, the passing of time
        is applied, the goal model re-evaluated (incrementally), the tactics selected,
        queued, started and checked.
        """
        with self._lock:
            self._drain()
            inputs = list(self._inputs)
            self._inputs.clear()
            ops = list(self._ops)
            self._ops.clear()
        self._wake.clear()
        # The clock is read after draining, so no input taken here arrived after ``t``.
        t = self.clock.now() if now is None else float(now)
        t = max(t, self.now)
        previous, self.now = self.now, t
        a = self.analyzer
        if self._started_at is None:
            self._started_at = t
        a.warming_up = t - self._started_at < self.warmup
        for topic, msg, t_in in inputs:
            ti = t if t_in is None else min(max(t_in, previous), t)
            if self.monitor.take(topic, msg, ti):
                a.observe(topic, msg, ti)
        ticked = a.tick(t)
        changed = a.record_changes(t)
        for op in ops:
            self.knowledge.record_input(t, OPERATOR, op)
            self._apply_op(op, t)
        decisions_before = self.knowledge.decisions_written
        self._plan_and_execute(t)
        first = not self._stepped
        self._stepped = True
        decided = self.knowledge.decisions_written != decisions_before
        if first or inputs or ticked or changed or ops or decided:
            # Mark the end of this step, so a replay steps at the same instants.
            self.knowledge.record_input(t, TICK, {})
        # Goals, the queue (a decision) or the flags (an operator call) changed: tell displays.
        if (changed or ops or decided) and self.publish_state:
            self._publish_state(t)

    def _plan_and_execute(self, t: float) -> None:
        a = self.analyzer
        for rt in list(self.planner.runtimes.values()):
            if rt.state == "running":  # resumed mid-action after a restart
                self.executor.run_actions(rt, t)
        for rt in list(self.planner.runtimes.values()):
            if rt.state == "awaiting":
                self.executor.check(rt, a, t)
        if self.paused or self.run_stopped:
            return
        eligible = a.eligible()
        self._eligible = eligible
        for rt in self.planner.update(eligible, t):
            if self.paused or self.run_stopped:
                break
            self.executor.start(rt, t)

    def _escalate(self, failed: TacticRuntime, now: float) -> None:
        if self.paused or self.run_stopped:
            return
        eligible = [
            self.planner.runtimes[n]
            for n in self.analyzer.eligible()
            if n != failed.name and n in self.planner.runtimes
        ]
        eligible.sort(key=lambda rt: -rt.tactic.priority)
        for rt in eligible:
            if rt.state == "idle" and not any(
                o.in_flight and self.planner.conflicts(rt.name, o.name)
                for o in self.planner.runtimes.values()
            ):
                self.knowledge.record_decision(now, "escalated", failed.name, to=rt.name)
                self.executor.start(rt, now, reason=f"escalation from {failed.name}")
                return
        fs = self.planner.runtimes.get(self.failsafe or "")
        if fs is not None and fs.name != failed.name and not fs.in_flight:
            self.knowledge.record_decision(now, "escalated", failed.name, to=fs.name)
            self.executor.start(fs, now, reason=f"escalation from {failed.name} (fail-safe)")
            return
        if self.escalate_to_run_stop:
            self.knowledge.record_decision(now, "escalated", failed.name, to="run-stop")
            self._do_run_stop(
                now, caller=f"escalation:{failed.name}", reason="postcondition failed"
            )
        else:
            self.knowledge.record_decision(now, "escalation_exhausted", failed.name)

    def _apply_op(self, op: Mapping[str, Any], t: float) -> None:
        kind = op.get("op")
        caller = str(op.get("caller", "unknown"))
        if kind == "pause":
            self.paused = True
            self.knowledge.record_decision(t, "paused", None, caller=caller)
        elif kind == "resume":
            self.paused = False
            self.run_stopped = False
            self.knowledge.record_decision(t, "resumed_adaptation", None, caller=caller)
        elif kind == "approve":
            result = self.planner.approve(
                str(op.get("tactic")), bool(op.get("approve", True)), caller, t
            )
            if result not in ("approved", "rejected"):
                self.knowledge.record_decision(
                    t, "operator_refused", str(op.get("tactic")), caller=caller, reason=result
                )
        elif kind == "reload":
            self.knowledge.record_decision(t, "reload_requested", None, caller=caller)
            self.reload(
                goal_model=op.get("goal_model"),
                binding=op.get("binding"),
                tactics=op.get("tactics"),
                now=t,
            )
        elif kind == "node_lost":
            node = str(op.get("node"))
            agents = [a for a in self.model.agents.values() if a.node == node]
            for agent in agents:
                for tb in agent.topics:
                    self.analyzer.evaluator.expire(tb.topic, t)
            self.analyzer.record_changes(t)
            # A dead publisher is a known fact, not data still arriving: end the warm-up.
            self._started_at = min(self._started_at or t, t - self.warmup)
            self.analyzer.warming_up = False
            self.knowledge.record_decision(
                t, "liveliness_lost", None, node=node, agents=[a.id for a in agents]
            )
        elif kind == "run_stop":
            self._do_run_stop(t, caller=caller, reason=str(op.get("reason", "operator")))
        else:
            self.knowledge.record_decision(
                t, "operator_refused", None, caller=caller, reason=f"unknown operation {kind!r}"
            )

    def _do_run_stop(self, t: float, *, caller: str, reason: str) -> None:
        self.run_stopped = True
        self.paused = True
        outcome = None
        if self.run_stop_service is not None:
            outcome = self.actuator.request(self.run_stop_service, self.run_stop_payload, 2.0)
        self.knowledge.record_decision(
            t,
            "run_stop",
            None,
            caller=caller,
            reason=reason,
            service=self.run_stop_service,
            ok=None if outcome is None else outcome.ok,
        )
        if self.bus is not None:
            try:
                from anunnaki.bus import RunStop

                self.bus.publish(
                    topics.RUN_STOP,
                    RunStop(reason=f"{reason} (asked by {caller})", caller=f"utu:{self.name}"),
                )
            except AnunnakiError as exc:  # pragma: no cover - closed bus at shutdown
                log.warning("could not announce run-stop: %s", exc)

    def _publish_state(self, t: float) -> None:
        try:
            msg = self.analyzer.state_message(t, self._eligible)
            msg["queue"] = self.planner.queue()
            msg["paused"] = self.paused
            msg["run_stopped"] = self.run_stopped
            self.bus.publish(topics.ANALYSIS, msg)  # type: ignore[union-attr]
        except AnunnakiError as exc:  # pragma: no cover - closed bus at shutdown
            log.warning("could not publish the analysis: %s", exc)

    # -- queries ------------------------------------------------------------------------------
    def _query(self, message: Any) -> dict[str, Any]:
        body = body_of(message)
        what = body.get("what", "state")
        limit = body.get("limit", 100)
        if not isinstance(limit, int) or limit < 1:
            limit = 100
        if what == "decisions":
            return {
                "ok": True,
                "decisions": [
                    {"t": d.t, "kind": d.kind, "tactic": d.tactic, "data": d.data}
                    for d in self.knowledge.decisions(limit=min(limit, 10_000))
                ],
            }
        if what == "queue":
            return {"ok": True, "queue": self.planner.queue()}
        if what == "state":
            return {
                "ok": True,
                **self.analyzer.state_message(self.now, self._eligible),
                "queue": self.planner.queue(),
                "paused": self.paused,
                "run_stopped": self.run_stopped,
            }
        return {"ok": False, "error": f"unknown query {what!r}; ask decisions, queue or state"}

    # -- reload -------------------------------------------------------------------------------
    def reload(
        self,
        *,
        goal_model: str | None = None,
        binding: str | None = None,
        tactics: str | None = None,
        now: float | None = None,
    ) -> list[str]:
        """Swap in new files without stopping; returns the problems (empty = swapped).

        The new set is checked as ``anunnaki check`` does; an invalid one is refused with
        its errors (recorded) and the old one stays active. Tactic state (in flight,
        cooldowns) carries over for tactics that keep their name; the attribute values and
        rates carry over by re-feeding the recent inputs.
        """
        t = self.now if now is None else now
        sources = dict(self._sources)
        try:
            for kind, path in (
                ("goal_model", goal_model),
                ("binding", binding),
                ("tactics", tactics),
            ):
                if path is not None:
                    sources[kind] = (path, Path(path).read_text(encoding="utf-8"))
            if goal_model is None and binding is None:
                model = self.model
            elif "goal_model" not in sources:
                raise ModelFileError(
                    "this manager was built without its goal-model file; give goal_model too"
                )
            else:
                model = _model_from_sources(sources)
            ts = _tactics_from_sources(sources) if "tactics" in sources else self.tactics
            from anunnaki.check import check_tactics

            problems = [f.render() for f in model.findings if f.severity == "error"]
            problems += [
                f.render()
                for f in check_tactics(model, ts, sources.get("tactics", (None,))[0])
                if f.severity == "error"
            ]
            if problems:
                raise ModelFileError(problems[0])
            analyzer = Analyzer(model, ts, self.knowledge)
        except (AnunnakiError, OSError) as exc:
            msg = str(exc)
            self.knowledge.record_decision(t, "reload_refused", None, error=msg)
            log.warning("reload refused, the old model stays active: %s", msg)
            return [msg]
        recent = sorted(
            (
                (arrived, topic, body)
                for topic, stats in self.monitor.topics.items()
                for arrived, body in stats.recent
            ),
            key=lambda x: x[0],
        )
        for arrived, topic, body in recent:
            analyzer.observe(topic, body, arrived)
        analyzer.tick(t)
        analyzer.record_changes(t)
        self.model, self.tactics, self.analyzer = model, ts, analyzer
        self.monitor.set_model(model)
        self.planner.set_tactics(ts)
        self._sources = sources
        for kind, (path, text) in sources.items():
            self.knowledge.record_model(t, kind, path, text)
        self.knowledge.record_decision(
            t, "reloaded", None, files=[p for p in (goal_model, binding, tactics) if p is not None]
        )
        if self.bus is not None:
            for topic in self.monitor.topics:
                if topic not in self._pull:
                    self._subscribe_topic(topic)
        return []

    # -- live ----------------------------------------------------------------------------------
    def spin(
        self,
        stop: threading.Event | None = None,
        *,
        rate: float = 20.0,
        until: float | None = None,
        on_step: Callable[[AutonomicManager], None] | None = None,
    ) -> None:
        """Run live until ``stop`` is set (or the clock passes ``until``).

        Inputs are processed as they arrive; with none, time-driven checks run ``rate``
        times a second.
        """
        stop = stop or threading.Event()
        period = 1.0 / rate
        while not stop.is_set() and not self._closed:
            self.step()
            if on_step is not None:
                on_step(self)
            if until is not None and self.clock.now() >= until:
                break
            if (
                not self._inputs
                and not self._ops
                and not any(sub.pending for sub in self._pull.values())
            ):
                wait = period
                if isinstance(self.clock, SimClock) and self.clock.speed > 0:
                    wait = min(period / max(self.clock.speed, 0.05), 0.5)
                self._wake.wait(wait)

    def input_queues(self) -> list[Any]:
        """The bounded queues of the monitored topics (pull subscribers)."""
        return list(self._pull.values())

    def wake(self) -> None:
        """Wake ``spin()`` now."""
        self._wake.set()

    def snapshot(self) -> dict[str, Any]:
        """What a display needs now: analysis, monitor, queue, flags."""
        state = self.analyzer.state_message(self.now, self._eligible)
        state["monitor"] = self.monitor.snapshot(self.now)
        state["queue"] = self.planner.queue()
        state["paused"] = self.paused
        state["run_stopped"] = self.run_stopped
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
        notifier = getattr(self.actuator, "notifier", None)
        if notifier is not None:
            notifier.close()
        self.knowledge.close()

    def __enter__(self) -> AutonomicManager:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _read_sources(
    goal_model: str, binding: str | None, tactics: str | None
) -> dict[str, tuple[str | None, str]]:
    out: dict[str, tuple[str | None, str]] = {}
    for kind, path in (("goal_model", goal_model), ("binding", binding), ("tactics", tactics)):
        if path is not None:
            try:
                out[kind] = (path, Path(path).read_text(encoding="utf-8"))
            except OSError as exc:
                raise ModelFileError(f"cannot read {kind}: {exc.strerror}", path=path) from exc
    return out


def _model_from_sources(sources: Mapping[str, tuple[str | None, str]]) -> GoalModel:
    b = sources.get("binding")
    binding = parse_binding(b[1], source=b[0] or "<binding>") if b else None
    path, text = sources["goal_model"]
    return parse_goal_model(text, source=path or "<goal-model>", binding=binding)


def _tactics_from_sources(sources: Mapping[str, tuple[str | None, str]]) -> TacticSet:
    t = sources.get("tactics")
    if t is None:
        return TacticSet(tactics=[])
    return load_tactics_text(t[1], t[0])
