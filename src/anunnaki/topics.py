"""The well-known topics, services and node names, in one place.

Every name that two parts of Anunnaki must agree on is defined here, once, and used from
here (``topics.GROUND_TRUTH``): no module keeps an alias of its own. The messages that
travel on these names are :mod:`anunnaki.messages`; the transport is :mod:`anunnaki.bus`.
Names are in the ROS-style form the files use
(``/utu/oracle/output``); the bus maps them to keys (``anunnaki/utu/oracle/output``,
:func:`anunnaki.bus.ros_to_key`). A managed system's own topics (``/rover/status``) are not
here: they belong to its binding file, so that a goal model moves to another platform by
swapping the binding.

Utu's services and topics (paper §4.1.4, Fig. 13)
    ================================  ==========================================================
    name                              what
    ================================  ==========================================================
    ``/utu/run_stop`` (service/topic)  halt adaptation and stop the managed system (guideline S4)
    ``/utu/pause``, ``/utu/resume``   suspend / resume adaptation (resume clears a run-stop)
    ``/utu/approve``                  approve or reject a tactic that ``requires_approval``
    ``/utu/reload``                   swap in new goal-model, binding or tactics files
    ``/utu/ready``                    readiness of the manager (guideline C9)
    ``/utu/<node>/ready``             readiness of one node (:func:`ready_service`)
    ``/utu/knowledge/query``          decisions, queue, state
    ``/utu/monitor/input``            monitor → analyze: a :class:`~anunnaki.messages.MonitorBatch`
    ``/utu/analyze/state``            the analysis (:class:`~anunnaki.messages.AnalysisState`)
    ``/utu/execute/status``           execute → plan (:class:`~anunnaki.messages.ExecuteStatus`)
    ``/utu/plan/start``               plan → execute (:class:`~anunnaki.messages.PlanStart`)
    ``/utu/execute/done``             execute → analyze, a cycle finished
    ``/utu/knowledge/decisions``      new decisions, for displays and logs
    ``/utu/oracle/output``            behavior assessments (:class:`~anunnaki.messages.Assessment`)
    ================================  ==========================================================
"""

from __future__ import annotations

from typing import Final, Literal

__all__ = [
    "ACTIVE_MODEL",
    "ANALYSIS",
    "APPROVE",
    "ASSURANCE_QUERY",
    "ASSURANCE_STATE",
    "BAG_DECISIONS",
    "CLEAN_FRAMES",
    "CLOCK",
    "CYCLE_DONE",
    "DECISIONS",
    "DETECTIONS",
    "EXECUTE_STATUS",
    "GROUND_TRUTH",
    "LM_MANAGER",
    "MONITOR_INPUT",
    "OPERATOR_SERVICES",
    "ORACLE_OUTPUT",
    "PAUSE",
    "PHENOMENA",
    "PLAN_START",
    "QUERY",
    "READY",
    "RELOAD",
    "RESUME",
    "RUN_STOP",
    "SCORER",
    "SHADOW_ORACLE",
    "SWAP",
    "UTU_NODES",
    "UTU_NODE_PREFIX",
    "UtuNodeName",
    "node_token",
    "operator_service",
    "ready_service",
]

# -- time ------------------------------------------------------------------------------------
#: Simulation time (:class:`~anunnaki.messages.Clock`), from simulators and trace players.
CLOCK: Final = "/clock"

# -- Utu: operator services ------------------------------------------------------------------
RUN_STOP: Final = "/utu/run_stop"
PAUSE: Final = "/utu/pause"
RESUME: Final = "/utu/resume"
APPROVE: Final = "/utu/approve"
RELOAD: Final = "/utu/reload"
READY: Final = "/utu/ready"
QUERY: Final = "/utu/knowledge/query"

#: The operator operations and their services.
OPERATOR_SERVICES: Final[dict[str, str]] = {
    "run_stop": RUN_STOP,
    "pause": PAUSE,
    "resume": RESUME,
    "approve": APPROVE,
    "reload": RELOAD,
}

# -- Utu: between the MAPE-K parts ----------------------------------------------------------
MONITOR_INPUT: Final = "/utu/monitor/input"
ANALYSIS: Final = "/utu/analyze/state"
EXECUTE_STATUS: Final = "/utu/execute/status"
PLAN_START: Final = "/utu/plan/start"
CYCLE_DONE: Final = "/utu/execute/done"
DECISIONS: Final = "/utu/knowledge/decisions"

#: An exported ROS bag carries a run's decisions on this topic (``anunnaki log --export-bag``).
BAG_DECISIONS: Final = "/utu/decisions"

UtuNodeName = Literal["monitor", "analyze", "plan", "execute", "knowledge"]
#: The five Utu nodes, in the order a cycle visits them (knowledge last).
UTU_NODES: Final[tuple[UtuNodeName, ...]] = ("monitor", "analyze", "plan", "execute", "knowledge")

#: Utu's nodes hold liveliness tokens ``/utu_<node>`` (:func:`node_token`): while one is
#: alive, Utu runs.
UTU_NODE_PREFIX: Final = "/utu_"

#: The assurance case's live statuses (``anunnaki run`` with a case; docs/assurance.md).
ASSURANCE_STATE: Final = "/utu/assurance/state"
#: Asks the running case for its statuses now (``{"svg": true}``: with its drawing).
ASSURANCE_QUERY: Final = "/utu/assurance/query"

# -- behavior oracles --------------------------------------------------------------------------
ORACLE_OUTPUT: Final = "/utu/oracle/output"
#: Where a live scorer beside the oracle publishes (not Utu's input: no agent reads it).
SCORER: Final = "/sim/oracle/scorer"
#: Where a shadow oracle publishes: one model's oracle (the default's) assessing every frame
#: whichever model is active, so Utu can tell that model would cope now before swapping to it.
SHADOW_ORACLE: Final = "/utu/oracle/shadow"

# -- the learning model manager ----------------------------------------------------------------
LM_MANAGER: Final = "/lm_manager"
ACTIVE_MODEL: Final = "/lm_manager/active"
SWAP: Final = "/lm_manager/swap"
RELOAD_MODELS: Final = "/lm_manager/reload"  # re-read the model registry (operator token)
DETECTIONS: Final = "/lec/detector/detections"

# -- simulation ground truth (never seen by a real robot's oracle) ----------------------------
#: Ground truth of each frame: ``{seq, t, width, height, boxes, labels}`` (scoring only).
GROUND_TRUTH: Final = "/sim/ground_truth"
#: What the scenario applied to each frame: ``{t, seq, phenomena: [{name, params}], faults}``.
PHENOMENA: Final = "/sim/phenomena"
#: Each camera frame as rendered before the scenario's phenomena (an ``Image``, the camera
#: frame's ``seq``), for a scorer that compares the model on both (``reference: paired``).
CLEAN_FRAMES: Final = "/sim/camera/clean"


def ready_service(node: str) -> str:
    """The readiness service of a Utu node: ``/utu/<node>/ready``."""
    return f"/utu/{node}/ready"


def node_token(node: str) -> str:
    """The liveliness token of a Utu node: ``/utu_<node>``."""
    return f"{UTU_NODE_PREFIX}{node}"


def operator_service(op: str) -> str:
    """The service of an operator operation (``pause`` → ``/utu/pause``)."""
    return OPERATOR_SERVICES[op]
