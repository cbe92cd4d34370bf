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
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from anunnaki import lec  # lec.evaluate_detector, lec.predict: torch at first call
from anunnaki.datasets import Dataset
from anunnaki.enlil._context import (
    ContextResult,
    EnlilError,
    evaluate_context,
    fixed_batch,
    resolve_phenomenon,
    to_phenomenon_vector,
)
from anunnaki.enlil._oracle_metrics import (
    classification_metrics,
    cohen_kappa,
    expected_calibration_error,
    regression_metrics,
)
from anunnaki.enlil._oracle_net import OracleModel
from anunnaki.enlil._sweep import ContextSpec, draw_contexts
from anunnaki.lec import Detector
from anunnaki.phenomena import CameraEncoding, Phenomenon

__all__ = [
    "BASELINES",
    "Baseline",
    "BaselineFit",
    "HeldOut",
    "Predictions",
    "Retest",
    "baseline_predictions",
    "box_stability",
    "detector_statistic",
    "drop_curve",
    "drop_noise",
    "evaluate_oracles",
    "fit_baseline",
    "fit_baselines",
    "held_out_frames",
    "interior_mask",
    "label_ceiling",
    "of_ceiling",
    "oracle_predictions",
    "retest_contexts",
    "score_all",
    "score_predictions",
]

Baseline = Literal["atc", "max-score", "box-stability"]
#: The detector-output baselines ``oracle evaluate --baseline`` knows.
BASELINES: tuple[Baseline, ...] = ("atc", "max-score", "box-stability")
#: Lowest detection score the baselines look at (the detector's candidates).
SCORE_FLOOR = 0.05
#: Box stability: the share of feature channels dropped, and the score a detection needs
#: to be compared (Liu et al., "Bounding Box Stability against Feature Dropout Reflects
#: Detector Generalization", ICLR 2024).
BOX_DROPOUT = 0.1
BOX_SCORE = 0.3


