"""Utu's MAPE-K cycle, written once: five stages that every deployment wires together.

A cycle visits the stages in a fixed order; each stage takes the previous one's message and
returns its own (the typed messages of :mod:`anunnaki.bus`)::

    MonitorStage.batch ─MonitorBatch─▶ AnalyzeStage.analyze ─AnalysisState─▶
    ExecuteStage.begin ─ExecuteStatus─▶ PlanStage.plan ─PlanStart─▶
    ExecuteStage.complete ─CycleDone─▶ AnalyzeStage.finish

:class:`~anunnaki.utu.AutonomicManager` calls them directly, one after the other, in one
thread (no hop, no copy through the bus); the nodes of :mod:`anunnaki.utu.host._nodes` run one
stage each and carry the messages over the bus. Because the logic exists only here, both
deployments decide alike by construction.

Who owns what
    * monitor: which topics are watched; the time of the cycle; each input's arrival time
      (clamped into the cycle's interval, so a burst keeps its spacing);
    * analyze: the goal model's evaluation, inputs/verdicts/ticks in Knowledge, node losses
      (an agent's topics expire), the warm-up, the analysis of reloaded files;
    * plan: selection — when a tactic became eligible, queued/pending/rejected, the
      ``deferred`` reasons, once-per-episode firing;
    * execute: everything once a tactic starts — actions, deadlines, cooldowns, attempts,
      postconditions, escalation (next tactic → fail-safe → run-stop) — and the operator
      flags (pause, run-stop);
    * knowledge: queries, and the decisions written since the last publication.

All stages share one :class:`~anunnaki.utu.Knowledge` (in one process the object, across
processes the SQLite file, WAL mode): it stays the single source of truth (guideline N8).
None of them reads a clock: the monitor stamps the cycle, the others take its time.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, cast

from anunnaki._safeyaml import read_text_limited
from anunnaki.bus import (
    AnalysisState,
    CycleDone,
    ExecuteStatus,
    MonitorBatch,
    MonitorInput,
    PlanStart,
    body_of,
)
from anunnaki.errors import AnunnakiError, ModelFileError
from anunnaki.goals import GoalModel, parse_binding, parse_goal_model, status_name
from anunnaki.tactics import TacticSet
from anunnaki.tokens import OPERATOR_TOKEN_ENV, token_matches
from anunnaki.utu.cycle._actions import ActionRunner, Actuator
from anunnaki.utu.cycle._knowledge import Decision, Knowledge
from anunnaki.utu.cycle._mape import Analyzer, Executor, Monitor, Planner, TacticRuntime
from anunnaki.utu.cycle._parts import UtuParts, check_parts, load_tactics_text, parts_from_sources

__all__ = [
    "OPERATOR",
    "RESTART",
    "TICK",
    "AnalyzeStage",
    "DecisionTail",
    "ExecuteStage",
    "KnowledgeStage",
    "MonitorStage",
    "PlanStage",
    "Sources",
    "decision_dict",
    "model_from_sources",
    "operator_entry",
    "reloaded_parts",
    "tactics_from_sources",
]

log = logging.getLogger("anunnaki.utu")

#: What Knowledge's inputs table calls the end of a step and an operator call.
TICK = "__tick__"
OPERATOR = "__operator__"
#: Input marker: a stage started on a run's knowledge and took up its state (``node``:
#: which part: ``manager`` for the composed one, or ``analyze``/``plan``/``execute``).
RESTART = "__restart__"
#: Seconds of recorded inputs a restarted analyzer re-reads to recover its values and rates.
RESTORE_WINDOW = 120.0

Sources = dict[str, tuple[str | None, str]]
_STATUS_OF_NAME: dict[str, bool | None] = {"satisfied": True, "unsatisfied": False}


def _build(c: Callable[..., Any], **fields: Any) -> Any:
    """Build a cycle message from our own, trusted values (validated only at the bus)."""
    return cast(Any, c).trusted(**fields)


# -- restarts ------------------------------------------------------------------------------------
def resuming(knowledge: Knowledge, node: str = "manager") -> bool:
    """Whether ``node`` takes up a run that it (or its predecessor) was part of.

    The whole manager: the knowledge holds a run (inputs or decisions). One node of a
    per-node run, whose peers may have recorded inputs before it came up (the robot runs
    first): analyze when a step was ever marked (it writes the step ends), plan and execute
    when anything was decided (nothing is decided without both of them).
    """
    if node == "analyze":
        return knowledge.has_input(TICK)
    if node in ("plan", "execute"):
        return knowledge.counts()["decisions"] > 0
    return knowledge.holds_run()


def mark_restart(knowledge: Knowledge, node: str) -> float:
    """Record that ``node`` (``manager``, ``analyze``, ``plan``, ``execute``) took up the run.

    An input marker (:data:`RESTART`, where a replay restarts the same part) and a
    ``restarted`` decision (what ``anunnaki log`` and ``explain`` show), at the run's last
    instant. Returns that instant.
    """
    t = knowledge.last_t()
    knowledge.record_input(t, RESTART, {"node": node})
    knowledge.record_decision(t, "restarted", None, node=node)
    knowledge.flush()
    return t


def last_halt(knowledge: Knowledge) -> tuple[bool, bool]:
    """(paused, run-stopped) as the run's decisions left them (a restart keeps a run-stop)."""
    paused = stopped = False
    for d in knowledge.decisions():
        if d.kind == "run_stop":
            paused = stopped = True
        elif d.kind == "paused":
            paused = True
        elif d.kind == "resumed_adaptation":
            paused = stopped = False
    return paused, stopped


