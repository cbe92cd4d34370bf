"""Utu's cycle, once: Monitor → Analyze → Plan → Execute over Knowledge.

The cycle has no bus hop, thread or clock read of its own.

Every function here takes the time it runs at (``now``, a batch's ``t``) as an argument and
hands its result back to the caller: the host (:mod:`anunnaki.utu.host`) decides where the
inputs come from (a bus, :meth:`~anunnaki.utu.AutonomicManager.feed`, a replay), when a step
runs and how a stage's output reaches the next stage (a direct call, or a message on the
bus). Import-linter keeps it so: the host imports the cycle, never the other way round.

* ``_mape``: the parts — :class:`Monitor`, :class:`Analyzer`, :class:`Planner`,
  :class:`Executor` (and the :class:`Actuator` they act through);
* ``_actions``: how an action's outcome comes back (:class:`ActionRunner`, the replay's
  :class:`ReplayRunner`);
* ``_stages``: the five stages a host runs — one cycle's work of each part, exchanging the
  typed cycle messages (``MonitorBatch``, ``AnalysisState``, ``ExecuteStatus``,
  ``PlanStart``, ``CycleDone``), and the operator entries they apply;
* ``_knowledge``: the store (SQLite, WAL) every stage writes;
* ``_parts``: loading and checking the files a cycle runs on.

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
from anunnaki.utu.cycle._knowledge import Decision, InputRow, Knowledge, TacticRow, VerdictRow
from anunnaki.utu.cycle._mape import Analyzer, Executor, Monitor, Planner, TacticRuntime
from anunnaki.utu.cycle._parts import (
    NodeConfigError,
    UtuParts,
    load_parts,
    load_tactics_text,
    open_knowledge,
)
from anunnaki.utu.cycle._stages import (
    AnalyzeStage,
    DecisionTail,
    ExecuteStage,
    KnowledgeStage,
    MonitorStage,
    PlanStage,
)

__all__ = [
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
    "Monitor",
    "MonitorStage",
    "NodeConfigError",
    "PlanStage",
    "Planner",
    "RecordedOutcome",
    "ReplayRunner",
    "TacticRow",
    "TacticRuntime",
    "UtuParts",
    "VerdictRow",
    "load_parts",
    "load_tactics_text",
    "open_knowledge",
]
