"""Precision, recall and F1 at an IoU threshold — the one rule used everywhere.

The rule (``docs/detector.md``): in each image, predictions with a score at or above the
threshold are taken in descending score order (ties keep their given order); each is matched
to the not-yet-matched ground-truth box *of the same class* with which it has the highest
IoU, and counts as a true positive when that IoU is at least ``iou`` (0.5), otherwise as a
false positive — unless it lies mostly inside an *ignore box* (intersection over the
prediction's own area at least ``ignore_ioa``, 0.5, as COCO treats crowd regions; any
class), and then it counts neither way. Ignore boxes mark objects in the image that are not
labelled (too small, mostly occluded, cut by the frame); they are never false negatives.
Every truth is matched at most once; truths left over are false negatives. Counts are
summed over all images before precision, recall and F1 are computed.

Why greedy by score makes threshold search cheap: thresholding removes only the
lowest-scoring predictions, and those are matched last, so one matching pass at threshold
zero labels every prediction, and the counts at any threshold are cumulative sums
(:func:`choose_threshold`). Whether a prediction is ignored depends only on the
predictions ranked above it, so that stays true with ignore boxes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from anunnaki.lec._detector import DetectionResult, DetectorError

__all__ = [
    "IGNORE_IOA",
    "Metrics",
    "Truth",
    "box_ioa",
    "box_iou",
    "choose_threshold",
    "f1_at_iou",
    "match_image",
]

#: Ground truth of one image: ``(boxes [N, 4] xyxy pixels, labels [N] int)``, optionally
#: with a third item, the image's ignore boxes ``[K, 4]`` (what ``Dataset.truths()`` gives).
Truth = tuple[npt.ArrayLike, npt.ArrayLike] | tuple[npt.ArrayLike, npt.ArrayLike, npt.ArrayLike]

#: An unmatched prediction is ignored when at least this share of its area is inside one
#: ignore box (COCO's rule for crowd regions).
IGNORE_IOA = 0.5


@dataclass(frozen=True)
class Metrics:
    """Detection quality over a set of images.

    Attributes:
        precision: ``tp / (tp + fp)``; 1.0 when nothing was predicted and nothing was there,
            0.0 when nothing was predicted but something was there.
        recall: ``tp / (tp + fn)``; 1.0 when there was nothing to find.
        f1: ``2 tp / (2 tp + fp + fn)``; 1.0 when there was nothing to find and nothing
            was predicted.
        tp: True positives.
        fp: False positives (unmatched, wrong-class or low-IoU predictions).
        fn: False negatives (truths no prediction matched).

    """

    precision: float
    recall: float
    f1: float
    tp: int
    fp: int
    fn: int

    @classmethod
    def from_counts(cls, tp: int, fp: int, fn: int) -> Metrics:
        """Compute the rates from the counts (see the attribute docs for empty cases)."""
        precision = tp / (tp + fp) if tp + fp else (1.0 if fn == 0 else 0.0)
        recall = tp / (tp + fn) if tp + fn else 1.0
        f1 = 2 * tp / (2 * tp + fp + fn) if tp + fp + fn else 1.0
        return cls(precision, recall, f1, tp, fp, fn)

    def as_dict(self) -> dict[str, float | int]:
        """The figures as a plain dict (for JSON)."""
        return {
            "precision": self.precision,
            "recall": self.recall,
            "f1": self.f1,
            "tp": self.tp,
            "fp": self.fp,
            "fn": self.fn,
        }


def box_iou(a: npt.ArrayLike, b: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Pairwise IoU of ``[N, 4]`` and ``[M, 4]`` xyxy boxes → ``[N, M]`` (float64)."""
    a64 = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b64 = np.asarray(b, dtype=np.float64).reshape(-1, 4)
    lt = np.maximum(a64[:, None, :2], b64[None, :, :2])
    rb = np.minimum(a64[:, None, 2:], b64[None, :, 2:])
    wh = np.clip(rb - lt, 0.0, None)
    inter = wh[..., 0] * wh[..., 1]
    area_a = np.clip(a64[:, 2] - a64[:, 0], 0, None) * np.clip(a64[:, 3] - a64[:, 1], 0, None)
    area_b = np.clip(b64[:, 2] - b64[:, 0], 0, None) * np.clip(b64[:, 3] - b64[:, 1], 0, None)
    union = area_a[:, None] + area_b[None, :] - inter
    out: npt.NDArray[np.float64] = np.divide(
        inter, union, out=np.zeros_like(inter), where=union > 0
    )
    return out