# -- operator calls ------------------------------------------------------------------------------
def operator_entry(op: str, message: Any) -> dict[str, Any]:
    """Turn an operator service request into an op entry, or ``{"error": …}`` to refuse it.

    The operations are ``run_stop``, ``pause``, ``resume``, ``approve``, ``reload``; the
    request names its ``caller`` (recorded with the decision). A reload is checked here, as
    ``anunnaki check`` does, so a broken file is refused with its error before it reaches
    the cycle; the entry then carries the files' *texts*, so every stage applies the same
    version even if a file changes meanwhile.
    """
    body = body_of(message)
    caller = str(body.get("caller") or "unknown")
    entry: dict[str, Any] = {"op": op, "caller": caller}
    if op == "approve":
        tactic = body.get("tactic")
        if not isinstance(tactic, str):
            return {"error": "give 'tactic': the name of a pending tactic"}
        approve = body.get("approve", True)
        if not isinstance(approve, bool):
            return {"error": "'approve' must be true or false"}
        entry["tactic"] = tactic
        entry["approve"] = approve
    elif op == "run_stop":
        entry["reason"] = str(body.get("reason", "operator"))
    elif op == "reload":
        files = {k: body.get(k) for k in ("goal_model", "binding", "tactics")}
        if not any(isinstance(v, str) for v in files.values()):
            return {"error": "give goal_model, binding and/or tactics paths"}
        entry.update({k: v for k, v in files.items() if isinstance(v, str)})
    elif op not in ("pause", "resume"):
        return {"error": f"unknown operation {op!r}"}
    return entry


#: The largest file a hot reload reads (goal models and tactics are small).
MAX_RELOAD_BYTES = 4 << 20


def read_sources(
    base: Mapping[str, tuple[str | None, str]],
    files: Mapping[str, Any],
    roots: Sequence[Path] | None = None,
) -> Sources:
    """``base`` with the named files read (``goal_model``, ``binding``, ``tactics``).

    With ``roots``, a file must lie in one of those folders (symlinks resolved); it must be
    a regular file of at most :data:`MAX_RELOAD_BYTES` (a pipe or a device would block or
    never end), read without following it anywhere else.
    """
    sources = dict(base)
    for kind in ("goal_model", "binding", "tactics"):
        path = files.get(kind)
        if isinstance(path, str):
            sources[kind] = (path, _read_reload_file(kind, path, roots))
    return sources


def _read_reload_file(kind: str, path: str, roots: Sequence[Path] | None) -> str:
    what = kind.replace("_", " ")
    real = Path(path).resolve()
    if roots is not None and not any(real.is_relative_to(r) for r in roots):
        raise ModelFileError(
            f"refused: the {what} is outside the folders a reload may read",
            path=path,
            hint="put it next to the running files, or list its folder in the Utu "
            f"configuration's reload_dirs (now: {', '.join(map(str, roots)) or 'none'})",
        )
    try:
        return read_text_limited(real, max_bytes=MAX_RELOAD_BYTES)
    except ModelFileError as exc:  # a pipe, a device, too big, unreadable: refused, never read
        raise ModelFileError(
            f"refused: the {what}: {exc.message}", path=path, line=exc.line, hint=exc.hint
        ) from None


