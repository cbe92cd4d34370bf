"""Learning-enabled components (LECs): the detector interface, the default detector, metrics.

Any model becomes an LEC by implementing :class:`Detector` — ``model_id``, ``classes``,
``domain`` and ``detect(images) -> list[DetectionResult]`` (``uint8`` ``(H, W, 3)`` RGB in,
one result per image out: ``boxes [N, 4]`` ``float32`` xyxy pixels, ``labels [N]`` ``int64``,
``scores [N]`` ``float32`` in [0, 1]). The LEC node, the model manager and the assessors use
nothing else.

The default LEC is :class:`CenterNetDetector`, a compact CenterNet-style heat-map detector
in plain PyTorch (``anunnaki train-detector``). Model files are safe: safetensors weights plus
a JSON sidecar with the architecture, classes, input size, score threshold, domain, metrics
and the weights' sha256; :func:`load_detector` checks the hash before reading any tensor and
never unpickles anything::

    from anunnaki.lec import load_detector, f1_at_iou

    det = load_detector("examples/models/rover-default.safetensors")
    results = det.detect(frames)                      # list[DetectionResult]
    m = f1_at_iou(results, truths, score_threshold=0.0)   # Metrics(precision, recall, f1, …)

A model is named as the commands name it — a model file, or a registry and an id, whatever
loader plugin the entry names — with :func:`resolve_model` (``.load()`` gives the detector);
:func:`shared_classes` cuts a detector and a dataset to the class names both have, to measure
e.g. a person detector on data that also labels deer.

The F1 rule used everywhere (``docs/detector.md``): class-aware greedy matching in
descending score order at IoU ≥ 0.5, each truth matched at most once, the score threshold
chosen on the validation split (:func:`choose_threshold`) and F1 reported on the test split.
Under a phenomenon that hides objects (a raindrop), :func:`hide_boxes` makes a box at least
half hidden an ignore box, in training and in :func:`evaluate_visible` (F1 on all boxes and
on the visible ones, and the ceiling a perfect detector of the visible boxes reaches).

Importing this package needs numpy and pydantic only; torch is imported when a CenterNet is
built, loaded or trained (the ``vision`` extra). It sets ``OMP_WAIT_POLICY=PASSIVE`` unless
set (see the comment in the source): inference shares the CPU with other nodes.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any

# OpenMP threads that spin while they wait make a CPU shared with other processes (a robot's
# other nodes, a test suite) several times slower: measured on the 2-core dev machine under
# load 6, two spinning threads cost 5x the CPU of one and took 2x longer per training step
# than one thread; with passive waiting two threads took a third of the one-thread time.
# Set here, before any submodule imports torch; effective only if torch is not loaded yet,
# and a value the user set wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from anunnaki.lec._detector import (
    ARCHITECTURES,
    SIDECAR_FORMAT,
    BuildsFromCard,
    DetectionResult,
    Detector,
    DetectorArchitecture,
    DetectorError,
    DetectorLoadError,
    ImageBatch,
    ModelCard,
    ReadsFiles,
    architecture_files,
    as_image_list,
    load_detector,
    read_card,
    save_detector,
    sha256_file,
    sidecar_path,
    update_metrics,
    weights_path,
)
from anunnaki.lec._hidden import box_occlusion, hide_boxes
from anunnaki.lec._metrics import (
    Metrics,
    Truth,
    box_iou,
    choose_threshold,
    f1_at_iou,
    match_image,
)
from anunnaki.lec._node import (
    LecNode,
    LecNodeStats,
    ReloadResult,
    SwapResult,
    decode_image,
    detections_topic,
)
from anunnaki.lec._register import check_registrable, register_model
from anunnaki.lec._registry import (
    DEFAULT_DOMAIN,
    REGISTRY_FORMAT,
    ModelIntegrityError,
    ModelLoadError,
    ModelRegistry,
    ModelRegistryError,
    ModelSpec,
    OracleRef,
    UnknownModelError,
)
from anunnaki.lec._registry_file import ResolvedModel, load_registry, parse_registry, resolve_model
from anunnaki.lec._registry_reload import RegistryChange

if TYPE_CHECKING:
    from anunnaki.lec._centernet import CenterNet, CenterNetArchitecture, CenterNetDetector
    from anunnaki.lec._recipe import CandidatePerturb
    from anunnaki.lec._train import (
        Augmenter,
        EpochHook,
        Perturb,
        SharedClassesDetector,
        TrainConfig,
        TrainResult,
        TrainState,
        class_map,
        evaluate_detector,
        predict,
        shared_classes,
        train_detector,
    )
    from anunnaki.lec._visible import VisibleMetrics, evaluate_visible

__all__ = [
    "ARCHITECTURES",
    "DEFAULT_DOMAIN",
    "REGISTRY_FORMAT",
    "SIDECAR_FORMAT",
    "Augmenter",
    "BuildsFromCard",
    "CandidatePerturb",
    "CenterNet",
    "CenterNetArchitecture",
    "CenterNetDetector",
    "DetectionResult",
    "Detector",
    "DetectorArchitecture",
    "DetectorError",
    "DetectorLoadError",
    "EpochHook",
    "ImageBatch",
    "LecNode",
    "LecNodeStats",
    "Metrics",
    "ModelCard",
    "ModelIntegrityError",
    "ModelLoadError",
    "ModelRegistry",
    "ModelRegistryError",
    "ModelSpec",
    "OracleRef",
    "Perturb",
    "ReadsFiles",
    "RegistryChange",
    "ReloadResult",
    "ResolvedModel",
    "SharedClassesDetector",
    "SwapResult",
    "TrainConfig",
    "TrainResult",
    "TrainState",
    "Truth",
    "UnknownModelError",
    "VisibleMetrics",
    "architecture_files",
    "as_image_list",
    "box_iou",
    "box_occlusion",
    "check_registrable",
    "choose_threshold",
    "class_map",
    "decode_image",
    "detections_topic",
    "evaluate_detector",
    "evaluate_visible",
    "f1_at_iou",
    "hide_boxes",
    "load_detector",
    "load_registry",
    "match_image",
    "parse_registry",
    "predict",
    "read_card",
    "register_model",
    "resolve_model",
    "save_detector",
    "sha256_file",
    "shared_classes",
    "sidecar_path",
    "train_detector",
    "update_metrics",
    "weights_path",
]

_LAZY = {
    "CandidatePerturb": "anunnaki.lec._recipe",
    "CenterNet": "anunnaki.lec._centernet",
    "CenterNetArchitecture": "anunnaki.lec._centernet",
    "CenterNetDetector": "anunnaki.lec._centernet",
    "Augmenter": "anunnaki.lec._train",
    "EpochHook": "anunnaki.lec._train",
    "SharedClassesDetector": "anunnaki.lec._train",
    "shared_classes": "anunnaki.lec._train",
    "TrainConfig": "anunnaki.lec._train",
    "TrainResult": "anunnaki.lec._train",
    "TrainState": "anunnaki.lec._train",
    "Perturb": "anunnaki.lec._train",
    "class_map": "anunnaki.lec._train",
    "evaluate_detector": "anunnaki.lec._train",
    "predict": "anunnaki.lec._train",
    "train_detector": "anunnaki.lec._train",
    "VisibleMetrics": "anunnaki.lec._visible",
    "evaluate_visible": "anunnaki.lec._visible",
}


def __getattr__(name: str) -> Any:
    """Import the torch-based names on first use (``import anunnaki.lec`` stays light)."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'anunnaki.lec' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value
