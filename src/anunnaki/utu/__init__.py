"""Utu: the MAPE-K autonomic manager (paper §2.6, §3.4, Fig. 8).

Five parts, composed by :class:`AutonomicManager`:

* the monitor takes the messages of every topic the goal model's binding names, stamps each
  cycle, and keeps in a :class:`TopicWatch` what is known of each topic (freshness, last
  value, rate);
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

Configuration: :class:`UtuConfig` (``anunnaki: utu/1``), read by :func:`load_config` or
:func:`parse_config`. Actions reach the managed system through an :class:`Actuator`
(:class:`BusActuator` live, :class:`RecordingActuator` in tests and replay), each giving
an :class:`ActionOutcome`. One process per part: :func:`build_node` brings up the node
:class:`UtuNode` called one of :data:`NODE_NAMES`; bad configuration raises
:class:`NodeConfigError`. After a run, :func:`replay` repeats its decision log
(:class:`ReplayReport`; an unreadable log raises :class:`RunLogError`).

For the launcher and the CLI, which wire Utu into a run: the files a manager runs on
(:class:`UtuParts`, read by :func:`load_parts`), its knowledge (:func:`open_knowledge`, the
rows :class:`VerdictRow`, the decisions feed :class:`DecisionTail`), the managers a run may
choose (:data:`MANAGERS`: ``utu`` and the ``none``/``random`` baselines), the names of the
five nodes (:data:`NodeName`) and the order in which their survivors act
(:data:`ACT_ORDER`, :class:`PeerWatch`), the notifier's configuration (:class:`NotifyConfig`)
and :func:`stop_platform` (a run-stop from outside the loop).

Two rooms below this face, each with its own: :mod:`anunnaki.utu.cycle` (the cycle once:
parts, stages, knowledge rows, loading the files) and :mod:`anunnaki.utu.host` (where it
meets the bus: the nodes, the inline manager, the operator desk, the watchdog); reading a
run's log is :mod:`anunnaki.utu.runlog`. Only this package imports them (an import-linter
contract holds it): everything above Utu takes its names from here.
"""

from anunnaki.utu._config import RunStopConfig, UtuConfig, load_config, parse_config
from anunnaki.utu._replay import ReplayReport, RunLogError, replay
from anunnaki.utu.cycle import (
    MANAGERS,
    ActionOutcome,
    Actuator,
    Analyzer,
    Decision,
    DecisionTail,
    Executor,
    Knowledge,
    NodeConfigError,
    Planner,
    TopicWatch,
    UtuParts,
    VerdictRow,
    load_parts,
    open_knowledge,
)
from anunnaki.utu.host import (
    ACT_ORDER,
    NODE_NAMES,
    AutonomicManager,
    BusActuator,
    NodeName,
    NotifyConfig,
    PeerWatch,
    RecordingActuator,
    UtuNode,
    build_node,
    stop_platform,
)

__all__ = [
    "ACT_ORDER",
    "MANAGERS",
    "NODE_NAMES",
    "ActionOutcome",
    "Actuator",
    "Analyzer",
    "AutonomicManager",
    "BusActuator",
    "Decision",
    "DecisionTail",
    "Executor",
    "Knowledge",
    "NodeConfigError",
    "NodeName",
    "NotifyConfig",
    "PeerWatch",
    "Planner",
    "RecordingActuator",
    "ReplayReport",
    "RunLogError",
    "RunStopConfig",
    "TopicWatch",
    "UtuConfig",
    "UtuNode",
    "UtuParts",
    "VerdictRow",
    "build_node",
    "load_config",
    "load_parts",
    "open_knowledge",
    "parse_config",
    "replay",
    "stop_platform",
]
