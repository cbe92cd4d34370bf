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

__all__ = [
    "ActionOutcome",
    "Actuator",
    "Analyzer",
    "AutonomicManager",
    "BusActuator",
    "Decision",
    "Executor",
    "InputRow",
    "Knowledge",
    "Monitor",
    "Planner",
    "RecordingActuator",
    "RunStopConfig",
    "TacticRow",
    "TacticRuntime",
    "UtuConfig",
    "VerdictRow",
    "load_config",
    "load_tactics_text",
    "parse_config",
]
