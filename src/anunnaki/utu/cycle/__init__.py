"""Utu's cycle, once: Monitor → Analyze → Plan → Execute over Knowledge.

The cycle has no bus hop, thread or clock read of its own.

Every function here takes the time it runs at (``now``, a batch's ``t``) as an argument and
hands its result back to the caller: the host (:mod:`anunnaki.utu.host`) decides where the
inputs come from (a bus, :meth:`~anunnaki.utu.AutonomicManager.feed`, a replay), when a step
runs and how a stage's output reaches the next stage (a direct call, or a message on the
bus). Import-linter keeps it so: the host imports the cycle, never the other way round.

A cycle visits the stages in a fixed order; each takes the previous one's message and
returns its own (the typed cycle messages of :mod:`anunnaki.bus`)::

    MonitorStage.batch ─MonitorBatch─▶ AnalyzeStage.analyze ─AnalysisState─▶
    ExecuteStage.begin ─ExecuteStatus─▶ PlanStage.plan ─PlanStart─▶
    ExecuteStage.complete ─CycleDone─▶ the step's end (end_step, by the host)

Each stage is entered once per goal update. Execute's two halves frame plan: ``begin``
settles what is in flight (operator calls, outcomes, postconditions, escalation) so that
plan selects among what it left, and ``complete`` starts plan's choice. One
:class:`Planner` holds every tactic's runtime: the execute stage's, handed to the plan
stage of the same process, which writes only the selection fields (nodes in different
processes each keep a copy and ``mirror`` the other's fields from the cycle's messages).

Who owns what, one module each:

* ``_monitor``: which topics are watched; the time of the cycle; each input's arrival time
  (clamped into the cycle's interval, so a burst keeps its spacing);
* ``_analyze``: the goal model's evaluation, inputs and verdicts in Knowledge, node losses
  (an agent's topics expire), the warm-up, the analysis of reloaded files, and whether a
  step took something (its end is marked once execute has acted);
* ``_plan``: selection — when a tactic became eligible, queued/pending/rejected, the
  ``deferred`` reasons, once-per-episode firing;
* ``_execute``: the tactic runtimes (one store), everything once a tactic starts —
  actions, deadlines, cooldowns, attempts, postconditions checked against the analysis,
  escalation (next tactic → fail-safe → run-stop) — and the operator flags (pause,
  run-stop);
* ``_knowledge_stage``: queries, and the decisions written since the last publication;
* ``_entries``: what they share — the markers in Knowledge (the step's end:
  ``end_step``), operator entries, restarts, reloads, and which fields of a tactic's
  runtime plan or execute owns;
* ``_mape``: the parts the stages run — :class:`TopicWatch` (what is known of each monitored
  topic, kept by the analyze stage), :class:`Analyzer`, :class:`Planner`, :class:`Executor`;
* ``_actions``: the :class:`Actuator` actions go through and how an outcome comes back
  (:class:`ActionRunner`, the replay's :class:`ReplayRunner`);
* ``_knowledge``: the store (SQLite, WAL) every stage writes, the single source of truth
  (guideline N8); ``_parts``: loading and checking the files a cycle runs on.

The public names are re-exported by :mod:`anunnaki.utu`.
"""

from anunnaki.utu.cycle._actions import (
    ActionOutcome,
    ActionRunner,
    Actuator,
    Finished,
    RecordedOutcome,
    ReplayRunner,
)
from anunnaki.utu.cycle._analyze import AnalyzeStage
from anunnaki.utu.cycle._execute import ExecuteStage
from anunnaki.utu.cycle._knowledge import Decision, InputRow, Knowledge, TacticRow, VerdictRow
from anunnaki.utu.cycle._knowledge_stage import DecisionTail, KnowledgeStage
from anunnaki.utu.cycle._managers import MANAGERS, baseline
from anunnaki.utu.cycle._mape import Analyzer, Executor, Planner, TacticRuntime, TopicWatch
from anunnaki.utu.cycle._monitor import MonitorStage
from anunnaki.utu.cycle._parts import (
    NodeConfigError,
    UtuParts,
    load_parts,
    load_tactics_text,
    open_knowledge,
)
from anunnaki.utu.cycle._plan import PlanStage

__all__ = [
    "MANAGERS",
    "ActionOutcome",
    "ActionRunner",
    "Actuator",
    "AnalyzeStage",
    "Analyzer",
    "Decision",
    "DecisionTail",
    "ExecuteStage",
    "Executor",
    "Finished",
    "InputRow",
    "Knowledge",
    "KnowledgeStage",
    "MonitorStage",
    "NodeConfigError",
    "PlanStage",
    "Planner",
    "RecordedOutcome",
    "ReplayRunner",
    "TacticRow",
    "TacticRuntime",
    "TopicWatch",
    "UtuParts",
    "VerdictRow",
    "baseline",
    "load_parts",
    "load_tactics_text",
    "open_knowledge",
]
