"""Figures of a category predictor: accuracy, macro-F1, ECE, Cohen's kappa, rank correlation.

Shared by the oracle's training (:mod:`anunnaki.enlil._oracle_train`), its context lookup
(:mod:`anunnaki.enlil._oracle_lookup`) and its evaluation (:mod:`anunnaki.enlil._oracle_eval`);
numpy only, so every module below the network can import it.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = [
    "classification_metrics",
    "cohen_kappa",
    "expected_calibration_error",
    "regression_metrics",
    "spearman",
]


def expected_calibration_error(probs: np.ndarray, labels: np.ndarray, bins: int = 10) -> float:
    """ECE of the top-class confidence over *bins* equal-width bins."""
    if len(labels) == 0:
        return math.nan
    conf = probs.max(axis=1)
    correct = probs.argmax(axis=1) == labels
    edges = np.linspace(0.0, 1.0, bins + 1)
    ece = 0.0
    for lo, hi in itertools.pairwise(edges):
        mask = (conf > lo) & (conf <= hi)
        if mask.any():
            ece += mask.mean() * abs(float(correct[mask].mean()) - float(conf[mask].mean()))
    return float(ece)


def classification_metrics(
    predicted: Sequence[int] | np.ndarray, truth: Sequence[int] | np.ndarray, n: int = 3
) -> dict[str, Any]:
    """Accuracy, macro-F1 (over the classes present in truth or predictions), recall, confusion."""
    pred = np.asarray(predicted, np.int64)
    true = np.asarray(truth, np.int64)
    confusion = np.zeros((n, n), np.int64)
    for t, p in zip(true, pred, strict=True):
        confusion[t, p] += 1
    f1s, recall = [], {}
    for c in range(n):
        tp = confusion[c, c]
        support, predicted_c = confusion[c].sum(), confusion[:, c].sum()
        if support:
            recall[str(c)] = float(tp / support)
        if support or predicted_c:
            f1s.append(2 * tp / (support + predicted_c))
    return {
        "accuracy": float((pred == true).mean()) if len(true) else math.nan,
        "macro_f1": float(np.mean(f1s)) if f1s else math.nan,
        "per_category_recall": recall,
        "confusion": confusion.tolist(),
        "n": len(true),
    }


def cohen_kappa(a: Sequence[int] | np.ndarray, b: Sequence[int] | np.ndarray, n: int = 3) -> float:
    """Cohen's kappa between two labellings of the same items (1: identical, 0: chance).

    ``nan`` for no items; 1 when both labellings are one and the same single class.
    """
    x, y = np.asarray(a, np.int64), np.asarray(b, np.int64)
    if len(x) == 0:
        return math.nan
    confusion = np.zeros((n, n), np.float64)
    np.add.at(confusion, (x, y), 1.0)
    confusion /= confusion.sum()
    observed = float(np.trace(confusion))
    expected = float(confusion.sum(axis=1) @ confusion.sum(axis=0))
    if expected >= 1.0:
        return 1.0 if observed >= 1.0 else 0.0
    return (observed - expected) / (1.0 - expected)


def _ranks(v: np.ndarray) -> np.ndarray:
    """Ranks of *v* from 0, ties given their mean rank."""
    order = np.argsort(v, kind="stable")
    ranks = np.empty(len(v), np.float64)
    ranks[order] = np.arange(len(v), dtype=np.float64)
    _, inverse, counts = np.unique(v, return_inverse=True, return_counts=True)
    sums = np.zeros(len(counts), np.float64)
    np.add.at(sums, inverse, ranks)
    out: np.ndarray = (sums / counts)[inverse]
    return out


def spearman(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray) -> float:
    """Spearman's rank correlation (ties at mean rank); ``nan`` when either side is constant."""
    x, y = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if len(x) < 2:
        return math.nan
    rx, ry = _ranks(x), _ranks(y)
    rx, ry = rx - rx.mean(), ry - ry.mean()
    denom = math.sqrt(float(rx @ rx) * float(ry @ ry))
    return float(rx @ ry) / denom if denom > 0 else math.nan


def regression_metrics(
    predicted: Sequence[float] | np.ndarray, truth: Sequence[float] | np.ndarray
) -> dict[str, float]:
    """``rmse``, ``mae`` and ``spearman`` of predicted against measured values (e.g. F1 drops)."""
    p, t = np.asarray(predicted, np.float64), np.asarray(truth, np.float64)
    if len(t) == 0:
        return {"rmse": math.nan, "mae": math.nan, "spearman": math.nan}
    err = p - t
    return {
        "rmse": float(np.sqrt(np.mean(err**2))),
        "mae": float(np.mean(np.abs(err))),
        "spearman": spearman(p, t),
    }
