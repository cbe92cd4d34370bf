"""The execute stage: actions, postconditions, escalation, and the operator flags."""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Mapping
from typing import Any, cast

from anunnaki.messages import AnalysisState, CycleDone, ExecuteStatus, PlanStart
from anunnaki.utu.cycle._actions import ActionRunner, Actuator
from anunnaki.utu.cycle._entries import (
    STATUS_OF_NAME,
    build_message,
    last_halt,
    model_from_sources,
    resuming,
    runtime_row,
    sources_of,
    tactics_from_sources,
)
from anunnaki.utu.cycle._knowledge import Knowledge
from anunnaki.utu.cycle._mape import Analyzer, Executor, Planner, TacticRuntime
from anunnaki.utu.cycle._parts import UtuParts

__all__ = [
    "ExecuteStage",
]

log = logging.getLogger("anunnaki.utu")


# -- execute -------------------------------------------------------------------------------------
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
    """What :meth:`Executor.check` reads from an :class:`Analyzer`, from an analysis."""

    def __init__(self) -> None:
        self.post: dict[str, bool] = {}
        self.evaluator = _StatusView()

    def update(self, state: AnalysisState) -> None:
        self.post = dict(state.postconditions or {})
        self.evaluator.index = {
            n: STATUS_OF_NAME.get(s) for n, s in (state.post_goals or {}).items()
        }

    def postconditions_hold(self, tactic: Any) -> bool:
        return self.post.get(tactic.name, False)


