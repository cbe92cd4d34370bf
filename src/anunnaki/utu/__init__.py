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
from anunnaki.utu._knowledge import Decision, InputRow, Knowledge, TacticRow, VerdictRow
from anunnaki.utu._launch import (
    Launch,
    LaunchConfig,
    RunResult,
    load_launch,
    parse_launch,
    run_launch,
)
from anunnaki.utu._manager import (
    AutonomicManager,
    BusActuator,
    RecordingActuator,
    load_tactics_text,
)
from anunnaki.utu._mape import (
    ActionOutcome,
    Actuator,
    Analyzer,
    Executor,
    Monitor,
    Planner,
    TacticRuntime,
)
from anunnaki.utu._nodes import (
    AnalyzeNode,
    ComposedUtu,
    ExecuteNode,
    KnowledgeNode,
    MonitorNode,
    PlanNode,
    UtuNode,
    UtuParts,
    build_node,
    load_parts,
    step_nodes,
)
from anunnaki.utu._replay import ReplayReport, replay

__all__ = [
    "ActionOutcome",
    "Actuator",
    "AnalyzeNode",
    "Analyzer",
    "AutonomicManager",
    "BusActuator",
    "ComposedUtu",
    "Decision",
    "ExecuteNode",
    "Executor",
    "InputRow",
    "Knowledge",
    "KnowledgeNode",
    "Launch",
    "LaunchConfig",
    "Monitor",
    "MonitorNode",
    "PlanNode",
    "Planner",
    "RecordingActuator",
    "ReplayReport",
    "RunResult",
    "RunStopConfig",
    "TacticRow",
    "TacticRuntime",
    "UtuConfig",
    "UtuNode",
    "UtuParts",
    "VerdictRow",
    "build_node",
    "load_config",
    "load_launch",
    "load_parts",
    "load_tactics_text",
    "parse_config",
    "parse_launch",
    "replay",
    "run_launch",
    "step_nodes",
]
