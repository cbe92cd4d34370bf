"""The plan stage: selection — dwell, cooldown, conflicts, approvals, once per episode."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, cast

from anunnaki.messages import ExecuteStatus, PlanStart
from anunnaki.utu.cycle._entries import (
    EXEC_FIELDS,
    build_message,
    last_halt,
    resuming,
    sources_of,
    tactics_from_sources,
)
from anunnaki.utu.cycle._knowledge import Knowledge
from anunnaki.utu.cycle._managers import baseline
from anunnaki.utu.cycle._mape import Planner
from anunnaki.utu.cycle._parts import UtuParts

__all__ = [
    "PlanStage",
]


class PlanStage:
    """The priority-sorted queue of tactics: selection (the :class:`~anunnaki.utu.Planner`).

    Plan writes only the selection fields of a tactic's runtime (``PLAN_FIELDS``: when
    it became eligible, queued/pending/rejected, the last ``deferred`` reason, whether it
    fired in this episode); everything that happens once a tactic starts is execute's.

    Args:
        parts: The loaded configuration.
        knowledge: The knowledge base.
        planner: The tactic runtimes of the execute stage in the same process (one store:
            nothing is copied between the two); a plan stage starts with no selection state
            of its own (a restarted one knows what Knowledge kept: the pending approvals).
            ``None`` (a plan node alone): a copy of its own, restored from Knowledge, that
            takes the execute node's fields from each status (:meth:`mirror`).

    """

    def __init__(
        self, parts: UtuParts, knowledge: Knowledge, *, planner: Planner | None = None
    ) -> None:
        self.knowledge = knowledge
        if planner is None:
            planner = Planner(parts.tactics, knowledge, dwell=parts.config.dwell)
            rows = knowledge.tactics()
            if rows:
                planner.restore(rows)
        else:
            planner.forget_selection()
        planner.select = baseline(parts.config.manager, parts.config.manager_seed)
        self.planner = planner
        self.run_stopped = False  # a run-stop heard on its topic (guideline S4)
        if resuming(knowledge):
            self.run_stopped = last_halt(knowledge)[1]

    def mirror(self, st: ExecuteStatus) -> None:
        """Take what the execute node owns into this plan node's own copy of the runtimes.

        Only where plan and execute run in different processes: a reload's tactics, the
        execute-owned fields of each runtime (``EXEC_FIELDS``), its state once execute
        has it (started, in flight, finished), and the operator's approvals.
        """
        for op in st.ops:
            if op.get("op") == "reload" and isinstance(op.get("sources"), Mapping):
                self.planner.set_tactics(tactics_from_sources(sources_of(op)))
        runtimes = self.planner.runtimes
        for name, row in st.runtimes.items():
            rt = runtimes.get(name)
            if rt is None:
                continue
            attempt = row.get("attempt")
            started = isinstance(attempt, int) and attempt > rt.attempt
            if started:
                rt.fired = True  # started by execute since we last heard (plan, escalation)
            for f in EXEC_FIELDS:
                if f in row:
                    setattr(rt, f, row[f])
            state = row.get("state")
            if started or state in ("running", "awaiting") or rt.in_flight:
                rt.state = cast(Any, state)
        for name, state in st.approvals:
            if name in runtimes:
                runtimes[name].state = cast(Any, state)

    def plan(self, st: ExecuteStatus) -> PlanStart:
        """Update the queue from execute's status; return what to start."""
        kb = self.knowledge
        t = float(st.t)
        before = kb.decisions_written
        if any(op.get("op") == "resume" for op in st.ops):
            self.run_stopped = False
        halted = st.paused or st.run_stopped or self.run_stopped
        start = [] if halted else self.planner.update(list(st.eligible), t)
        states = {name: rt.state for name, rt in self.planner.runtimes.items()}
        for rt in start:
            rt.fired = True  # its episode has fired: execute starts it now
        names = [rt.name for rt in start]
        return cast(
            PlanStart,
            build_message(
                PlanStart,
                origin=st.origin,
                seq=st.seq,
                t=t,
                start=names,
                states=states,
                queue=self.planner.queue(starting=names),
                decisions=kb.decisions_written - before,
            ),
        )
