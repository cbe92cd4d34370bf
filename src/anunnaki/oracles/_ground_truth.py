"""The ``ground_truth`` assessor: the LEC's behavior measured against a simulator's truth.

Before Enlil has built a behavior oracle, the simulator knows the answer: it publishes every
object in every frame (``/sim/ground_truth``) and which phenomena are active
(``/sim/phenomena``). This assessor matches the active model's published detections to that
truth, frame by frame, and turns the F1 over a sliding window into the paper's behavior
category (§4.1.2), relative to the model's F1 on clean data::

    drop = (clean_f1 - window_f1) / clean_f1          (0 when the window does better)
    category = 2 if drop > 10 %  else  1 if drop > 5 %  else  0        (thresholds configurable)
    confidence = frames in the window / window size
    context = the phenomena ground truth, e.g. {"phenomenon": "fog", "params": {...}}

Where ``clean_f1`` comes from is the ``reference``:

* ``clean_f1`` (the default): one number per model, its F1 on clean data as given (the model
  registry's: its test split's). It is measured on other images than the window's: a
  simulated flight whose frames are easier than the test split (the UAV demo's: uav-fog 0.95
  on the flight's frames without fog, 0.894 on its test split) understates every drop.
* ``paired``: the same model's F1 over the same window of frames *as rendered without the
  phenomena* (the simulator's clean frames, ``topics.CLEAN_FRAMES``; the assessor runs the
  model on them itself, loaded from ``models``): the drop is the phenomena's alone, as
  Enlil labels a context (the same batch, clean and perturbed). Simulation only. A frame
  whose clean render is the camera frame pixel for pixel (no phenomenon, no fault) is not
  run again: the model's published detections of it are what the run would give (the
  same network on the same pixels), so they are counted for both.

With ``min_objects``, a window holding fewer labelled objects shows no drop: by default
(``sparse: nominal``) it is assessed as category 0 with its confidence scaled down, which
keeps an agent bound to the assessor fresh; ``sparse: withhold`` publishes nothing for it,
as a live scorer should (a window with nothing to find is no evidence of either category,
and an oracle compared with it would be marked against a guess).

The rule of a match is the detector's own (``anunnaki.lec.f1_at_iou``): per frame,
class-aware greedy matching in descending score order at IoU ≥ 0.5, and a detection that
matches nothing but lies mostly inside one of the frame's *ignore boxes* (objects seen but
not labelled: too small, occluded, cut by the frame — given to ``observe_ground_truth`` as
``ignore=``, e.g. from an ``"ignore"`` list in the ground-truth message) counts neither
way; counts are summed over the window before F1 is computed. Frames are matched by
sequence number, whatever order the truth and the detections arrive in. The window holds
one model's frames only: when detections of another model arrive (a swap), it starts
afresh.
"""

from __future__ import annotations

import logging
import math
import threading
from collections import OrderedDict, deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from pydantic import JsonValue

from anunnaki.lec import DetectionResult, Detector, ModelRegistry, match_image
from anunnaki.messages import Assessment, Detections
from anunnaki.oracles._base import Frame, OracleError

__all__ = [
    "CleanF1",
    "GroundTruthAssessor",
    "Reference",
    "Sparse",
    "WindowMetrics",
    "category_for_drop",
]

log = logging.getLogger("anunnaki.oracles")

#: Where the clean F1 of a model comes from: one number for every model, a mapping from model
#: id, or a function (e.g. ``ModelRegistry.clean_f1``) returning ``None`` when unknown.
CleanF1 = float | Mapping[str, float] | Callable[[str], float | None]
#: What a window's F1 is compared against: the model's clean F1 as given, or the model's F1
#: on the same frames rendered without the phenomena (a simulator's clean frames).
Reference = Literal["clean_f1", "paired"]
#: A window with fewer than ``min_objects`` objects: category 0 at a lower confidence, or
#: no assessment.
Sparse = Literal["nominal", "withhold"]


def category_for_drop(drop: float, thresholds: tuple[float, float] = (0.05, 0.10)) -> int:
    """Map a relative F1 drop to a behavior category (paper §4.1.2).

    ``drop <= thresholds[0]`` → 0 (no impact), ``> thresholds[0]`` → 1 (degraded),
    ``> thresholds[1]`` → 2 (compromised).
    """
    degraded, compromised = thresholds
    if drop > compromised:
        return 2
    if drop > degraded:
        return 1
    return 0


@dataclass(frozen=True)
class WindowMetrics:
    """The sliding window's figures.

    Attributes:
        model_id: The model the window is about.
        frames: Frames in the window.
        tp: True positives summed over the window.
        fp: False positives.
        fn: False negatives.
        f1: ``2 tp / (2 tp + fp + fn)`` (1.0 when there was nothing to find or predict).
        clean_f1: With ``reference: paired``, the same model's F1 over the same frames as
            rendered without the phenomena (1.0 likewise); ``None`` otherwise.

    """

    model_id: str
    frames: int
    tp: int
    fp: int
    fn: int
    f1: float
    clean_f1: float | None = None