class ExecuteStage:
    """Performs tactics and checks their postconditions (the :class:`~anunnaki.utu.Executor`).

    :meth:`begin` applies the cycle's operator calls, runs actions resumed after a restart
    and checks the postconditions of the tactics in flight against the analysis —
    escalating to another applicable tactic, the fail-safe, then a run-stop when one fails;
    :meth:`complete` starts what plan chose.

    Args:
        parts: The loaded configuration.
        knowledge: The knowledge base.
        actuator: How actions reach the managed system.
        on_run_stop: Called after a run-stop was performed (e.g. to announce it).

    """

    def __init__(
        self,
        parts: UtuParts,
        knowledge: Knowledge,
        actuator: Actuator,
        *,
        on_run_stop: Callable[[str, str], None] | None = None,
        runner: ActionRunner | None = None,
    ) -> None:
        self.parts = parts
        self.knowledge = knowledge
        self.actuator = actuator
        self.on_run_stop = on_run_stop
        # The planner here holds the tactic runtimes (and knows the conflicts); plan selects.
        self.planner = Planner(parts.tactics, knowledge, dwell=parts.config.dwell)
        self.executor = Executor(
            actuator,
            knowledge,
            on_failure=self._escalate,
            resolve=self._endpoint_name,
            runner=runner,
        )
        self.paused = False
        self.stopped = False  # a run-stop performed here
        self.heard_run_stop = False  # a run-stop heard on its topic, not yet performed
        self.now = 0.0
        self.eligible: list[str] = []
        self._view = _AnalysisView()
        self._approvals: list[list[str]] = []
        self._cascade_t: float | None = None  # the instant of the escalations in _cascade
        self._cascade: set[str] = set()  # tactics that failed at that instant
        self._state: AnalysisState | None = None
        self._before = 0
        if resuming(knowledge):
            self.now = knowledge.last_t()
            self.paused, self.stopped = last_halt(knowledge)
        rows = knowledge.tactics()
        if rows:
            resumed = self.planner.restore(rows)
            for rt in resumed:
                knowledge.record_decision(
                    self.now,
                    "resumed",
                    rt.name,
                    state=rt.state,
                    deadline=rt.deadline,
                    next_action=rt.next_action,
                )

    @property
    def halted(self) -> bool:
        """Whether adaptation is halted (paused, run-stopped, or a run-stop was heard)."""
        return self.paused or self.stopped or self.heard_run_stop

    @property
    def run_stopped(self) -> bool:
        """Whether a run-stop is in force (performed or heard)."""
        return self.stopped or self.heard_run_stop

    def begin(self, state: AnalysisState) -> ExecuteStatus:
        """Take one analysis: operator calls, resumed actions, postcondition checks."""
        kb = self.knowledge
        t = float(state.t or 0.0)
        self.now = t
        self._state = state
        self._view.update(state)
        self.eligible = list(state.eligible or [])
        self._approvals = []
        ops = [dict(op) for op in state.ops or []]
        for op in ops:
            self._apply_op(op, t)
        self._before = kb.decisions_written
        runtimes = self.planner.runtimes
        self.executor.collect(runtimes, t)  # actions that came back since the last cycle
        for rt in list(runtimes.values()):
            if rt.state == "running":  # resumed mid-action after a restart
                self.executor.run_actions(rt, t)
        analysis = cast(Analyzer, self._view)
        for rt in list(runtimes.values()):
            if rt.state == "awaiting":
                self.executor.check(rt, analysis, t)
        return cast(
            ExecuteStatus,
            build_message(
                ExecuteStatus,
                origin=state.origin or "",
                seq=state.seq or 0,
                t=t,
                eligible=self.eligible,
                runtimes={name: runtime_row(rt) for name, rt in runtimes.items()},
                approvals=self._approvals,
                ops=ops,
                paused=self.paused,
                run_stopped=self.run_stopped,
            ),
        )

    def complete(self, start: PlanStart | None) -> CycleDone:
        """Start what plan chose (nothing when plan did not answer); report the cycle done."""
        state, kb = self._state, self.knowledge
        t = self.now
        planned = 0
        started: list[str] = []
        if start is not None:
            runtimes = self.planner.runtimes
            for name, st in start.states.items():
                rt = runtimes.get(name)
                if rt is not None and not rt.in_flight:
                    rt.state = cast(Any, st)
            planned = start.decisions
            for name in start.start:
                rt = runtimes.get(name)
                if rt is None or self.halted:
                    break
                self.executor.start(rt, t)
                started.append(rt.name)
        self._state = None
        return cast(
            CycleDone,
            build_message(
                CycleDone,
                origin=(state.origin or "") if state is not None else "",
                seq=(state.seq or 0) if state is not None else 0,
                t=t,
                started=started,
                decisions=kb.decisions_written - self._before + planned,
            ),
        )

    # -- what happens between and around the parts
    def _apply_op(self, op: dict[str, Any], t: float) -> None:
        kb = self.knowledge
        kind = op.get("op")
        caller = str(op.get("caller", "unknown"))
        if kind == "pause":
            self.paused = True
            kb.record_decision(t, "paused", None, caller=caller)
        elif kind == "resume":
            self.paused = False
            self.stopped = False
            self.heard_run_stop = False
            kb.record_decision(t, "resumed_adaptation", None, caller=caller)
        elif kind == "approve":
            tactic = str(op.get("tactic"))
            result = self.planner.approve(tactic, op.get("approve", True) is True, caller, t)
            if result in ("approved", "rejected"):
                self._approvals.append([tactic, self.planner.runtimes[tactic].state])
            else:
                kb.record_decision(t, "operator_refused", tactic, caller=caller, reason=result)
        elif kind == "node_lost":
            kb.record_decision(
                t,
                "liveliness_lost",
                None,
                node=str(op.get("node")),
                agents=list(op.get("agents", [])),
            )
        elif kind == "run_stop":
            self._do_run_stop(t, caller=caller, reason=str(op.get("reason", "operator")))
        elif kind == "reload":
            self._apply_reload(op, t, caller)
        else:
            kb.record_decision(
                t, "operator_refused", None, caller=caller, reason=f"unknown operation {kind!r}"
            )

    def _endpoint_name(self, name: str) -> str:
        """The topic or service a tactic's (logical) endpoint name means in the current binding."""
        return self.parts.model.endpoint_name(name)

    def _apply_reload(self, op: Mapping[str, Any], t: float, caller: str) -> None:
        kb = self.knowledge
        kb.record_decision(t, "reload_requested", None, caller=caller)
        if "refused" in op:
            kb.record_decision(t, "reload_refused", None, error=str(op["refused"]))
            log.warning("reload refused, the old model stays active: %s", op["refused"])
            return
        sources = sources_of(op)
        tactics = tactics_from_sources(sources)
        # A new binding may map the tactics' logical endpoints elsewhere: take its model.
        model = model_from_sources(sources) if "goal_model" in sources else self.parts.model
        self.parts = dataclasses.replace(self.parts, sources=sources, model=model, tactics=tactics)
        self.planner.set_tactics(tactics)
        files = [op[k] for k in ("goal_model", "binding", "tactics") if isinstance(op.get(k), str)]
        kb.record_decision(t, "reloaded", None, files=files)

    def _escalate(self, failed: TacticRuntime, now: float) -> None:
        kb, planner = self.knowledge, self.planner
        if self.halted:
            return
        # A tactic that failed at this instant is not escalated to again in it: two tactics
        # whose actions a stopped robot refuses would otherwise hand over to each other
        # forever (a RecursionError killed the execute node, issue #12's fault benchmark).
        if self._cascade_t != now:
            self._cascade_t, self._cascade = now, set()
        self._cascade.add(failed.name)
        eligible = [
            planner.runtimes[n]
            for n in self.eligible
            if n not in self._cascade and n in planner.runtimes
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
        fs = planner.runtimes.get(self.parts.config.failsafe or "")
        if fs is not None and fs.name not in self._cascade and not fs.in_flight:
            if fs.tactic.postconditions and self._view.postconditions_hold(fs.tactic):
                # Already where the fail-safe brings the system (another tactic handed it
                # over while the failed one was in flight): running it again would only
                # repeat its actions, its e-mail included.
                kb.record_decision(
                    now, "escalation_exhausted", failed.name, note="fail-safe's goal already holds"
                )
                return
            kb.record_decision(now, "escalated", failed.name, to=fs.name)
            self.executor.start(fs, now, reason=f"escalation from {failed.name} (fail-safe)")
            return
        if self.parts.config.escalate_to_run_stop:
            kb.record_decision(now, "escalated", failed.name, to="run-stop")
            self._do_run_stop(
                now, caller=f"escalation:{failed.name}", reason="postcondition failed"
            )
        else:
            kb.record_decision(now, "escalation_exhausted", failed.name)

    def _do_run_stop(self, t: float, *, caller: str, reason: str) -> None:
        self.stopped = True
        self.paused = True
        service = self.parts.config.run_stop.service
        outcome = None
        if service is not None:
            outcome = self.actuator.request(service, self.parts.config.run_stop.payload, 2.0)
        self.knowledge.record_decision(
            t,
            "run_stop",
            None,
            caller=caller,
            reason=reason,
            service=service,
            ok=None if outcome is None else outcome.ok,
        )
        if self.on_run_stop is not None:
            self.on_run_stop(caller, reason)

    def notified(self, tactic: str, result: Any) -> None:
        """Record a notification's delivery (called from the notifier's worker thread)."""
        self.knowledge.record_decision(
            self.now,
            "notify_result",
            tactic,
            ok=bool(getattr(result, "ok", False)),
            channel=getattr(result, "channel", None),
            to=getattr(result, "to", None),
            error=getattr(result, "error", None),
        )
