"""Utu's host: where the cycle (:mod:`anunnaki.utu.cycle`) meets the bus, threads and clocks.

* ``_nodes``: :class:`UtuNode` on :class:`anunnaki.bus.Node` (liveliness, readiness) and
  the five stage nodes (one process each, or several in one process);
* ``_manager``: :class:`AutonomicManager`, the five stages run inline on one thread, handing
  each other their messages by direct call;
* ``_desk``, ``_host``: what both hosts call, written once — the operator desk, run-stop
  listening and announcement, the watchdog's run-stop, the decisions feed (``_desk``); the
  host's clock, the watchdog around a live loop, a stage's bring-up on a run's knowledge,
  the execute side (actuator, action threads, notifier), the token and readiness of a node
  stood for (``_host``);
* ``_actuators``: how actions reach the managed system (over the bus, or recorded);
* ``_threads``: actions off the loop's path (worker threads);
* ``_intake``, ``_peers``, ``_notify``: the monitored topics' queues and what a step takes
  from them and from ``/clock`` (and a live step's budget), the watch over the nodes of
  other processes, notifications (:class:`Notifier` sends a :class:`Notification` as its
  :class:`NotifyConfig` says: e-mail, webhook or log).

The names :mod:`anunnaki.utu` re-exports are its face; the rest are here.
"""

from anunnaki.topics import UTU_NODES as NODE_NAMES
from anunnaki.topics import UtuNodeName as NodeName
from anunnaki.utu.host._actuators import BusActuator, RecordingActuator, stop_platform
from anunnaki.utu.host._desk import OperatorDesk, Watchdog
from anunnaki.utu.host._manager import AutonomicManager
from anunnaki.utu.host._nodes import (
    NODE_KINDS,
    AnalyzeNode,
    ExecuteNode,
    KnowledgeNode,
    MonitorNode,
    PlanNode,
    UtuNode,
    build_node,
    step_nodes,
)
from anunnaki.utu.host._notify import Notification, Notifier, NotifyConfig
from anunnaki.utu.host._peers import ACT_ORDER, PeerWatch
from anunnaki.utu.host._threads import ThreadRunner

__all__ = [
    "ACT_ORDER",
    "NODE_KINDS",
    "NODE_NAMES",
    "AnalyzeNode",
    "AutonomicManager",
    "BusActuator",
    "ExecuteNode",
    "KnowledgeNode",
    "MonitorNode",
    "NodeName",
    "Notification",
    "Notifier",
    "NotifyConfig",
    "OperatorDesk",
    "PeerWatch",
    "PlanNode",
    "RecordingActuator",
    "ThreadRunner",
    "UtuNode",
    "Watchdog",
    "build_node",
    "step_nodes",
    "stop_platform",
]