def box_ioa(a: npt.ArrayLike, b: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Pairwise intersection over the area of ``a``: ``[N, 4]`` and ``[M, 4]`` → ``[N, M]``.

    A box of zero area has IoA 0 with everything.
    """
    a64 = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b64 = np.asarray(b, dtype=np.float64).reshape(-1, 4)
    lt = np.maximum(a64[:, None, :2], b64[None, :, :2])
    rb = np.minimum(a64[:, None, 2:], b64[None, :, 2:])
    wh = np.clip(rb - lt, 0.0, None)
    inter = wh[..., 0] * wh[..., 1]
    area_a = np.clip(a64[:, 2] - a64[:, 0], 0, None) * np.clip(a64[:, 3] - a64[:, 1], 0, None)
    denom = np.broadcast_to(area_a[:, None], inter.shape)
    out: npt.NDArray[np.float64] = np.divide(
        inter, denom, out=np.zeros_like(inter), where=denom > 0
    )
    return out


def match_image(
    pred: DetectionResult,
    truth_boxes: npt.ArrayLike,
    truth_labels: npt.ArrayLike,
    *,
    iou: float,
    ignore: npt.ArrayLike | None = None,
    ignore_ioa: float = IGNORE_IOA,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.bool_], int]:
    """Greedy class-aware matching in one image, all predictions (no threshold).

    Args:
        pred: The image's predictions.
        truth_boxes: ``[N, 4]`` labelled boxes.
        truth_labels: ``[N]`` their classes.
        iou: A match needs IoU at least this.
        ignore: ``[K, 4]`` ignore boxes (default none).
        ignore_ioa: An unmatched prediction with at least this share of its area inside
            one ignore box is ignored.

    Returns:
        ``(scores, is_tp, n_truths)``: the scores, in descending order, of the predictions
        that count (ignored ones are left out), whether each is a true positive, and the
        number of ground-truth boxes.

    """
    tboxes = np.asarray(truth_boxes, dtype=np.float64).reshape(-1, 4)
    tlabels = np.asarray(truth_labels, dtype=np.int64).reshape(-1)
    if len(tboxes) != len(tlabels):
        raise DetectorError(
            f"ground truth has {len(tboxes)} boxes but {len(tlabels)} labels; give one each"
        )
    order = np.argsort(-pred.scores, kind="stable")
    scores = pred.scores[order]
    is_tp = np.zeros(len(order), dtype=bool)
    if len(order) and len(tboxes):
        ious = box_iou(pred.boxes[order], tboxes)
        ious[pred.labels[order][:, None] != tlabels[None, :]] = -1.0
        taken = np.zeros(len(tboxes), dtype=bool)
        for i in range(len(order)):
            row = np.where(taken, -1.0, ious[i])
            j = int(np.argmax(row))
            if row[j] >= iou:
                taken[j] = True
                is_tp[i] = True
    iboxes = np.zeros((0, 4)) if ignore is None else np.asarray(ignore, np.float64).reshape(-1, 4)
    if len(order) and len(iboxes):
        inside = (box_ioa(pred.boxes[order], iboxes) >= ignore_ioa).any(axis=1)
        counted = is_tp | ~inside
        scores, is_tp = scores[counted], is_tp[counted]
    return scores, is_tp, len(tboxes)


def _unpack(truth: Truth) -> tuple[npt.ArrayLike, npt.ArrayLike, npt.ArrayLike | None]:
    if len(truth) == 3:
        return truth[0], truth[1], truth[2]
    if len(truth) == 2:
        return truth[0], truth[1], None
    raise DetectorError(
        f"a ground truth is (boxes, labels) or (boxes, labels, ignore), got {len(truth)} items"
    )


def _check_lengths(preds: Sequence[DetectionResult], truths: Sequence[Truth]) -> None:
    if len(preds) != len(truths):
        raise DetectorError(
            f"{len(preds)} predictions but {len(truths)} ground truths; give one per image"
        )


def _check_iou(iou: float) -> None:
    if not 0.0 < iou <= 1.0:
        raise DetectorError(f"iou must be in (0, 1], got {iou}")


def f1_at_iou(
    preds: Sequence[DetectionResult],
    truths: Sequence[Truth],
    *,
    iou: float = 0.5,
    score_threshold: float,
) -> Metrics:
    """Precision, recall and F1 of *preds* against *truths* (the module's rule).

    Args:
        preds: One :class:`DetectionResult` per image.
        truths: One ``(boxes [N, 4] xyxy, labels [N])`` or ``(boxes, labels, ignore
            [K, 4])`` per image, in the same order (``Dataset.truths()``).
        iou: A match needs IoU at least this (inclusive).
        score_threshold: Predictions with a lower score are ignored.

    Raises:
        DetectorError: The two sequences differ in length, or a truth is malformed.

    """
    _check_lengths(preds, truths)
    _check_iou(iou)
    tp = fp = fn = 0
    for pred, truth in zip(preds, truths, strict=True):
        tboxes, tlabels, ignore = _unpack(truth)
        scores, is_tp, n_truth = match_image(
            pred.above(score_threshold), tboxes, tlabels, iou=iou, ignore=ignore
        )
        del scores
        hits = int(is_tp.sum())
        tp += hits
        fp += len(is_tp) - hits
        fn += n_truth - hits
    return Metrics.from_counts(tp, fp, fn)


def choose_threshold(
    preds: Sequence[DetectionResult], truths: Sequence[Truth], *, iou: float = 0.5
) -> float:
    """The score threshold that maximises F1 on *preds* (use the validation split).

    Every distinct prediction score is a candidate; the F1 is constant between two
    neighbouring candidates, so the threshold returned is the midpoint between the best
    candidate and the next lower score (half the best candidate when it is the lowest),
    which keeps exactly the same predictions on this data and leaves a margin on new data.
    Ties go to the higher threshold (fewer false alarms). With no predictions at all it
    returns 0.5; with no ground truth at all, a threshold above every score.

    Raises:
        DetectorError: The two sequences differ in length.

    """
    _check_lengths(preds, truths)
    _check_iou(iou)
    all_scores: list[npt.NDArray[np.float32]] = []
    all_tp: list[npt.NDArray[np.bool_]] = []
    n_truth = 0
    for pred, truth in zip(preds, truths, strict=True):
        tboxes, tlabels, ignore = _unpack(truth)
        scores, is_tp, n = match_image(pred, tboxes, tlabels, iou=iou, ignore=ignore)
        all_scores.append(scores)
        all_tp.append(is_tp)
        n_truth += n
    scores = np.concatenate(all_scores) if all_scores else np.zeros(0, np.float32)
    if len(scores) == 0:
        return 0.5
    if n_truth == 0:  # nothing to find: only keeping nothing is right
        return float((1.0 + scores.max()) / 2.0)
    tps = np.concatenate(all_tp)
    order = np.argsort(-scores, kind="stable")
    scores, tps = scores[order].astype(np.float64), tps[order]
    cum_tp = np.cumsum(tps)
    cum_fp = np.cumsum(~tps)
    # The last index of each run of equal scores: a threshold keeps whole runs.
    last = np.flatnonzero(np.r_[scores[1:] != scores[:-1], True])
    tp, fp = cum_tp[last], cum_fp[last]
    f1 = 2 * tp / np.maximum(2 * tp + fp + (n_truth - tp), 1)
    best = int(np.flatnonzero(f1 == f1.max())[0])  # first = highest threshold
    chosen = scores[last[best]]
    lower = scores[last[best] + 1] if last[best] + 1 < len(scores) else 0.0
    return float((chosen + lower) / 2.0)