def model_from_sources(sources: Mapping[str, tuple[str | None, str]]) -> GoalModel:
    """Parse the goal model (with its binding) from recorded texts."""
    b = sources.get("binding")
    binding = parse_binding(b[1], source=b[0] or "<binding>") if b else None
    if "goal_model" not in sources:
        raise ModelFileError("no goal model was recorded", hint="give goal_model")
    path, text = sources["goal_model"]
    return parse_goal_model(text, source=path or "<goal-model>", binding=binding)


def tactics_from_sources(sources: Mapping[str, tuple[str | None, str]]) -> TacticSet:
    """Parse the tactics from recorded texts (none when there is no tactics file)."""
    t = sources.get("tactics")
    return load_tactics_text(t[1], t[0]) if t else TacticSet(tactics=[])


def reloaded_parts(parts: UtuParts, op: Mapping[str, Any]) -> UtuParts:
    """The parts a reload op asks for (its texts, or its files read now), checked.

    Raises:
        ModelFileError: A file is unreadable or invalid (the message names file and line).

    """
    texts = op.get("sources")
    if isinstance(texts, Mapping):
        sources = {**parts.sources, **_sources_of(op)}
    else:
        sources = read_sources(parts.sources, op, parts.config.reload_roots())
    if "goal_model" not in sources:  # a manager built from objects: keep its model
        if "binding" in sources:
            raise ModelFileError(
                "this manager was built without its goal-model file; give goal_model too"
            )
        replaced = dataclasses.replace(
            parts, sources=sources, tactics=tactics_from_sources(sources)
        )
        return check_parts(replaced)
    return parts_from_sources(parts.config, sources)


# -- monitor -------------------------------------------------------------------------------------
class MonitorStage:
    """Takes what arrived and stamps the cycle.

    Each input keeps its own arrival time (the sender's stamp on wall time, else the
    cycle's), clamped into ``(previous cycle, this cycle]``: a burst taken by one cycle
    keeps its spacing, so ``rate(A)`` and temporal goals see what really happened.
    """

    def __init__(self, parts: UtuParts, *, origin: str = "") -> None:
        self.origin = origin
        self.seq = 0
        self.last_t = 0.0  # inputs are never stamped before the start of time
        self.operator_token = parts.config.operator_token()
        self.unauthorised = 0  # operator requests refused for want of the token
        self.set_parts(parts)

    def set_parts(self, parts: UtuParts) -> None:
        """Watch the topics of ``parts``' goal model."""
        self.parts = parts
        topics: list[str] = []
        for agent in parts.model.agents.values():
            for tb in agent.topics:
                if tb.topic not in topics:
                    topics.append(tb.topic)
        self.topics = topics

    def request(self, op: str, message: Any) -> tuple[dict[str, Any] | None, dict[str, Any]]:
        """An operator service request: ``(op entry to queue or None, the reply)``.

        A reload is checked now, so the caller hears of a broken file at once: refused, it
        still enters the cycle (marked ``refused``) so the decision log says it and a replay
        repeats it; accepted, it carries the files' texts and this monitor watches the new
        model's topics from now on.
        """
        refused = self._unauthorised(op, message)
        if refused is not None:
            return None, {"ok": False, "status": "unauthorised", "error": refused}
        entry = operator_entry(op, message)
        if "error" in entry:
            return None, {"ok": False, "error": entry["error"]}
        reply: dict[str, Any] = {"ok": True, "queued": op, "caller": entry["caller"]}
        if op == "reload":
            try:
                parts = reloaded_parts(self.parts, entry)
            except (AnunnakiError, OSError) as exc:
                return {**entry, "refused": str(exc)}, {
                    "ok": False,
                    "status": "refused",
                    "error": str(exc),
                }
            entry["sources"] = {k: [p, text] for k, (p, text) in parts.sources.items()}
            self.set_parts(parts)
            reply["status"] = "accepted"
        return entry, reply

    def _unauthorised(self, op: str, message: Any) -> str | None:
        """Why an operator request may not act (``None``: it may); a run-stop always may."""
        token = self.operator_token
        if token is None or op == "run_stop" or token_matches(body_of(message).get("token"), token):
            return None
        self.unauthorised += 1
        if self.unauthorised == 1:
            log.warning(
                "utu: refused an operator %s without the operator token; further refusals "
                "are counted, not logged",
                op,
            )
        return (
            f"unauthorised: {op} needs the operator token ('token' in the request; clients "
            f"read it from ${OPERATOR_TOKEN_ENV}); anyone may request a run-stop"
        )

    def batch(
        self,
        t: float,
        inputs: Sequence[tuple[str, Mapping[str, Any], float | None]],
        ops: Sequence[Mapping[str, Any]],
    ) -> MonitorBatch:
        """One batch at time ``t`` (never earlier than the last) of ``(topic, msg, t_in)``."""
        t = max(float(t), self.last_t)
        previous, self.last_t = self.last_t, t
        self.seq += 1
        taken = [
            _build(
                MonitorInput,
                topic=topic,
                t=t if t_in is None else min(max(float(t_in), previous), t),
                msg=dict(msg),
            )
            for topic, msg, t_in in inputs
        ]
        return cast(
            MonitorBatch,
            _build(
                MonitorBatch,
                origin=self.origin,
                seq=self.seq,
                t=t,
                inputs=taken,
                ops=[dict(op) for op in ops],
            ),
        )


