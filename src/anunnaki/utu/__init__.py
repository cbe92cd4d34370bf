"""Utu: the MAPE-K autonomic manager (paper §2.6, §3.4, Fig. 8).

Five parts, composed by :class:`AutonomicManager`:

* :class:`Monitor` takes the messages of every topic the goal model's binding names;
* :class:`Analyzer` evaluates the goal model on every change (incrementally) and selects the
  tactics whose preconditions hold;
* :class:`Planner` keeps the priority-sorted queue (dwell/hysteresis, cooldown, conflicts,
  approvals);
* :class:`Executor` performs actions and checks postconditions by their deadline,
  escalating when one fails;
* :class:`Knowledge` is the single source of truth: model texts, inputs, verdicts,
  decisions and tactic state in SQLite (WAL), surviving a process kill.

``manager.step(now)`` is one deterministic cycle (tests, simulation, replay);
``manager.spin()`` runs live. See docs/utu.md.
"""

from anunnaki.utu._config import RunStopConfig, UtuConfig, load_config, parse_config
from anunnaki.utu._replay import (
    KINDS,
    ReplayReport,
    RunLogError,
    export_trace,
    format_data,
    open_run,
    reading,
    rebuild_goal_state,
    replay,
    run_models,
    run_span,
)
from anunnaki.utu.cycle._actions import (
    ActionOutcome,
    ActionRunner,
    Actuator,
    RecordedOutcome,
    ReplayRunner,
)
from anunnaki.utu.cycle._knowledge import Decision, InputRow, Knowledge, TacticRow, VerdictRow
from anunnaki.utu.cycle._mape import (
    Analyzer,
    Executor,
    Monitor,
    Planner,
    TacticRuntime,
)
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
from anunnaki.utu.host._actuators import BusActuator, RecordingActuator, stop_platform
from anunnaki.utu.host._manager import AutonomicManager
from anunnaki.utu.host._nodes import (
    NODE_NAMES,
    AnalyzeNode,
    ExecuteNode,
    KnowledgeNode,
    MonitorNode,
    NodeName,
    PlanNode,
    UtuNode,
    build_node,
    step_nodes,
)
from anunnaki.utu.host._peers import ACT_ORDER, PeerWatch
from anunnaki.utu.host._threads import ThreadRunner

__all__ = [
    "ACT_ORDER",
    "KINDS",
    "NODE_NAMES",
    "ActionOutcome",
    "ActionRunner",
    "Actuator",
    "AnalyzeNode",
    "AnalyzeStage",
    "Analyzer",
    "AutonomicManager",
    "BusActuator",
    "Decision",
    "DecisionTail",
    "ExecuteNode",
    "ExecuteStage",
    "Executor",
    "InputRow",
    "Knowledge",
    "KnowledgeNode",
    "KnowledgeStage",
    "Monitor",
    "MonitorNode",
    "MonitorStage",
    "NodeConfigError",
    "NodeName",
    "PeerWatch",
    "PlanNode",
    "PlanStage",
    "Planner",
    "RecordedOutcome",
    "RecordingActuator",
    "ReplayReport",
    "ReplayRunner",
    "RunLogError",
    "RunStopConfig",
    "TacticRow",
    "TacticRuntime",
    "ThreadRunner",
    "UtuConfig",
    "UtuNode",
    "UtuParts",
    "VerdictRow",
    "build_node",
    "export_trace",
    "format_data",
    "load_config",
    "load_parts",
    "load_tactics_text",
    "open_knowledge",
    "open_run",
    "parse_config",
    "reading",
    "rebuild_goal_state",
    "replay",
    "run_models",
    "run_span",
    "step_nodes",
    "stop_platform",
]
