"""The execute stage: actions, postconditions, escalation, and the operator flags."""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Mapping
from typing import Any, cast

from anunnaki.messages import AnalysisState, CycleDone, ExecuteStatus, PlanStart
from anunnaki.utu.cycle._actions import ActionRunner, Actuator
from anunnaki.utu.cycle._entries import (
    build_message,
    last_halt,
    model_from_sources,
    resuming,
    runtime_row,
    sources_of,
    tactics_from_sources,
)
from anunnaki.utu.cycle._knowledge import Knowledge
from anunnaki.utu.cycle._mape import Executor, Planner, TacticRuntime
from anunnaki.utu.cycle._parts import UtuParts

__all__ = [
    "ExecuteStage",
]

log = logging.getLogger("anunnaki.utu")


# -- execute -------------------------------------------------------------------------------------
class ExecuteStage:
    """Performs tactics and checks their postconditions (the :class:`~anunnaki.utu.Executor`).

    :meth:`begin` applies the cycle's operator calls, runs actions resumed after a restart
    and checks the postconditions of the tactics in flight against the analysis (the
    verdicts the :class:`~anunnaki.utu.Analyzer` put in it) — escalating to another
    applicable tactic, the fail-safe, then a run-stop when one fails; :meth:`complete`
    starts what plan chose. Plan comes between the two because it selects among what
    :meth:`begin` left: a tactic verified or failed at this instant, and the tactic an
    escalation started, are what the selection sees (docs/architecture.md, "Where a goal
    update flows").

    The stage owns the tactic runtimes (:attr:`planner`, one store per process): it
    restores them after a restart, swaps them on a reload and writes every field of what
    happens once a tactic starts (:data:`~anunnaki.utu.cycle._entries.EXEC_FIELDS`); the
    plan stage of the same process is handed the same store and writes only the selection
    fields (:data:`~anunnaki.utu.cycle._entries.PLAN_FIELDS`).

    Args:
        parts: The loaded configuration.
        knowledge: The knowledge base.
        actuator: How actions reach the managed system.
        on_run_stop: Called after a run-stop was performed (e.g. to announce it).
        runner: Runs blocking requests off the loop (``None``: in the step).
        planner: The tactic runtimes to take up (a restarted execute stage keeps the
            selection state of its process's plan stage); default: a new store.

    """

    def __init__(
        self,
        parts: UtuParts,
        knowledge: Knowledge,
        actuator: Actuator,
        *,
        on_run_stop: Callable[[str, str], None] | None = None,
        runner: ActionRunner | None = None,
        planner: Planner | None = None,
    ) -> None:
        self.parts = parts
        self.knowledge = knowledge
        self.actuator = actuator
        self.on_run_stop = on_run_stop
        #: The tactic runtimes (and the conflicts between tactics): plan selects among them.
        self.planner = planner or Planner(parts.tactics, knowledge, dwell=parts.config.dwell)
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
        #: The analysis of the cycle: applicable tactics, postconditions, their goals' status.
        self.analysis: AnalysisState | None = None
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
    def eligible(self) -> list[str]:
        """The applicable tactics, as the analysis of the cycle has them (file order)."""
        return list((self.analysis.eligible if self.analysis is not None else None) or [])

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
        self._state = self.analysis = state
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
        goals = dict(state.post_goals or {})
        for rt in list(runtimes.values()):
            if rt.state == "awaiting":
                self.executor.check(rt, t, verified=self._verified(rt), goals=goals)
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

    def mirror(self, start: PlanStart) -> None:
        """Take what the plan node owns into this execute node's own copy of the runtimes.

        Only where plan and execute run in different processes: the selection state of
        each tactic not in flight (queued, pending, idle, …).
        """
        runtimes = self.planner.runtimes
        for name, st in start.states.items():
            rt = runtimes.get(name)
            if rt is not None and not rt.in_flight:
                rt.state = cast(Any, st)

    def complete(self, start: PlanStart | None) -> CycleDone:
        """Start what plan chose (nothing when plan did not answer); report the cycle done."""
        state, kb = self._state, self.knowledge
        t = self.now
        planned = 0
        started: list[str] = []
        if start is not None:
            runtimes = self.planner.runtimes
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

    def _verified(self, rt: TacticRuntime) -> bool:
        """Whether the analysis of this cycle found every postcondition of ``rt`` holding."""
        post = self.analysis.postconditions if self.analysis is not None else None
        return bool((post or {}).get(rt.name, False))

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
            if fs.tactic.postconditions and self._verified(fs):
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