class GroundTruthAssessor:
    """Behavior categories from the simulator's ground truth (the ``ground_truth`` oracle).

    Args:
        clean_f1: The models' F1 on clean data (see :data:`CleanF1`); pass
            ``registry.clean_f1`` to take it from the model registry's metrics. A model whose
            clean F1 is unknown gets no assessment (logged once).
        window: Frames in the sliding window (N).
        min_frames: Frames needed before the first assessment (default ``window // 3``,
            at least 1).
        thresholds: Relative F1 drops above which a model is degraded (category 1) and
            compromised (category 2).
        iou: IoU a detection needs to match a truth.
        score_threshold: Detections scoring lower are ignored (published detections are
            already thresholded by their detector, hence 0).
        buffer: Frames kept while waiting for their other parts (truth, detections and,
            paired, the clean render; default ``4 * window``), the oldest dropped first.
        min_objects: Labelled objects the window needs before an F1 drop is believed: with
            fewer, one or two misses swing the F1 by tens of percent, so the assessment is
            category 0 (no drop shown) with its confidence scaled by ``objects /
            min_objects`` (or none: ``sparse``). 0 (the default) always believes the window.
        sparse: What a window with fewer than ``min_objects`` objects gets: ``nominal``
            (category 0, lower confidence) or ``withhold`` (no assessment: a live scorer's
            choice, so that an oracle is compared only where there was evidence).
        reference: What the window's F1 is compared against: ``clean_f1`` (the model's clean
            F1 as given) or ``paired`` (the model's F1 on the window's frames as rendered
            without the phenomena; needs ``models`` and a simulator that publishes its clean
            frames, ``topics.CLEAN_FRAMES``).
        models: With ``reference: paired``, where the assessed models come from: the
            detector's :class:`~anunnaki.lec.ModelRegistry` (each model is loaded once, its
            sha256 checked) or a function from model id to a loaded
            :class:`~anunnaki.lec.Detector`.

    """

    #: ``observe_ground_truth`` takes ``ignore=`` (:class:`~anunnaki.oracles.ObservesIgnoreBoxes`).
    ignore_boxes = True

    name: str = "ground_truth"

    def __init__(
        self,
        *,
        clean_f1: CleanF1 | None = None,
        window: int = 30,
        min_frames: int | None = None,
        thresholds: tuple[float, float] = (0.05, 0.10),
        iou: float = 0.5,
        score_threshold: float = 0.0,
        buffer: int | None = None,
        min_objects: int = 0,
        sparse: Sparse = "nominal",
        reference: Reference = "clean_f1",
        models: ModelRegistry | Callable[[str], Detector] | None = None,
    ) -> None:
        if not isinstance(window, int) or window < 1:
            raise OracleError(f"window must be a whole number of frames >= 1, got {window!r}")
        self.window = window
        self.min_frames = max(1, window // 3) if min_frames is None else int(min_frames)
        if not 1 <= self.min_frames <= window:
            raise OracleError(f"min_frames must be in [1, window={window}], got {min_frames}")
        low, high = (float(t) for t in thresholds)
        if not (0.0 <= low <= high < 1.0):
            raise OracleError(
                f"thresholds must be two drops 0 <= degraded <= compromised < 1, got {thresholds}"
            )
        self.thresholds = (low, high)
        if not 0.0 < iou <= 1.0:
            raise OracleError(f"iou must be in (0, 1], got {iou}")
        self.iou = float(iou)
        self.score_threshold = float(score_threshold)
        self.buffer = 4 * window if buffer is None else int(buffer)
        if not isinstance(min_objects, int) or min_objects < 0:
            raise OracleError(f"min_objects must be a whole number >= 0, got {min_objects!r}")
        self.min_objects = min_objects
        if sparse not in ("nominal", "withhold"):
            raise OracleError(
                f"sparse must be 'nominal' (category 0 at a lower confidence) or 'withhold' "
                f"(no assessment), got {sparse!r}"
            )
        self.sparse: Sparse = sparse
        if reference not in ("clean_f1", "paired"):
            raise OracleError(
                f"reference must be 'clean_f1' (the model's clean F1 as given) or 'paired' "
                f"(the same frames rendered without the phenomena), got {reference!r}"
            )
        if reference == "paired" and models is None:
            raise OracleError(
                "reference 'paired' runs the assessed model on each frame's clean render: give "
                "models= (the detector's model registry; a launch file's camera chain passes it)"
            )
        self.reference: Reference = reference
        #: ``ObservesCleanFrames``: the node feeds the clean frames only to a paired assessor.
        self.clean_frames = reference == "paired"
        self._models = models
        self._detectors: dict[str, Detector] = {}
        self._clean = clean_f1
        self._lock = threading.Lock()
        # frames waiting for their other parts: "truth" (boxes, names, ignore), "dets" and,
        # paired, "clean" (the frame as rendered without the phenomena)
        self._pending: OrderedDict[int, dict[str, Any]] = OrderedDict()
        # per frame: tp, fp, fn on the frame, then (paired) on its clean render; a frame
        # whose "clean" part is the camera frame itself (``assess`` compared the pixels)
        # has "same" set, and its detections stand for the clean run of the model
        self._counts: deque[tuple[int, ...]] = deque(maxlen=window)
        self._model: str | None = None
        self._context: dict[str, JsonValue] | None = None
        self._warned: set[str] = set()

    @classmethod
    def options_from_models(cls, models: ModelRegistry) -> dict[str, Any]:
        """Take the assessed detector's registry: its clean F1s and models (``TakesModels``).

        The models are loaded only with ``reference: paired``.
        """
        return {"clean_f1": models.clean_f1, "models": models}

    def __repr__(self) -> str:
        return (
            f"GroundTruthAssessor(window={self.window}, thresholds={self.thresholds}, "
            f"iou={self.iou}, reference={self.reference!r})"
        )

    # -- hooks -------------------------------------------------------------------------------
    def observe_ground_truth(
        self,
        seq: int,
        boxes: npt.ArrayLike,
        labels: Sequence[str] | None,
        ignore: npt.ArrayLike | None = None,
    ) -> None:
        """Take the simulator's objects in frame ``seq`` (``[N, 4]`` xyxy px, class names).

        ``ignore``: the frame's ``[K, 4]`` ignore boxes (``anunnaki.sim.Frame.ignore``),
        where a detection that matches no object is not counted as a false positive.
        """
        array = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
        skip = np.asarray([] if ignore is None else ignore, dtype=np.float64).reshape(-1, 4)
        names = None if labels is None else [str(x) for x in labels]
        if names is not None and len(names) != len(array):
            raise OracleError(
                f"ground truth of frame {seq}: {len(array)} boxes but {len(names)} labels"
            )
        self._offer(seq, "truth", (array, names, skip))

    def observe_detections(self, detections: Detections) -> None:
        """Take what the LEC published for one frame."""
        self._offer(detections.frame_seq, "dets", detections)

    def observe_clean_frame(self, seq: int, frame: Frame) -> None:
        """Take frame ``seq`` as rendered without the phenomena (``reference: paired``).

        The model that handled the frame is run on it when the frame's detections and truth
        are in (``ObservesCleanFrames``; the node sends them only to a paired assessor).
        """
        if self.reference == "paired":
            self._offer(seq, "clean", frame)

    def observe_context(self, context: dict[str, JsonValue]) -> None:
        """Take the phenomena ground truth (reported as the assessments' context)."""
        with self._lock:
            self._context = dict(context)

    def _offer(self, seq: int, part: str, value: Any) -> None:
        """Keep one part of frame ``seq``; score the frame once it has every part."""
        needed = ("truth", "dets", "clean") if self.reference == "paired" else ("truth", "dets")
        with self._lock:
            entry = self._pending.setdefault(seq, {})
            entry[part] = value
            if all(k in entry for k in needed):
                del self._pending[seq]
                self._score(
                    entry["dets"],
                    *entry["truth"],
                    clean=entry.get("clean"),
                    same=entry.get("same", False),
                )
                return
            while len(self._pending) > self.buffer:
                self._pending.popitem(last=False)

    def _note_same(self, seq: int, frame: Frame) -> None:
        """Mark frame ``seq`` when its clean render, already in, has the same pixels."""
        with self._lock:
            entry = self._pending.get(seq)
            if entry is None or "clean" not in entry:
                return
            if np.array_equal(np.asarray(entry["clean"]), np.asarray(frame)):
                entry["same"] = True

    def _detector(self, model_id: str) -> Detector:
        """The assessed model, loaded once (``reference: paired``)."""
        detector = self._detectors.get(model_id)
        if detector is None:
            source = self._models
            assert source is not None  # checked in __init__
            detector = (
                source.load(model_id) if isinstance(source, ModelRegistry) else source(model_id)
            )
            self._detectors[model_id] = detector
        return detector

    def _score(
        self,
        dets: Detections,
        boxes: npt.NDArray[np.float64],
        names: list[str] | None,
        ignore: npt.NDArray[np.float64],
        *,
        clean: Frame | None = None,
        same: bool = False,
    ) -> None:
        if dets.model_id != self._model:
            self._model = dets.model_id
            self._counts.clear()
        pred = DetectionResult(
            np.asarray(dets.boxes, np.float32).reshape(-1, 4),
            np.zeros(len(dets.labels), np.int64),
            np.asarray(dets.scores, np.float32),
        )
        counts: tuple[int, ...] = self._match(pred, list(dets.labels), boxes, names, ignore)
        if same:  # the clean render is the frame the model ran on: the same detections
            counts += counts
        elif clean is not None:
            detector = self._detector(dets.model_id)
            found = detector.detect([clean])[0]
            classes = list(detector.classes)
            counts += self._match(
                found, [classes[int(k)] for k in found.labels], boxes, names, ignore
            )
        self._counts.append(counts)

    def _match(
        self,
        pred: DetectionResult,
        pred_names: list[str],
        boxes: npt.NDArray[np.float64],
        names: list[str] | None,
        ignore: npt.NDArray[np.float64],
    ) -> tuple[int, int, int]:
        """``(tp, fp, fn)`` of one frame's predictions (labels given by ``pred_names``)."""
        vocab: dict[str, int] = {}
        if names is None:  # the truth's classes are unknown: match class-agnostically
            pred_labels = np.zeros(len(pred_names), np.int64)
            true_labels = np.zeros(len(boxes), np.int64)
        else:
            true_labels = np.array([vocab.setdefault(n, len(vocab)) for n in names], np.int64)
            pred_labels = np.array([vocab.setdefault(n, len(vocab)) for n in pred_names], np.int64)
        pred = DetectionResult(pred.boxes, pred_labels, pred.scores).above(self.score_threshold)
        _, is_tp, n_truth = match_image(pred, boxes, true_labels, iou=self.iou, ignore=ignore)
        tp = int(is_tp.sum())
        return tp, len(is_tp) - tp, n_truth - tp

    # -- assessing ---------------------------------------------------------------------------
    def metrics(self) -> WindowMetrics | None:
        """The window's figures now, or ``None`` before the first matched frame."""
        with self._lock:
            if self._model is None or not self._counts:
                return None
            tp, fp, fn, *clean = (sum(column) for column in zip(*self._counts, strict=True))
            return WindowMetrics(
                self._model,
                len(self._counts),
                tp,
                fp,
                fn,
                _f1(tp, fp, fn),
                _f1(*clean) if clean else None,
            )

    def clean_f1(self, model_id: str) -> float | None:
        """The clean F1 this assessor compares ``model_id`` against (``None``: unknown)."""
        source = self._clean
        value: float | None = None
        if isinstance(source, bool) or source is None:
            value = None
        elif isinstance(source, int | float):
            value = float(source)
        elif isinstance(source, Mapping):
            raw = source.get(model_id)
            value = None if raw is None else float(raw)
        elif callable(source):
            value = source(model_id)
        if value is None or not math.isfinite(value) or value <= 0.0:
            return None
        return value

    def assess(self, frame: Frame, *, seq: int, model_id: str) -> Assessment | None:
        """Assess ``model_id`` from the window (the frame's pixels are not assessed).

        Returns ``None`` until the window holds ``min_frames`` frames of ``model_id``, for a
        model whose clean F1 is unknown, and (``sparse: withhold``) for a window with fewer
        than ``min_objects`` objects.

        With ``reference: paired``, the frame is compared with its clean render when that
        came first (a simulator publishes it before the camera frame): equal pixels spare
        the model's second run on it (the frame's detections count for both).
        """
        if self.reference == "paired":
            self._note_same(seq, frame)
        window = self.metrics()
        if window is None or window.model_id != model_id or window.frames < self.min_frames:
            return None
        objects = window.tp + window.fn
        if objects < self.min_objects and self.sparse == "withhold":
            return None
        clean = window.clean_f1 if self.reference == "paired" else self.clean_f1(model_id)
        if clean is None:
            if model_id not in self._warned:
                self._warned.add(model_id)
                log.warning(
                    "ground_truth: no clean F1 for model %r (give clean_f1, or metrics "
                    "{f1: …} in the model registry); it is not assessed",
                    model_id,
                )
            return None
        # a model that finds nothing even on the clean frames cannot drop (paired)
        drop = max(0.0, (clean - window.f1) / clean) if clean > 0 else 0.0
        confidence = min(1.0, window.frames / self.window)
        if objects < self.min_objects:  # too little evidence to tell a drop
            drop = 0.0
            confidence *= objects / self.min_objects
        with self._lock:
            context: dict[str, JsonValue] = dict(self._context or {})
        return Assessment(
            category=category_for_drop(drop, self.thresholds),
            confidence=confidence,
            context=context,
            model_id=model_id,
            assessor=self.name,
            frame_seq=seq,
        )


def _f1(tp: int, fp: int, fn: int) -> float:
    """``2 tp / (2 tp + fp + fn)``; 1.0 with nothing to find and nothing found."""
    return 2 * tp / (2 * tp + fp + fn) if tp + fp + fn else 1.0