@dataclass(frozen=True)
class Retest:
    """Held-out contexts measured once more, on a disjoint batch of as many images.

    Attributes:
        drops: ``[C]`` each context's relative F1 drop on the second batch.
        categories: ``[C]`` its category there.
        clean_f1: The model's F1 on the second batch, clean.
        batch_images: Images of the second batch.

    """

    drops: npt.NDArray[np.float64]
    categories: npt.NDArray[np.int64]
    clean_f1: float
    batch_images: int


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
        retest: The contexts measured again on a disjoint batch (:func:`retest_contexts`),
            or ``None`` before.

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
    retest: Retest | None = None

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

    def drops(self) -> npt.NDArray[np.float64]:
        """``[F]`` the measured relative F1 drop of each frame's context."""
        return np.asarray([self.contexts[int(i)].drop for i in self.context_index], np.float64)

    def only(self, keep: npt.NDArray[np.bool_]) -> HeldOut:
        """The same held-out set restricted to the contexts where *keep* ``[C]`` is true."""
        kept = np.flatnonzero(keep)
        frames = (
            np.concatenate(
                [c * self.per_context + np.arange(self.per_context) for c in kept]
            ).astype(np.int64)
            if len(kept)
            else np.zeros(0, np.int64)
        )
        retest = self.retest
        if retest is not None:
            retest = replace(retest, drops=retest.drops[kept], categories=retest.categories[kept])
        return replace(
            self,
            contexts=[self.contexts[int(c)] for c in kept],
            frames=[self.frames[int(i)] for i in frames],
            labels=self.labels[frames],
            context_index=np.repeat(np.arange(len(kept)), self.per_context),
            retest=retest,
        )

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
    margin: float = 0.0,
    encoding: CameraEncoding | None = None,
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
        margin: For ``interior:N``: how far from a band edge a context's drop must lie.
        encoding: The camera's encoding, after the phenomenon, on every frame measured or
            predicted on (the clean batch's too).
        **kwargs: Passed to :func:`anunnaki.lec.evaluate_detector` (``score_threshold``).

    """
    if per_context < 1:
        raise EnlilError(f"frames per context must be at least 1, got {per_context}")
    phen = resolve_phenomenon(phenomenon)
    batch = fixed_batch(data, n=batch_images, seed=seed)
    clean_f1 = float(lec.evaluate_detector(detector, batch, encoding=encoding, **kwargs).f1)
    drawn = draw_contexts(
        detector, batch, phen, spec, clean_f1=clean_f1, thresholds=thresholds, seed=seed,
        max_draws=max_draws, margin=margin, encoding=encoding, **kwargs,
    )  # fmt: skip
    if not drawn.results:
        raise EnlilError(f"{phen.name}: no context could be drawn for {spec}")
    rng = np.random.default_rng([seed, 7])
    frames: list[npt.NDArray[np.uint8]] = []
    for result in drawn.results:
        params = phen.from_vector(to_phenomenon_vector(phen, result.params))
        for i in rng.integers(len(data), size=per_context):
            frame = phen.apply(data.image(int(i)), params, seed=int(rng.integers(2**31)))
            frames.append(frame if encoding is None else encoding.apply(frame))
    index = np.repeat(np.arange(len(drawn.results)), per_context)
    labels = np.asarray([r.category for r in drawn.results], np.int64)[index]
    return HeldOut(
        phen.name, tuple(phen.param_names), drawn.results, frames, labels, index, per_context,
        clean_f1, drawn.evaluations, drawn.short,
    )  # fmt: skip


def retest_contexts(
    detector: Detector,
    data: Dataset,
    held: HeldOut,
    *,
    batch_images: int = 32,
    thresholds: tuple[float, float] = (0.05, 0.10),
    seed: int = 0,
    score_threshold: float | None = None,
    encoding: CameraEncoding | None = None,
) -> HeldOut:
    """*held* with its contexts measured once more (:attr:`HeldOut.retest`).

    The labels are one measurement each on the fixed batch :func:`held_out_frames` drew
    with *seed*; the retest measures every context on a disjoint batch of as many images of
    *data* (drawn with ``seed + 2`` among the others), with its own clean F1. How well the
    two agree bounds what any predictor that never sees the labelling batch can reach.
    """
    n = min(batch_images, len(data))
    first = fixed_batch_indices(len(data), n, seed)
    rest = data.subset([i for i in range(len(data)) if i not in first])
    if len(rest) == 0:
        raise EnlilError(
            f"the split has {len(data)} images: none left for a second label batch of "
            f"{batch_images}; use at most half the split (--batch-images) or no ceiling "
            "(--no-ceiling)"
        )
    batch = fixed_batch(rest, n=batch_images, seed=seed + 2)
    clean = float(
        lec.evaluate_detector(
            detector, batch, score_threshold=score_threshold, encoding=encoding
        ).f1
    )
    again = [
        evaluate_context(
            detector, batch, held.phenomenon, r.params, clean_f1=clean, thresholds=thresholds,
            seed=seed, score_threshold=score_threshold, encoding=encoding,
        )
        for r in held.contexts
    ]  # fmt: skip
    retest = Retest(
        np.asarray([r.drop for r in again], np.float64),
        np.asarray([r.category for r in again], np.int64),
        clean,
        len(batch),
    )
    return replace(held, retest=retest)


def fixed_batch_indices(size: int, n: int, seed: int) -> set[int]:
    """The indices of a split of *size* images :func:`anunnaki.enlil.fixed_batch` draws."""
    if n >= size:
        return set(range(size))
    return {int(i) for i in np.random.default_rng(seed).choice(size, size=n, replace=False)}


def drop_noise(
    held: HeldOut, thresholds: tuple[float, float] | None = (0.05, 0.10)
) -> tuple[float, int]:
    """The standard deviation of one measurement of a drop near the band, and its contexts.

    From the retest's differences, ``sqrt(mean((d1 - d2)^2) / 2)``, over the contexts whose
    mean drop is at most twice the upper threshold (a drop's noise grows with the drop: a
    context that loses 60 % of its F1 varies by far more than one at the band, and only
    the band's edges matter); over all contexts when fewer than two are that near, or when
    *thresholds* is ``None``.
    """
    if held.retest is None or not held.contexts:
        return math.nan, 0
    first = np.asarray([r.drop for r in held.contexts], np.float64)
    second = held.retest.drops
    use = np.ones(len(first), bool)
    if thresholds is not None:
        near = (first + second) / 2.0 <= 2.0 * thresholds[1]
        if near.sum() >= 2:
            use = near
    noise = float(np.sqrt(np.mean((first[use] - second[use]) ** 2) / 2.0))
    return noise, int(use.sum())


def label_ceiling(held: HeldOut, thresholds: tuple[float, float] = (0.05, 0.10)) -> dict[str, Any]:
    """How far *held*'s labels reproduce: the retest scored against them (per context).

    ``kappa`` (Cohen's) and ``macro_f1``, ``accuracy`` and ``confusion`` of the retest's
    categories against the labels, ``drop`` (``rmse``, ``spearman`` of the retest's drops
    against the first ones), ``drop_noise`` near the band (:func:`drop_noise`, over
    ``drop_noise_contexts`` contexts) and ``drop_noise_all`` (over every context), and the
    retest's
    ``batch_images`` and ``clean_f1``. Per frame the figures are the same (every context
    has as many frames).
    """
    if held.retest is None:
        raise EnlilError("label_ceiling: measure the contexts again first (retest_contexts)")
    labels = np.asarray([r.category for r in held.contexts], np.int64)
    metrics = classification_metrics(held.retest.categories, labels)
    first = np.asarray([r.drop for r in held.contexts], np.float64)
    noise, near = drop_noise(held, thresholds)
    return {
        "drop": regression_metrics(held.retest.drops, first),
        "kappa": cohen_kappa(labels, held.retest.categories),
        "macro_f1": metrics["macro_f1"],
        "accuracy": metrics["accuracy"],
        "confusion": metrics["confusion"],
        "drop_noise": noise,
        "drop_noise_contexts": near,
        "drop_noise_all": drop_noise(held, None)[0],
        "contexts": len(labels),
        "batch_images": held.retest.batch_images,
        "clean_f1": held.retest.clean_f1,
    }


def interior_mask(
    drops: npt.NDArray[np.float64], thresholds: tuple[float, float], margin: float
) -> npt.NDArray[np.bool_]:
    """Which *drops* lie farther than *margin* from both category thresholds."""
    d = np.asarray(drops, np.float64)[:, None]
    return np.asarray(np.all(np.abs(d - np.asarray(thresholds)) > margin, axis=1))


def of_ceiling(figures: dict[str, Any], ceiling: dict[str, Any]) -> dict[str, float | None]:
    """A predictor's ``macro_f1`` and ``kappa`` as fractions of the labels' own agreement."""
    out: dict[str, float | None] = {}
    for key in ("macro_f1", "kappa"):
        mine, best = figures.get(key), ceiling.get(key)
        if mine is None or best is None or not math.isfinite(best) or best <= 0:
            out[key] = None
        else:
            out[key] = float(mine) / float(best)
    return out


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
        drop: ``[F]`` the predicted relative F1 drop (an oracle's drop head, a baseline's
            statistic through its fitted curve), else ``None``.

    """

    name: str
    category: npt.NDArray[np.int64]
    window_category: npt.NDArray[np.int64]
    probs: npt.NDArray[np.float64] | None = None
    window_probs: npt.NDArray[np.float64] | None = None
    params: npt.NDArray[np.float64] | None = None
    phenomenon_hit: npt.NDArray[np.bool_] | None = None
    info: dict[str, Any] | None = None
    drop: npt.NDArray[np.float64] | None = None


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
        oracle.outputs(held.frames[i : i + batch_size])
        for i in range(0, len(held.frames), batch_size)
    ]
    logits = np.concatenate([c.category for c in chunks])
    all_params = np.concatenate([c.params for c in chunks])
    phen_logits = np.concatenate([c.phenomenon for c in chunks])
    raw = [c.drop for c in chunks if c.drop is not None]
    drop = oracle.predicted_drop(np.concatenate(raw) if len(raw) == len(chunks) else None)
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
        drop,
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
    ``box-stability``: :func:`box_stability`.
    """
    if kind == "box-stability":
        return box_stability(detector, frames, batch_size=batch_size)
    out = np.zeros(len(frames), np.float64)
    for i, det in enumerate(lec.predict(detector, list(frames), batch_size=batch_size)):
        scores = np.asarray(det.scores, np.float64)
        scores = scores[scores >= SCORE_FLOOR]
        if len(scores) == 0:
            continue
        out[i] = (
            float(scores.max()) if kind == "max-score" else float((scores > atc_threshold).mean())
        )
    return out


def _torch_network(detector: Detector) -> Any:
    net = getattr(detector, "network", None)
    if net is None or not hasattr(net, "register_forward_hook"):
        raise EnlilError(
            f"the box-stability baseline drops features of a torch network; "
            f"{type(detector).__name__} has no 'network' module: use --baseline atc or max-score"
        )
    return net


def _box_iou(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """``[len(a), len(b)]`` IoU of xyxy boxes."""
    lt = np.maximum(a[:, None, :2], b[None, :, :2])
    rb = np.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = np.prod(np.clip(rb - lt, 0.0, None), axis=2)
    area_a = np.prod(np.clip(a[:, 2:] - a[:, :2], 0.0, None), axis=1)
    area_b = np.prod(np.clip(b[:, 2:] - b[:, :2], 0.0, None), axis=1)
    union = area_a[:, None] + area_b[None, :] - inter
    out: npt.NDArray[np.float64] = np.where(union > 0, inter / np.maximum(union, 1e-12), 0.0)
    return out


def _matched_iou(a: Any, b: Any) -> float:
    """Mean IoU of *a*'s detections matched one to one (Hungarian) with *b*'s, by class.

    Unmatched detections count 0; no detection on either side is perfectly stable (1).
    """
    from scipy.optimize import linear_sum_assignment

    ka = np.asarray(a.scores) >= BOX_SCORE
    kb = np.asarray(b.scores) >= BOX_SCORE
    boxes_a, boxes_b = np.asarray(a.boxes, np.float64)[ka], np.asarray(b.boxes, np.float64)[kb]
    labels_a, labels_b = np.asarray(a.labels)[ka], np.asarray(b.labels)[kb]
    total = max(len(boxes_a), len(boxes_b))
    if total == 0:
        return 1.0
    if len(boxes_a) == 0 or len(boxes_b) == 0:
        return 0.0
    iou = _box_iou(boxes_a, boxes_b) * (labels_a[:, None] == labels_b[None, :])
    rows, cols = linear_sum_assignment(-iou)
    return float(iou[rows, cols].sum()) / total


def box_stability(
    detector: Detector,
    frames: Sequence[npt.NDArray[np.uint8]],
    *,
    batch_size: int = 32,
    p: float = BOX_DROPOUT,
    seed: int = 0,
) -> npt.NDArray[np.float64]:
    """Per frame, how little the detections move when features are dropped (1: not at all).

    In the spirit of BoS (Liu et al., ICLR 2024): the detector runs once as it is and once
    with dropout (probability *p*, a fixed seed) on the output of each of its network's
    top-level stages; detections scoring at least 0.3 are matched one to one between the
    two runs (Hungarian, same class) and the frame's statistic is the mean IoU of the
    matches, unmatched detections counting 0. A detector that works on a frame finds the
    same boxes with fewer features; one that is failing moves them. Needs a detector with
    a torch ``network`` (the built-in CenterNet; :class:`anunnaki.enlil.EnlilError`
    otherwise).
    """
    import torch

    net = _torch_network(detector)
    plain = lec.predict(detector, list(frames), batch_size=batch_size)
    gen = torch.Generator().manual_seed(seed)

    def drop(_module: Any, _inputs: Any, output: Any) -> Any:
        if not isinstance(output, torch.Tensor) or output.dim() != 4:
            return output
        keep = torch.rand((*output.shape[:2], 1, 1), generator=gen) >= p
        return output * keep.to(output.dtype) / (1.0 - p)

    hooks = [child.register_forward_hook(drop) for child in net.children()]
    try:
        dropped = lec.predict(detector, list(frames), batch_size=batch_size)
    finally:
        for hook in hooks:
            hook.remove()
    return np.asarray([_matched_iou(a, b) for a, b in zip(plain, dropped, strict=True)])


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
        drop_curve: ``(statistic knots, drop values)``: the frame's predicted relative F1
            drop is the statistic interpolated on it (fitted on the val frames: the mean
            measured drop of each tenth of them by statistic); empty when not fitted.

    """

    kind: Baseline
    atc_threshold: float
    frame_thresholds: tuple[float, float]
    window_thresholds: tuple[float, float]
    drop_curve: tuple[tuple[float, ...], tuple[float, ...]] = ((), ())

    def drops(self, stat: npt.NDArray[np.float64]) -> npt.NDArray[np.float64] | None:
        """The predicted relative F1 drop of each statistic (``None`` without a curve)."""
        knots, values = self.drop_curve
        if not knots:
            return None
        out: npt.NDArray[np.float64] = np.interp(stat, np.asarray(knots), np.asarray(values))
        return out

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
        scores = [
            np.asarray(d.scores, np.float64) for d in lec.predict(detector, list(clean_frames))
        ]
        flat = np.concatenate(scores) if scores else np.zeros(0)
        atc = _atc_threshold(flat[flat >= SCORE_FLOOR], clean_f1)
    stat = detector_statistic(detector, val.frames, kind, atc_threshold=atc)
    rows = val.windows(window)
    return BaselineFit(
        kind,
        atc,
        _fit_thresholds(stat, val.labels),
        _fit_thresholds(stat[rows].mean(axis=1), val.labels[rows[:, 0]]),
        drop_curve(stat, val.drops()),
    )


def drop_curve(
    stat: npt.NDArray[np.float64], drops: npt.NDArray[np.float64], bins: int = 10
) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Knots mapping a statistic to a relative F1 drop: mean of each of *bins* quantile bins."""
    order = np.argsort(stat, kind="stable")
    xs, ys = [], []
    for part in np.array_split(order, min(bins, len(order))):
        if len(part):
            xs.append(float(stat[part].mean()))
            ys.append(float(drops[part].mean()))
    knots, first = np.unique(np.asarray(xs), return_index=True)
    return tuple(float(v) for v in knots), tuple(ys[i] for i in first)


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
        drop=fit.drops(stat),
    )


def _metrics(
    pred: npt.NDArray[np.int64], labels: npt.NDArray[np.int64], probs: Any
) -> dict[str, Any]:
    out = classification_metrics(pred, labels)
    out["kappa"] = cohen_kappa(labels, pred)
    out["ece"] = expected_calibration_error(probs, labels) if probs is not None else None
    return out


def score_predictions(
    held: HeldOut,
    pred: Predictions,
    *,
    window: int = 5,
    thresholds: tuple[float, float] = (0.05, 0.10),
) -> dict[str, Any]:
    """The figures of one predictor on *held* (see the module docstring)."""
    out = _metrics(pred.category, held.labels, pred.probs)
    out.pop("n")
    if pred.drop is not None:
        out["drop"] = regression_metrics(pred.drop, held.drops())
        t0, t1 = thresholds
        from_drop = np.where(pred.drop > t1, 2, np.where(pred.drop > t0, 1, 0))
        out["drop"]["category_macro_f1"] = classification_metrics(from_drop, held.labels)[
            "macro_f1"
        ]
    else:
        out["drop"] = None
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
    encoding: CameraEncoding | None = None,
) -> tuple[dict[Baseline, BaselineFit], dict[str, Any]]:
    """Fit the detector-output *baselines* on the val split (see :func:`fit_baseline`).

    Returns:
        The fits by name, and what they were fitted on (contexts, categories, clean F1).

    """
    held = held_out_frames(
        detector, val, phenomenon, spec, per_context=per_context, batch_images=batch_images,
        seed=seed, thresholds=thresholds, score_threshold=score_threshold, encoding=encoding,
    )  # fmt: skip
    clean = fixed_batch(val, n=4 * batch_images, seed=seed + 1)
    clean_f1 = float(
        lec.evaluate_detector(
            detector, clean, score_threshold=score_threshold, encoding=encoding
        ).f1
    )
    frames = [clean.image(i) for i in range(len(clean))]
    if encoding is not None:
        frames = [encoding.apply(f) for f in frames]
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
    ceiling: bool = True,
    interior: bool = True,
    encoding: CameraEncoding | None = None,
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
        ceiling: Measure every context again on a disjoint batch of *test* and report the
            labels' agreement with themselves (``ceiling``) and each predictor's figures as
            a fraction of it (``of_ceiling``).
        interior: With *ceiling* and a ``balanced`` *spec*: also a balanced set drawn from
            each category's interior (drops farther from a band edge than the measured
            drop noise), scored the same way, under ``interior``.
        encoding: The camera's encoding every frame goes through after the phenomenon
            (contexts measured, frames predicted on, the baselines' fits): the figures for
            a camera that sends JPEG.

    Returns:
        ``{"phenomenon", "test": contexts info, "predictors": name → figures
        (:func:`score_predictions`), "ceiling", "fit": val contexts info, "interior"}``.

    """
    if baselines and val is None and fits is None:
        raise EnlilError("the detector-output baselines are fitted on val: give the val split")
    phen = resolve_phenomenon(phenomenon)
    kw: dict[str, Any] = {
        "per_context": per_context, "batch_images": batch_images, "thresholds": thresholds,
        "score_threshold": score_threshold, "encoding": encoding,
    }  # fmt: skip
    if fits is None and baselines and val is not None:
        fspec = fit_spec or ContextSpec("balanced", spec.n)
        fits, fit_info = fit_baselines(
            detector, val, phen, fspec, baselines, window=window, seed=seed + 1, **kw
        )
    else:
        fit_info = None

    def score(held: HeldOut) -> dict[str, Any]:
        if ceiling:
            held = retest_contexts(
                detector, test, held, batch_images=batch_images, thresholds=thresholds,
                seed=seed, score_threshold=score_threshold, encoding=encoding,
            )  # fmt: skip
        part: dict[str, Any] = {"test": _held_info(held, spec)}
        preds = {
            name: oracle_predictions(oracle, held, window=window)
            for name, oracle in oracles.items()
        } | {
            kind: baseline_predictions(fit, detector, held, window=window)
            for kind, fit in (fits or {}).items()
        }
        part |= score_all(held, preds, window=window, thresholds=thresholds)
        return part

    held = held_out_frames(detector, test, phen, spec, seed=seed, **kw)
    report: dict[str, Any] = {"phenomenon": phen.name} | score(held)
    report["encoding"] = "none" if encoding is None else str(encoding)
    if fit_info is not None:
        report["fit"] = fit_info
    if ceiling and interior and spec.kind == "balanced":
        margin = float(report["ceiling"]["drop_noise"])
        inner_spec = ContextSpec("interior", spec.n)
        inner = held_out_frames(detector, test, phen, inner_spec, seed=seed, margin=margin, **kw)
        report["interior"] = {"margin": margin} | score(inner)
        report["interior"]["test"]["spec"] = str(inner_spec)
    return report


def score_all(
    held: HeldOut,
    preds: Mapping[str, Predictions],
    *,
    window: int = 5,
    thresholds: tuple[float, float] = (0.05, 0.10),
) -> dict[str, Any]:
    """Every predictor's figures on *held*, beside the labels' ceiling when it was retested.

    Returns ``{"predictors": name → figures}`` and, when *held* has a retest, ``ceiling``
    (:func:`label_ceiling`) and in each predictor's figures ``of_ceiling``
    (:func:`of_ceiling`).
    """
    out: dict[str, Any] = {
        "predictors": {
            name: score_predictions(held, p, window=window, thresholds=thresholds)
            for name, p in preds.items()
        }
    }
    if held.retest is not None:
        out["ceiling"] = ceiling = label_ceiling(held, thresholds)
        for figures in out["predictors"].values():
            figures["of_ceiling"] = of_ceiling(figures, ceiling)
    return out
