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
    """The priority-sorted queue of tactics (the :class:`~anunnaki.utu.Planner`)."""

    def __init__(self, parts: UtuParts, knowledge: Knowledge) -> None:
        self.knowledge = knowledge
        self.planner = Planner(parts.tactics, knowledge, dwell=parts.config.dwell)
        self.planner.select = baseline(parts.config.manager, parts.config.manager_seed)
        self.run_stopped = False  # a run-stop heard on its topic (guideline S4)
        if resuming(knowledge):
            self.run_stopped = last_halt(knowledge)[1]
        rows = knowledge.tactics()
        if rows:
            self.planner.restore(rows)

    def plan(self, st: ExecuteStatus) -> PlanStart:  # noqa: C901
        """Update the queue from execute's status; return what to start."""
        kb = self.knowledge
        t = float(st.t)
        before = kb.decisions_written
        for op in st.ops:
            if op.get("op") == "reload" and isinstance(op.get("sources"), Mapping):
                self.planner.set_tactics(tactics_from_sources(sources_of(op)))
            elif op.get("op") == "resume":
                self.run_stopped = False
        runtimes = self.planner.runtimes
        for name, row in st.runtimes.items():
            rt = runtimes.get(name)
            if rt is None:
                continue
            attempt = row.get("attempt")
            if isinstance(attempt, int) and attempt > rt.attempt:
                rt.fired = True  # started by execute (escalation) since we last heard
            for f in EXEC_FIELDS:
                if f in row:
                    setattr(rt, f, row[f])
            state = row.get("state")
            if state in ("running", "awaiting") or rt.in_flight:
                rt.state = cast(Any, state)
        for name, state in st.approvals:
            if name in runtimes:
                runtimes[name].state = cast(Any, state)
        halted = st.paused or st.run_stopped or self.run_stopped
        start = [] if halted else self.planner.update(list(st.eligible), t)
        states = {name: rt.state for name, rt in runtimes.items()}
        for rt in start:
            rt.state = "running"  # execute starts it now; its next status confirms
            rt.fired = True
        return cast(
            PlanStart,
            build_message(
                PlanStart,
                origin=st.origin,
                seq=st.seq,
                t=t,
                start=[rt.name for rt in start],
                states=states,
                queue=self.planner.queue(),
                decisions=kb.decisions_written - before,
            ),
        )
