"""Behavior oracles: per-frame assessments of how the LEC is doing (paper §3.2).

An oracle runs beside the learning-enabled component on the same camera frames and says, for
each frame, which **behavior category** the LEC is in — 0: F1 drop under 5 %, 1: degraded
(over 5 %), 2: compromised (over 10 %), relative to the model's F1 on clean data — and the
**perceived context** (which phenomenon, how strong). Assessments are
:class:`~anunnaki.messages.Assessment` messages on ``/utu/oracle/output``, the topic agent A4
reads in the paper's goal models.

Using one::

    from anunnaki.bus import open_bus
    from anunnaki.lec import load_registry
    from anunnaki.oracles import OracleNode

    registry = load_registry("models/registry.yaml")
    with open_bus("inproc") as bus:
        node = OracleNode(bus, "ground_truth", camera="/uav/camera/image",
                          clean_f1=registry.clean_f1, window=30)

The plugin slot (:class:`Oracle`): anything with a ``name`` and
``assess(frame, *, seq, model_id) -> Assessment | None``; optional hooks
``observe_ground_truth(seq, boxes, labels)``, ``observe_detections(detections)`` and
``observe_context(context)`` and, for a simulator's scorer, ``observe_clean_frame(seq,
frame)`` are fed by the node when an oracle defines them. Every slot takes
a name or an object: the slot :data:`ORACLES` (a :class:`~anunnaki.plugins.Registry`;
``ORACLES.create("ground_truth")`` or an instance). Third parties register a class with
``@ORACLES.register`` or through an entry point in the ``anunnaki.oracles`` group (see
``docs/oracles.md``); so do Enlil's learned oracle (``enlil``) and the ROS bridge's
``light``, from ``pyproject.toml``.

Built-in: ``ground_truth`` (:class:`GroundTruthAssessor`) — sliding-window F1 of the active
model's detections against the simulator's ground truth, turned into a category by the
paper's thresholds; the context is the simulator's phenomena ground truth.
"""

from anunnaki.oracles._base import (
    CLEAR,
    HOOKS,
    Frame,
    ObservesCleanFrames,
    ObservesContext,
    ObservesDetections,
    ObservesGroundTruth,
    ObservesIgnoreBoxes,
    Oracle,
    OracleError,
    context_from_phenomena,
)
from anunnaki.oracles._ground_truth import (
    CleanF1,
    GroundTruthAssessor,
    WindowMetrics,
    category_for_drop,
)
from anunnaki.oracles._node import OracleNode, OracleNodeStats, truth_from_message
from anunnaki.oracles._registry import BUILTIN_ORACLES, ORACLES

__all__ = [
    "BUILTIN_ORACLES",
    "CLEAR",
    "HOOKS",
    "ORACLES",
    "CleanF1",
    "Frame",
    "GroundTruthAssessor",
    "ObservesCleanFrames",
    "ObservesContext",
    "ObservesDetections",
    "ObservesGroundTruth",
    "ObservesIgnoreBoxes",
    "Oracle",
    "OracleError",
    "OracleNode",
    "OracleNodeStats",
    "WindowMetrics",
    "category_for_drop",
    "context_from_phenomena",
    "truth_from_message",
]
