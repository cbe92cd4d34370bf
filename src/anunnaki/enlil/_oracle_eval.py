"""How well a behavior oracle (or a baseline) predicts the category on held-out frames.

:func:`held_out_frames` draws contexts of one phenomenon (``random:N`` or ``balanced:N``,
:mod:`anunnaki.enlil._sweep`), measures each one's true category on a fixed batch of the
split (:func:`anunnaki.enlil.evaluate_context`) and perturbs ``per_context`` other frames of
the split with it; every frame carries its context's category. Predictors are then scored
on exactly those frames, one frame at a time and over windows of ``window`` consecutive
frames of one context (calibrated probabilities, or a baseline's statistic, averaged):

* :func:`oracle_predictions` — a trained oracle (:class:`OracleModel`);
* :func:`baseline_predictions` — the detector's own outputs (Garg et al. 2022's ATC, or the
  mean max-score), mapped to categories by thresholds fitted on validation frames
  (:func:`fit_baseline`).

:func:`score_predictions` turns predictions into the figures of ``anunnaki oracle evaluate``:
``accuracy``, ``macro_f1``, ``per_category_recall``, ``confusion``, ``ece`` (oracles only),
``context_error`` (mean absolute error of the perceived normalised context) and the same
over windows.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from anunnaki.datasets import Dataset
from anunnaki.enlil._context import (
    ContextResult,
    EnlilError,
    fixed_batch,
    resolve_phenomenon,
    to_phenomenon_vector,
)
from anunnaki.enlil._oracle_net import (
    OracleModel,
    classification_metrics,
    expected_calibration_error,
)
from anunnaki.enlil._sweep import ContextSpec, draw_contexts
from anunnaki.lec import Detector, evaluate_detector, predict
from anunnaki.phenomena import Phenomenon

__all__ = [
    "BASELINES",
    "Baseline",
    "BaselineFit",
    "HeldOut",
    "Predictions",
    "baseline_predictions",
    "detector_statistic",
    "evaluate_oracles",
    "fit_baseline",
    "fit_baselines",
    "held_out_frames",
    "oracle_predictions",
    "score_predictions",
]

Baseline = Literal["atc", "max-score"]
#: The detector-output baselines ``oracle evaluate --baseline`` knows.
BASELINES: tuple[Baseline, ...] = ("atc", "max-score")
#: Lowest detection score the baselines look at (the detector's candidates).
SCORE_FLOOR = 0.05


@dataclass(frozen=True)
class HeldOut:
    """Perturbed frames of a split, each labelled with its context's measured category.

    Attributes:
        phenomenon: The phenomenon (or composition) name.
        param_names: Its parameters (vector order).
        contexts: The measured contexts.
        frames: ``per_context`` frames per context, context after context.
        labels: ``[F]`` the category of each frame's context.
        context_index: ``[F]`` which context each frame shows.
        per_context: Frames per context.
        clean_f1: The model's F1 on the clean fixed batch.
        evaluations: Contexts measured to find them.
        short: Categories a balanced set could not fill (category → missing).

    """

    phenomenon: str
    param_names: tuple[str, ...]
    contexts: list[ContextResult]
    frames: list[npt.NDArray[np.uint8]]
    labels: npt.NDArray[np.int64]
    context_index: npt.NDArray[np.int64]
    per_context: int
    clean_f1: float
    evaluations: int
    short: dict[int, int]

    def describe(self) -> dict[str, Any]:
        """Counts for a report: contexts, frames, evaluations, categories, clean F1."""
        return {
            "contexts": len(self.contexts),
            "frames": len(self.frames),
            "frames_per_context": self.per_context,
            "evaluations": self.evaluations,
            "category_counts": [int(sum(r.category == c for r in self.contexts)) for c in range(3)],
            "short": {str(k): v for k, v in self.short.items()},
            "clean_f1": self.clean_f1,
        }

    def units(self) -> npt.NDArray[np.float64]:
        """``[F, d]`` the normalised context of each frame."""
        return np.stack([self.contexts[int(i)].params for i in self.context_index])

    def windows(self, window: int) -> npt.NDArray[np.int64]:
        """``[W, window]`` frame indices of consecutive windows inside each context."""
        if window < 1 or window > self.per_context:
            raise EnlilError(
                f"a window of {window} frames needs 1 <= window <= frames per context "
                f"({self.per_context}); raise --frames-per-context"
            )
        per = self.per_context // window
        rows = [
            c * self.per_context + w * window + np.arange(window)
            for c in range(len(self.contexts))
            for w in range(per)
        ]
        return np.asarray(rows, np.int64).reshape(-1, window)


def held_out_frames(
    detector: Detector,
    data: Dataset,
    phenomenon: str | Phenomenon,
    spec: ContextSpec,
    *,
    per_context: int = 10,
    batch_images: int = 32,
    thresholds: tuple[float, float] = (0.05, 0.10),
    seed: int = 0,
    max_draws: int | None = None,
    **kwargs: Any,
) -> HeldOut:
    """Draw and measure contexts on *data*, then perturb ``per_context`` frames with each.

    Args:
        detector: The model whose behavior is predicted.
        data: The split (``test`` for figures, ``val`` to fit baselines).
        phenomenon: Name, composition or instance.
        spec: ``random:N`` or ``balanced:N``.
        per_context: Frames per context (drawn from the whole split, other seeds).
        batch_images: Images of the fixed batch each context's category is measured on.
        thresholds: Relative F1 drops of categories 1 and 2.
        seed: Contexts, frames and phenomenon seeds derive from it.
        max_draws: See :func:`anunnaki.enlil.draw_contexts`.
        **kwargs: Passed to :func:`anunnaki.lec.evaluate_detector` (``score_threshold``).

    """
    if per_context < 1:
        raise EnlilError(f"frames per context must be at least 1, got {per_context}")
    phen = resolve_phenomenon(phenomenon)
    batch = fixed_batch(data, n=batch_images, seed=seed)
    clean_f1 = float(evaluate_detector(detector, batch, **kwargs).f1)
    drawn = draw_contexts(
        detector, batch, phen, spec, clean_f1=clean_f1, thresholds=thresholds, seed=seed,
        max_draws=max_draws, **kwargs,
    )  # fmt: skip
    if not drawn.results:
        raise EnlilError(f"{phen.name}: no context could be drawn for {spec}")
    rng = np.random.default_rng([seed, 7])
    frames: list[npt.NDArray[np.uint8]] = []
    for result in drawn.results:
        params = phen.from_vector(to_phenomenon_vector(phen, result.params))
        for i in rng.integers(len(data), size=per_context):
            frames.append(phen.apply(data.image(int(i)), params, seed=int(rng.integers(2**31))))
    index = np.repeat(np.arange(len(drawn.results)), per_context)
    labels = np.asarray([r.category for r in drawn.results], np.int64)[index]
    return HeldOut(
        phen.name, tuple(phen.param_names), drawn.results, frames, labels, index, per_context,
        clean_f1, drawn.evaluations, drawn.short,
    )  # fmt: skip


@dataclass(frozen=True)
class Predictions:
    """What one predictor says about the frames of a :class:`HeldOut`.

    Attributes:
        name: ``oracle``, ``atc``, ``max-score`` …
        category: ``[F]`` predicted category per frame.
        window_category: ``[W]`` per window (:meth:`HeldOut.windows`).
        probs: ``[F, 3]`` calibrated probabilities (oracles), else ``None``.
        window_probs: ``[W, 3]`` their window means, else ``None``.
        params: ``[F, d]`` perceived normalised context (oracles), else ``None``.
        phenomenon_hit: ``[F]`` whether the perceived phenomenon is right (oracles with
            a trained phenomenon head), else ``None``.
        info: Fitted thresholds and such, copied into the report.

    """

    name: str
    category: npt.NDArray[np.int64]
    window_category: npt.NDArray[np.int64]
    probs: npt.NDArray[np.float64] | None = None
    window_probs: npt.NDArray[np.float64] | None = None
    params: npt.NDArray[np.float64] | None = None
    phenomenon_hit: npt.NDArray[np.bool_] | None = None
    info: dict[str, Any] | None = None


def oracle_predictions(
    oracle: OracleModel, held: HeldOut, *, window: int = 5, batch_size: int = 256
) -> Predictions:
    """The oracle's per-frame and per-window predictions on *held*'s frames.

    Raises:
        EnlilError: The oracle does not cover *held*'s phenomenon.

    """
    classes = oracle.card.phenomenon_classes
    if held.phenomenon not in classes[1:]:
        raise EnlilError(
            f"the oracle of {oracle.model_id!r} covers {classes[1:]}, not {held.phenomenon!r}; "
            "evaluate it on one of those, or train one that covers it (anunnaki oracle train)"
        )
    chunks = [
        oracle.logits(held.frames[i : i + batch_size])
        for i in range(0, len(held.frames), batch_size)
    ]
    logits = np.concatenate([c[0] for c in chunks])
    all_params = np.concatenate([c[1] for c in chunks])
    phen_logits = np.concatenate([c[2] for c in chunks])
    params = all_params[:, : len(held.param_names)]
    probs = oracle.category_probabilities(logits, all_params, phen_logits)
    rows = held.windows(window)
    window_probs = probs[rows].mean(axis=1)
    hit = None
    if oracle.card.phenomenon_head:
        hit = phen_logits.argmax(axis=1) == classes.index(held.phenomenon)
    return Predictions(
        "oracle",
        probs.argmax(axis=1).astype(np.int64),
        window_probs.argmax(axis=1).astype(np.int64),
        probs,
        window_probs,
        params.astype(np.float64),
        hit,
        {"temperature": oracle.card.temperature},
    )


def detector_statistic(
    detector: Detector,
    frames: Sequence[npt.NDArray[np.uint8]],
    kind: Baseline,
    *,
    atc_threshold: float = 0.5,
    batch_size: int = 32,
) -> npt.NDArray[np.float64]:
    """Per frame, the statistic a detector-output baseline reads (higher: healthier).

    ``max-score``: the highest detection score in the frame (0 without candidates).
    ``atc``: the fraction of the frame's candidates (scores >= 0.05) whose score exceeds
    *atc_threshold* (0 without candidates): average thresholded confidence.
    """
    out = np.zeros(len(frames), np.float64)
    for i, det in enumerate(predict(detector, list(frames), batch_size=batch_size)):
        scores = np.asarray(det.scores, np.float64)
        scores = scores[scores >= SCORE_FLOOR]
        if len(scores) == 0:
            continue
        out[i] = (
            float(scores.max()) if kind == "max-score" else float((scores > atc_threshold).mean())
        )
    return out


@dataclass(frozen=True)
class BaselineFit:
    """A detector-output baseline fitted on validation frames.

    Attributes:
        kind: ``atc`` or ``max-score``.
        atc_threshold: ATC's score threshold (fraction of clean candidates above it =
            the clean F1); unused by ``max-score``.
        frame_thresholds: ``(t0, t1)``: category 0 when the statistic > t0, 2 when <= t1,
            else 1 — per frame.
        window_thresholds: The same for window means.

    """

    kind: Baseline
    atc_threshold: float
    frame_thresholds: tuple[float, float]
    window_thresholds: tuple[float, float]

    def categories(self, stat: npt.NDArray[np.float64], *, window: bool) -> npt.NDArray[np.int64]:
        """Map statistics to categories with the fitted thresholds."""
        t0, t1 = self.window_thresholds if window else self.frame_thresholds
        return np.where(stat > t0, 0, np.where(stat > t1, 1, 2)).astype(np.int64)


def _atc_threshold(clean_scores: npt.NDArray[np.float64], clean_f1: float) -> float:
    """The score t with ``mean(clean_scores > t) == clean_f1`` (ATC's fit on clean data)."""
    if len(clean_scores) == 0:
        return 0.5
    return float(np.quantile(clean_scores, min(max(1.0 - clean_f1, 0.0), 1.0)))


def _fit_thresholds(
    stat: npt.NDArray[np.float64], labels: npt.NDArray[np.int64]
) -> tuple[float, float]:
    """The pair ``t0 >= t1`` of statistic cut points that maximises macro-F1 on *labels*."""
    cuts = np.unique(np.quantile(stat, np.linspace(0.0, 1.0, 41)))
    cuts = np.concatenate([[-math.inf], cuts])
    best, best_pair = -1.0, (0.5, 0.25)
    for t0, t1 in itertools.combinations_with_replacement(cuts[::-1], 2):
        pred = np.where(stat > t0, 0, np.where(stat > t1, 1, 2))
        value = classification_metrics(pred, labels)["macro_f1"]
        if value > best:
            best, best_pair = value, (float(t0), float(t1))
    return best_pair


def fit_baseline(
    kind: Baseline,
    detector: Detector,
    clean_frames: Sequence[npt.NDArray[np.uint8]],
    clean_f1: float,
    val: HeldOut,
    *,
    window: int = 5,
) -> BaselineFit:
    """Fit a baseline on validation data: ATC's threshold on clean frames, then categories.

    Args:
        kind: ``atc`` or ``max-score``.
        detector: The model whose outputs are read.
        clean_frames: Clean validation frames (ATC's fit: the fraction of their candidates
            above the threshold equals the clean F1, Garg et al. 2022).
        clean_f1: The model's F1 on clean validation data.
        val: Perturbed validation frames with their true categories (a balanced set fits
            the category-1 band best).
        window: Frames per window (the window thresholds are fitted on window means).

    """
    if kind not in BASELINES:
        raise EnlilError(f"unknown baseline {kind!r}; choose one of {list(BASELINES)}")
    atc = 0.5
    if kind == "atc":
        scores = [np.asarray(d.scores, np.float64) for d in predict(detector, list(clean_frames))]
        flat = np.concatenate(scores) if scores else np.zeros(0)
        atc = _atc_threshold(flat[flat >= SCORE_FLOOR], clean_f1)
    stat = detector_statistic(detector, val.frames, kind, atc_threshold=atc)
    rows = val.windows(window)
    return BaselineFit(
        kind,
        atc,
        _fit_thresholds(stat, val.labels),
        _fit_thresholds(stat[rows].mean(axis=1), val.labels[rows[:, 0]]),
    )


def baseline_predictions(
    fit: BaselineFit, detector: Detector, held: HeldOut, *, window: int = 5
) -> Predictions:
    """A fitted baseline's predictions on *held*'s frames."""
    stat = detector_statistic(detector, held.frames, fit.kind, atc_threshold=fit.atc_threshold)
    rows = held.windows(window)
    info: dict[str, Any] = {
        "frame_thresholds": list(fit.frame_thresholds),
        "window_thresholds": list(fit.window_thresholds),
    }
    if fit.kind == "atc":
        info["atc_threshold"] = fit.atc_threshold
    return Predictions(
        fit.kind,
        fit.categories(stat, window=False),
        fit.categories(stat[rows].mean(axis=1), window=True),
        info=info,
    )


def _metrics(
    pred: npt.NDArray[np.int64], labels: npt.NDArray[np.int64], probs: Any
) -> dict[str, Any]:
    out = classification_metrics(pred, labels)
    out["ece"] = expected_calibration_error(probs, labels) if probs is not None else None
    return out


def score_predictions(held: HeldOut, pred: Predictions, *, window: int = 5) -> dict[str, Any]:
    """The figures of one predictor on *held* (see the module docstring)."""
    out = _metrics(pred.category, held.labels, pred.probs)
    out.pop("n")
    out["frames"] = len(held.labels)
    if pred.params is not None:
        err = np.abs(pred.params - held.units())
        out["context_error"] = float(err.mean())
        out["context_error_per_param"] = dict(
            zip(held.param_names, (float(v) for v in err.mean(axis=0)), strict=True)
        )
    else:
        out["context_error"] = None
    if pred.phenomenon_hit is not None:
        affected = held.labels > 0
        out["phenomenon_accuracy"] = (
            float(pred.phenomenon_hit[affected].mean()) if affected.any() else None
        )
    rows = held.windows(window)
    win = _metrics(pred.window_category, held.labels[rows[:, 0]], pred.window_probs)
    win["windows"] = win.pop("n")
    win["frames"] = window
    out["window"] = win
    if pred.info:
        out.update(pred.info)
    return out


def _held_info(held: HeldOut, spec: ContextSpec) -> dict[str, Any]:
    return {"spec": str(spec), **held.describe()}


def fit_baselines(
    detector: Detector,
    val: Dataset,
    phenomenon: str | Phenomenon,
    spec: ContextSpec,
    baselines: Sequence[Baseline] = BASELINES,
    *,
    per_context: int = 10,
    window: int = 5,
    batch_images: int = 32,
    thresholds: tuple[float, float] = (0.05, 0.10),
    seed: int = 0,
    score_threshold: float | None = None,
) -> tuple[dict[Baseline, BaselineFit], dict[str, Any]]:
    """Fit the detector-output *baselines* on the val split (see :func:`fit_baseline`).

    Returns:
        The fits by name, and what they were fitted on (contexts, categories, clean F1).

    """
    held = held_out_frames(
        detector, val, phenomenon, spec, per_context=per_context, batch_images=batch_images,
        seed=seed, thresholds=thresholds, score_threshold=score_threshold,
    )  # fmt: skip
    clean = fixed_batch(val, n=4 * batch_images, seed=seed + 1)
    clean_f1 = float(evaluate_detector(detector, clean, score_threshold=score_threshold).f1)
    frames = [clean.image(i) for i in range(len(clean))]
    fits = {
        kind: fit_baseline(kind, detector, frames, clean_f1, held, window=window)
        for kind in baselines
    }
    return fits, _held_info(held, spec) | {"clean_images": len(clean), "clean_f1": clean_f1}


def evaluate_oracles(
    detector: Detector,
    test: Dataset,
    phenomenon: str | Phenomenon,
    spec: ContextSpec,
    *,
    oracles: Mapping[str, OracleModel],
    baselines: Sequence[Baseline] = (),
    val: Dataset | None = None,
    fit_spec: ContextSpec | None = None,
    fits: Mapping[Baseline, BaselineFit] | None = None,
    per_context: int = 10,
    window: int = 5,
    batch_images: int = 32,
    thresholds: tuple[float, float] = (0.05, 0.10),
    seed: int = 0,
    score_threshold: float | None = None,
) -> dict[str, Any]:
    """Score oracles and detector-output baselines on the same held-out frames.

    Args:
        detector: The model whose behavior is predicted (true categories; baselines).
        test: The split the figures come from.
        phenomenon: Name or composition.
        spec: Contexts of *test*.
        oracles: Name → oracle (e.g. ``enlil``, ``monte-carlo``).
        baselines: ``atc`` and/or ``max-score``, fitted on *val* (:func:`fit_baselines`).
        val: The validation split (needed with *baselines* unless *fits* are given).
        fit_spec: Contexts of *val* the baselines' category thresholds are fitted on
            (default ``balanced:N`` with *spec*'s N).
        fits: Baselines fitted before (then *baselines*, *val* and *fit_spec* are unused).
        per_context: Frames per context.
        window: Frames per window.
        batch_images: Images of the fixed batch each context is measured on.
        thresholds: Relative F1 drops of categories 1 and 2.
        seed: Everything derives from it (*val* uses ``seed + 1``).
        score_threshold: The detector's score threshold (default: its own).

    Returns:
        ``{"phenomenon", "test": contexts info, "predictors": name → figures
        (:func:`score_predictions`), "fit": val contexts info}``.

    """
    if baselines and val is None and fits is None:
        raise EnlilError("the detector-output baselines are fitted on val: give the val split")
    phen = resolve_phenomenon(phenomenon)
    kw: dict[str, Any] = {
        "per_context": per_context, "batch_images": batch_images, "thresholds": thresholds,
        "score_threshold": score_threshold,
    }  # fmt: skip
    held = held_out_frames(detector, test, phen, spec, seed=seed, **kw)
    report: dict[str, Any] = {"phenomenon": phen.name, "test": _held_info(held, spec)}
    predictors: dict[str, Any] = {}
    for name, oracle in oracles.items():
        preds = oracle_predictions(oracle, held, window=window)
        predictors[name] = score_predictions(held, preds, window=window)
    if fits is None and baselines and val is not None:
        fspec = fit_spec or ContextSpec("balanced", spec.n)
        fits, report["fit"] = fit_baselines(
            detector, val, phen, fspec, baselines, window=window, seed=seed + 1, **kw
        )
    for kind, fit in (fits or {}).items():
        preds = baseline_predictions(fit, detector, held, window=window)
        predictors[kind] = score_predictions(held, preds, window=window)
    report["predictors"] = predictors
    return report
