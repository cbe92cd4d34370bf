"""F1 on all boxes and on the visible ones: a perturbation that hides objects, measured fairly.

Under a phenomenon with an occlusion mask (a raindrop on the lens), some labelled objects are
no longer in the picture. :func:`evaluate_visible` measures a detector once and reports:

* ``all`` — every labelled box counts, as :func:`anunnaki.lec.evaluate_detector` does;
* ``visible`` — a box at least :data:`anunnaki.phenomena.HIDDEN` hidden is an ignore box
  (:func:`anunnaki.lec.hide_boxes`): not a miss, and a detection on it no false positive;
* ``ceiling`` — the F1 on all boxes of a detector that finds every visible box and nothing
  else: what a drop leaves to be found. A model at the ceiling has lost nothing that was
  still there.

A phenomenon without a mask hides nothing: ``visible`` and ``ceiling`` are ``None``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from anunnaki.datasets import Dataset
from anunnaki.lec._detector import DetectionResult, Detector
from anunnaki.lec._hidden import hide_boxes
from anunnaki.lec._metrics import Metrics, f1_at_iou
from anunnaki.lec._train import Image, class_map, phenomenon_params, predict
from anunnaki.phenomena import HIDDEN, Mask, Phenomenon

__all__ = ["VisibleMetrics", "evaluate_visible"]


@dataclass(frozen=True)
class VisibleMetrics:
    """A detector measured under a phenomenon, on all boxes and on the visible ones.

    Attributes:
        all: Every labelled box counts.
        visible: Hidden boxes are ignore boxes (``None``: the phenomenon has no mask).
        ceiling: F1 on all boxes of a detector that finds exactly the visible boxes
            (``None``: no mask).
        boxes: Labelled boxes.
        hidden: Of them, hidden (mean occlusion at least ``threshold``).
        threshold: The hidden threshold used.

    """

    all: Metrics
    visible: Metrics | None
    ceiling: float | None
    boxes: int
    hidden: int
    threshold: float = HIDDEN

    def as_dict(self) -> dict[str, Any]:
        """JSON-safe: the two metrics side by side, the ceiling and the counts."""
        return {
            "all": self.all.as_dict(),
            "visible": None if self.visible is None else self.visible.as_dict(),
            "ceiling_f1": self.ceiling,
            "boxes": self.boxes,
            "hidden_boxes": self.hidden,
            "hidden_threshold": self.threshold,
        }


def evaluate_visible(
    det: Detector,
    data: Dataset,
    *,
    phenomenon: str | Phenomenon,
    params: dict[str, float] | None = None,
    strength: float | None = None,
    seed: int = 0,
    score_threshold: float | None = None,
    iou: float = 0.5,
    batch_size: int = 32,
    threshold: float = HIDDEN,
) -> VisibleMetrics:
    """Measure *det* on *data* under *phenomenon*, on all boxes and on the visible ones.

    The arguments are :func:`anunnaki.lec.evaluate_detector`'s (image *i* gets the
    phenomenon with seed ``seed + i``, and ``all`` is the figure that function gives);
    *threshold* is the mean occlusion from which a box is hidden.

    Raises:
        DetectorError: As :func:`anunnaki.lec.evaluate_detector`.

    """
    phen, chosen = phenomenon_params(phenomenon, params, strength)
    masks: dict[int, Mask | None] = {}

    def transform(i: int, image: Image) -> Image:
        masks[i] = phen.occlusion(image.shape, chosen, seed + i)
        return phen.apply(image, chosen, seed=seed + i)

    remap = class_map(det, data)
    thr = score_threshold
    if thr is None:
        thr = float(getattr(det, "score_threshold", 0.0))
    preds = predict(det, data, batch_size=batch_size, transform=transform)
    if remap is not None:
        preds = [DetectionResult(p.boxes, remap[p.labels], p.scores) for p in preds]
    truths = data.truths()
    every = f1_at_iou(preds, truths, iou=iou, score_threshold=thr)
    n_boxes = sum(len(np.asarray(t[1]).reshape(-1)) for t in truths)
    if all(m is None for m in masks.values()):
        return VisibleMetrics(every, None, None, n_boxes, 0, threshold)
    seen = [
        hide_boxes(t[0], t[1], t[2], masks[i], threshold=threshold) for i, t in enumerate(truths)
    ]
    visible = f1_at_iou(preds, seen, iou=iou, score_threshold=thr)
    perfect = [_exactly(b, lab) for b, lab, _ in seen]
    ceiling = f1_at_iou(perfect, truths, iou=iou, score_threshold=0.5).f1
    hidden = n_boxes - sum(len(lab) for _, lab, _ in seen)
    return VisibleMetrics(every, visible, ceiling, n_boxes, hidden, threshold)


def _exactly(boxes: np.ndarray, labels: np.ndarray) -> DetectionResult:
    """A detection of exactly these boxes, each with score 1."""
    return DetectionResult(
        boxes.astype(np.float32), labels.astype(np.int64), np.ones(len(labels), np.float32)
    )