# -- analyze -------------------------------------------------------------------------------------
class AnalyzeStage:
    """Evaluates the goal model on every batch; records inputs, verdicts and step ends.

    Args:
        parts: The loaded configuration.
        knowledge: The knowledge base.
        origin: Names this analyzer's cycles (execute answers only its own).

    """

    def __init__(self, parts: UtuParts, knowledge: Knowledge, *, origin: str = "") -> None:
        self.parts = parts
        self.knowledge = knowledge
        self.origin = origin
        self.execute_alive: Callable[[], bool] | None = None  # per-node: is execute up?
        self.monitor = Monitor(parts.model, knowledge)
        self.analyzer = Analyzer(parts.model, parts.tactics, knowledge)
        self.now = 0.0
        self.started_at: float | None = None
        self.warm_from: float | None = None  # the warm-up's start: the first step, or a restart's
        self.cycles = 0
        self.taken = 0
        self.seq = 0
        self.eligible: list[str] = []
        self.refused = 0  # batches refused as implausible (see _plausible)
        #: A reaction took inputs and decided nothing: the next cycle ends that step.
        self.reacted = False
        self._marked: dict[int, tuple[float, bool]] = {}
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
            ts = self.monitor.topics.get(row.topic)
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
        unless_idle: Sequence[str] | None = None,
    ) -> AnalysisState | None:
        """Take one batch; return the analysis execute acts on.

        ``full`` fills in ``nodes`` (every goal's utility and status, what displays show);
        a cycle in one process leaves it out and builds it only to publish.

        ``unless_idle`` (the applicable tactics of the last cycle) makes this a reaction:
        when the batch changed no goal, brought no operator call and left the applicable
        tactics as they were, its inputs are recorded and ``None`` is returned — there is
        nothing to decide now, and the next cycle marks the end of the step.
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
            if self.monitor.take(item.topic, item.msg, at):
                a.observe(item.topic, item.msg, at)
        self.taken += len(inputs)
        self.now = t
        ticked = a.tick(t)
        changed = a.record_changes(t)
        out_ops: list[dict[str, Any]] = []
        for op in batch.ops:
            kb.record_input(t, OPERATOR, op)
            out_ops.append(self._apply_op(dict(op), t, changed))
        eligible = a.eligible()
        if unless_idle is not None and not changed and not out_ops and eligible == unless_idle:
            self.reacted = self.reacted or bool(inputs)
            return None
        self.eligible = eligible
        self.seq += 1
        self._marked[self.seq] = (
            t,
            bool(not self.cycles or inputs or ticked or changed or batch.ops or self.reacted),
        )
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
            taken=self.taken,
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
                for topic, stats in self.monitor.topics.items()
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
        self.monitor.set_model(parts.model)
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
            _build(
                AnalysisState,
                t=t,
                root=self.parts.model.root,
                nodes=msg["nodes"] if msg is not None else {},
                violated=violated,
                tactics=sorted(tactics),
                **extra,
            ),
        )

    def finish(self, done: CycleDone | None, seq: int | None = None) -> None:
        """End a cycle (``done``: execute's report, ``None`` when it never answered).

        Marks the end of the step in Knowledge when it took something or decided
        something, so a replay steps at the same instants.
        """
        key = done.seq if done is not None else seq
        if key is None or key not in self._marked:
            return
        # Unreported while execute is gone: the marker says so (a replay analyses only).
        gone = done is None and self.execute_alive is not None and not self.execute_alive()
        for old in [s for s in self._marked if s < key]:  # never reported: end them too
            self._mark(old, 0, gone)
        self._mark(key, done.decisions if done is not None else 0, gone)

    def _mark(self, seq: int, decisions: int, gone: bool) -> None:
        t, marked = self._marked.pop(seq)
        if marked or decisions > 0:
            self.knowledge.record_input(t, TICK, {"executed": False} if gone else {})
        self.cycles += 1

    @property
    def unfinished(self) -> list[int]:
        """Cycles analysed but not yet reported done."""
        return sorted(self._marked)


# -- plan ----------------------------------------------------------------------------------------
# Who owns which part of a tactic's runtime: plan selects (when it became eligible, the last
# "deferred" reason, whether it fired in this episode, queued/pending/rejected); execute
# owns everything that happens once it starts (every other field).
_PLAN_FIELDS = frozenset({"tactic", "state", "eligible_since", "blocked_logged", "fired"})
_EXEC_FIELDS = tuple(
    f.name for f in dataclasses.fields(TacticRuntime) if f.name not in _PLAN_FIELDS
)


class PlanStage:
    """The priority-sorted queue of tactics (the :class:`~anunnaki.utu.Planner`)."""

    def __init__(self, parts: UtuParts, knowledge: Knowledge) -> None:
        self.knowledge = knowledge
        self.planner = Planner(parts.tactics, knowledge, dwell=parts.config.dwell)
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
                self.planner.set_tactics(tactics_from_sources(_sources_of(op)))
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
            for f in _EXEC_FIELDS:
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
            _build(
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


def _sources_of(op: Mapping[str, Any]) -> Sources:
    return {str(k): (v[0], str(v[1])) for k, v in dict(op["sources"]).items()}


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
            n: _STATUS_OF_NAME.get(s) for n, s in (state.post_goals or {}).items()
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
            _build(
                ExecuteStatus,
                origin=state.origin or "",
                seq=state.seq or 0,
                t=t,
                eligible=self.eligible,
                runtimes={name: _runtime_row(rt) for name, rt in runtimes.items()},
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
            _build(
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
        sources = _sources_of(op)
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


def _runtime_row(rt: TacticRuntime) -> dict[str, Any]:
    return {"state": rt.state, **{f: getattr(rt, f) for f in _EXEC_FIELDS}}


# -- knowledge -----------------------------------------------------------------------------------
def decision_dict(d: Decision) -> dict[str, Any]:
    """A decision as published on ``/utu/knowledge/decisions``."""
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

    def read(self) -> list[Decision]:
        """Return the decisions written since the last call, in order."""
        rows = self.knowledge.decisions(after_id=self.last_id)
        if rows:
            self.last_id = rows[-1].id
        return rows


class KnowledgeStage:
    """Answers ``/utu/knowledge/query`` from the knowledge base and the latest cycle.

    ``{what: decisions|queue|state, limit, after}``: the decisions (the newest ``limit``,
    with ids above ``after`` if given), the priority-sorted queue, or the analysis with the
    queue and the operator flags.
    """

    def __init__(self, parts: UtuParts, knowledge: Knowledge) -> None:
        self.parts = parts
        self.knowledge = knowledge
        self.state: dict[str, Any] = {}
        self.queue: list[Any] = []
        self.flags = {"paused": False, "run_stopped": False}

    def query(self, message: Any) -> dict[str, Any]:
        """Answer one query (a bus message or a mapping)."""
        body = body_of(message)
        what = body.get("what", "state")
        limit = body.get("limit", 100)
        if not isinstance(limit, int) or isinstance(limit, bool) or limit < 1:
            limit = 100
        if what == "decisions":
            after = body.get("after")
            after_id = after if isinstance(after, int) and not isinstance(after, bool) else None
            rows = self.knowledge.decisions(limit=min(limit, 10_000), after_id=after_id)
            return {
                "ok": True,
                "decisions": [
                    {"id": d.id, "t": d.t, "kind": d.kind, "tactic": d.tactic, "data": d.data}
                    for d in rows
                ],
            }
        if what == "queue":
            return {"ok": True, "queue": list(self.queue)}
        if what == "state":
            state = self.state or {
                "t": None,
                "root": self.parts.model.root,
                "nodes": {},
                "violated": [],
                "tactics": [],
            }
            return {"ok": True, **state, "queue": list(self.queue), **self.flags}
        return {"ok": False, "error": f"unknown query {what!r}; ask decisions, queue or state"}
