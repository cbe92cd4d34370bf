"""The analyze stage: the goal model's evaluation at the start of every cycle."""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from typing import Any, cast

from anunnaki.errors import AnunnakiError
from anunnaki.goals import status_name
from anunnaki.messages import AnalysisState, MonitorBatch
from anunnaki.utu.cycle._entries import (
    OPERATOR,
    RESTORE_WINDOW,
    build_message,
    reloaded_parts,
    resuming,
)
from anunnaki.utu.cycle._knowledge import Knowledge
from anunnaki.utu.cycle._mape import Analyzer, TopicWatch
from anunnaki.utu.cycle._parts import UtuParts

__all__ = [
    "AnalyzeStage",
]

log = logging.getLogger("anunnaki.utu")


# -- analyze -------------------------------------------------------------------------------------
class AnalyzeStage:
    """Evaluates the goal model on every batch; records inputs and verdicts.

    Entered once per cycle: :meth:`analyze` hands on the analysis, which says whether the
    step took something (``took``); the host ends the step
    (:func:`~anunnaki.utu.cycle._entries.end_step`) once execute has acted on it.

    Args:
        parts: The loaded configuration.
        knowledge: The knowledge base.
        origin: Names this analyzer's cycles (execute answers only its own).

    """

    def __init__(self, parts: UtuParts, knowledge: Knowledge, *, origin: str = "") -> None:
        self.parts = parts
        self.knowledge = knowledge
        self.origin = origin
        self.topic_watch = TopicWatch(parts.model, knowledge)
        self.analyzer = Analyzer(parts.model, parts.tactics, knowledge)
        self.now = 0.0
        self.started_at: float | None = None
        self.warm_from: float | None = None  # the warm-up's start: the first step, or a restart's
        self.cycles = 0
        self.seq = 0
        self.eligible: list[str] = []  # the applicable tactics now (restored after a restart)
        self.handed: list[str] = []  # ... as the last analysis handed on had them
        self.refused = 0  # batches refused as implausible (see _plausible)
        #: A reaction took inputs and decided nothing: the next cycle ends that step.
        self.reacted = False
        if resuming(knowledge):
            self._restore()

    def _restore(self) -> None:
        """Take up a run after a restart: its time, and the values its last inputs gave.

        The inputs recorded in the last :data:`RESTORE_WINDOW` seconds are taken again (not
        recorded again), so every attribute has the value and age it had, rates and
        temporal goals their history, and an in-flight tactic's postconditions are judged
        on what was known — not on nothing (before: a restarted node started with no values
        and escalated an in-flight fail-safe to a run-stop). The verdicts this gives are the
        ones already recorded: they are not recorded again.
        """
        kb, a = self.knowledge, self.analyzer
        last = kb.last_t()
        first = kb.first_input_t()
        self.started_at = first if first is not None else last
        # The warm-up starts again at the restarted part's first step: restored values may
        # have gone stale while it was down, and fresh inputs get `warmup` seconds to arrive
        # before an unknown goal counts (in-flight tactics keep their deadlines).
        self.warm_from = None
        for row in kb.inputs(since=last - RESTORE_WINDOW):
            if row.topic.startswith("__"):
                continue
            ts = self.topic_watch.topics.get(row.topic)
            if ts is not None:
                ts.take(row.t, dict(row.msg))
                a.observe(row.topic, row.msg, row.t)
        a.tick(last)
        a.evaluator.drain_changes()  # known already: recorded before the restart
        self.now = last
        self.eligible = a.eligible()

    def analyze(
        self,
        batch: MonitorBatch,
        *,
        full: bool = True,
        react: bool = False,
    ) -> AnalysisState | None:
        """Take one batch; return the analysis execute acts on.

        ``full`` fills in ``nodes`` (every goal's utility and status, what displays show);
        a cycle in one process leaves it out and builds it only to publish.

        ``react`` makes this a reaction: when the batch changed no goal, brought no
        operator call and left the applicable tactics as the last analysis handed on had
        them, its inputs are recorded and ``None`` is returned — there is nothing to decide
        now, and the next cycle marks the end of the step.
        """
        a, kb = self.analyzer, self.knowledge
        if not self.plausible(batch):
            return None
        t = max(float(batch.t), self.now)
        inputs = batch.inputs
        if self.warm_from is None:  # the first step, or a restarted part's first
            self.warm_from = min([t, *(i.t for i in inputs)])
            if self.started_at is None:
                self.started_at = self.warm_from
        a.warming_up = t - self.warm_from < self.parts.config.warmup
        for item in inputs:
            at = min(max(item.t, self.now), t)
            if self.topic_watch.take(item.topic, item.msg, at):
                a.observe(item.topic, item.msg, at)
        self.now = t
        ticked = a.tick(t)
        changed = a.record_changes(t)
        out_ops: list[dict[str, Any]] = []
        for op in batch.ops:
            kb.record_input(t, OPERATOR, op)
            out_ops.append(self._apply_op(dict(op), t, changed))
        eligible = a.eligible()
        if react and not changed and not out_ops and eligible == self.handed:
            self.reacted = self.reacted or bool(inputs)
            return None
        self.eligible = self.handed = eligible
        self.seq += 1
        took = bool(not self.cycles or inputs or ticked or changed or batch.ops or self.reacted)
        self.cycles += 1
        self.reacted = False
        tactics = self.parts.tactics.tactics
        post_goals = {
            c.goal: status_name(a.evaluator.state(c.goal).status)
            for tac in tactics
            for c in tac.postconditions
            if c.goal in a.evaluator.index
        }
        return self.state(
            t,
            eligible,
            nodes=full,
            origin=self.origin,
            seq=self.seq,
            eligible=eligible,
            postconditions={
                tac.name: a.postconditions_hold(tac) for tac in tactics if tac.postconditions
            },
            post_goals=post_goals,
            ops=out_ops,
            warming_up=a.warming_up,
            changed=changed,
            took=took,
        )

    def plausible(self, batch: MonitorBatch) -> bool:
        """Refuse (count, log once) a batch stamped implausibly far ahead of this run's time.

        The first batch sets the time; afterwards a batch more than ``max_time_jump`` seconds
        ahead is refused whole (a forged ``/utu/monitor/input`` must not move time on for good).
        """
        jump = self.parts.config.max_time_jump
        t = float(batch.t)
        if not math.isfinite(t) or (
            jump is not None and self.started_at is not None and t > self.now + jump
        ):
            self.refused += 1
            if self.refused == 1:
                log.warning(
                    "utu: refused a monitor batch stamped %r (now %.3f; max_time_jump %s s); "
                    "further refusals are counted, not logged",
                    t, self.now, jump,
                )  # fmt: skip
            return False
        return True

    def _apply_op(self, op: dict[str, Any], t: float, changed: list[str]) -> dict[str, Any]:
        a = self.analyzer
        kind = op.get("op")
        if kind == "node_lost":
            node = str(op.get("node"))
            agents = [ag for ag in self.parts.model.agents.values() if ag.node == node]
            for agent in agents:
                for tb in agent.topics:
                    a.evaluator.expire(tb.topic, t)
            changed += a.record_changes(t)
            # A dead publisher is a known fact, not data still arriving: end the warm-up.
            self.started_at = min(self.started_at or t, t - self.parts.config.warmup)
            self.warm_from = self.started_at
            a.warming_up = False
            op["agents"] = [ag.id for ag in agents]
        elif kind == "reload" and "refused" not in op:
            op.update(self._reload(op, t))
        return op

    def _reload(self, op: Mapping[str, Any], t: float) -> dict[str, Any]:
        """Swap in reloaded files; returns what execute and plan need to follow."""
        try:
            parts = reloaded_parts(self.parts, op)
            analyzer = Analyzer(parts.model, parts.tactics, self.knowledge)
        except (AnunnakiError, OSError) as exc:
            return {"refused": str(exc)}
        recent = sorted(
            (
                (arrived, topic, body)
                for topic, stats in self.topic_watch.topics.items()
                for arrived, body in stats.recent
            ),
            key=lambda x: x[0],
        )
        for arrived, topic, body in recent:
            analyzer.observe(topic, body, arrived)
        analyzer.tick(t)
        analyzer.record_changes(t)
        analyzer.warming_up = self.analyzer.warming_up
        self.parts, self.analyzer = parts, analyzer
        self.topic_watch.set_model(parts.model)
        for kind, (path, text) in parts.sources.items():
            self.knowledge.record_model(t, kind, path, text)
        return {"sources": {k: [p, text] for k, (p, text) in parts.sources.items()}}

    def state(
        self, t: float, tactics: Sequence[str], *, nodes: bool = True, **extra: Any
    ) -> AnalysisState:
        """The analysis as displays see it (``nodes`` only when asked), plus ``extra`` fields."""
        ev = self.analyzer.evaluator
        msg = self.analyzer.state_message(t, tactics) if nodes else None
        violated = (
            msg["violated"]
            if msg is not None
            else [n for n in self.parts.model.goals if ev.state(n).status is not True]
        )
        return cast(
            AnalysisState,
            build_message(
                AnalysisState,
                t=t,
                root=self.parts.model.root,
                nodes=msg["nodes"] if msg is not None else {},
                violated=violated,
                tactics=sorted(tactics),
                **extra,
            ),
        )
