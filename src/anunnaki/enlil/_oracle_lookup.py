"""The perceived context → category lookup of a behavior oracle (non-parametric).

A context's behavior category is (nearly) a function of the context: the assessment measures
it on a fixed batch of images, whatever frame the oracle happens to see. The oracle's network
already regresses the perceived context (the phenomenon's parameters, normalised to
``[0, 1]^d``) and which phenomenon it is, so the category can also be *looked up*: the
measured contexts nearest to the perceived one (Enlil's archive rows, hundreds per
phenomenon) vote for their categories. :class:`ContextLookup` does that with a
distance-weighted k-nearest-neighbour vote in a rescaled parameter space, one scale per
parameter fitted by leave-one-out on the measured contexts themselves (a raindrop's category
hangs on its radius far more than on where it sits).

:func:`mixed_probabilities` blends it with the network's own category head:
``w · p_net + (1 - w) · p_lookup``, where ``p_lookup`` weighs each phenomenon's vote by the
phenomenon head's probability (``clear`` votes category 0). The weight *w* is chosen on
validation frames (:func:`choose_mix`), never on the test split.

The lookup travels inside the oracle's safetensors file (``lookup.NAME.params`` ``[N, d]``
float32, ``lookup.NAME.categories`` ``[N]`` int64) with its settings in the sidecar
(:class:`LookupSpec`); nothing is pickled.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field

from anunnaki.enlil._context import EnlilError

__all__ = [
    "LOOKUP_PREFIX",
    "ContextLookup",
    "LookupSpec",
    "choose_mix",
    "fit_scales",
    "lookup_probabilities",
    "mixed_probabilities",
]

#: Tensor names of the lookup in an oracle's safetensors file start with this.
LOOKUP_PREFIX = "lookup."
#: Pseudo-count added to every category's vote (no probability is ever exactly 0).
_PRIOR = 0.05
#: Scales tried for each parameter when fitting (0: the parameter does not matter).
_SCALES = (0.0, 0.25, 0.5, 1.0, 2.0, 4.0)


class LookupSpec(BaseModel):
    """The lookup's settings in an oracle's sidecar.

    Attributes:
        k: Neighbours that vote.
        weight: The network head's share in the mix (1: the network alone, 0: the lookup
            alone).
        scales: Per phenomenon, one scale per parameter (distance = Euclidean over scaled
            normalised parameters).
        rows: Measured contexts per phenomenon (the tensors' lengths).
        chosen_on: What *k* and *weight* were chosen on, and the figures there.

    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    k: int = Field(ge=1)
    weight: float = Field(ge=0.0, le=1.0)
    scales: dict[str, list[float]]
    rows: dict[str, int] = Field(default_factory=dict)
    chosen_on: dict[str, float | int | str] = Field(default_factory=dict)


@dataclass(frozen=True)
class ContextLookup:
    """Measured contexts per phenomenon, and the k-nearest-neighbour vote over them.

    Attributes:
        params: Phenomenon → ``[N, d]`` normalised contexts.
        categories: Phenomenon → ``[N]`` their measured categories (0, 1, 2).
        scales: Phenomenon → ``[d]`` per-parameter scales of the distance.
        k: Neighbours that vote.

    """

    params: Mapping[str, npt.NDArray[np.float32]]
    categories: Mapping[str, npt.NDArray[np.int64]]
    scales: Mapping[str, npt.NDArray[np.float64]]
    k: int = 15

    def __post_init__(self) -> None:
        for name, p in self.params.items():
            cats = self.categories.get(name)
            scale = self.scales.get(name)
            if cats is None or scale is None:
                raise EnlilError(f"lookup: phenomenon {name!r} lacks categories or scales")
            if p.ndim != 2 or len(p) == 0 or len(cats) != len(p) or len(scale) != p.shape[1]:
                raise EnlilError(
                    f"lookup: {name!r} has params {p.shape}, categories {cats.shape} and "
                    f"scales {np.shape(scale)}; they must be [N, d], [N] and [d] with N > 0"
                )
            if np.any((cats < 0) | (cats > 2)):
                raise EnlilError(f"lookup: {name!r} has categories outside 0, 1, 2")

    @classmethod
    def from_contexts(
        cls,
        contexts: Mapping[str, tuple[npt.ArrayLike, npt.ArrayLike]],
        *,
        k: int = 15,
        scales: Mapping[str, Sequence[float]] | None = None,
    ) -> ContextLookup:
        """Build from ``{phenomenon: (params [N, d], categories [N])}``; fit missing scales."""
        params = {n: np.asarray(p, np.float32) for n, (p, _) in contexts.items()}
        cats = {n: np.asarray(c, np.int64) for n, (_, c) in contexts.items()}
        fitted = {
            n: np.asarray(scales[n], np.float64)
            if scales and n in scales
            else fit_scales(params[n], cats[n], k=k)
            for n in params
        }
        return cls(params, cats, fitted, k)

    def with_k(self, k: int) -> ContextLookup:
        """The same lookup with *k* neighbours."""
        return ContextLookup(self.params, self.categories, self.scales, k)

    def tensors(self) -> dict[str, npt.NDArray[np.float32] | npt.NDArray[np.int64]]:
        """The arrays to store in the oracle's safetensors file."""
        out: dict[str, npt.NDArray[np.float32] | npt.NDArray[np.int64]] = {}
        for name in self.params:
            out[f"{LOOKUP_PREFIX}{name}.params"] = np.ascontiguousarray(self.params[name])
            out[f"{LOOKUP_PREFIX}{name}.categories"] = np.ascontiguousarray(self.categories[name])
        return out

    def spec(self, weight: float, chosen_on: Mapping[str, float | int | str]) -> LookupSpec:
        """The sidecar settings for this lookup mixed with weight *weight*."""
        return LookupSpec(
            k=self.k,
            weight=float(weight),
            scales={n: [float(v) for v in s] for n, s in self.scales.items()},
            rows={n: len(p) for n, p in self.params.items()},
            chosen_on=dict(chosen_on),
        )

    @classmethod
    def from_tensors(
        cls, tensors: Mapping[str, np.ndarray], spec: LookupSpec, *, source: str = "<oracle>"
    ) -> ContextLookup:
        """Rebuild from a file's tensors and its sidecar's :class:`LookupSpec`."""
        params, cats = {}, {}
        for name in spec.scales:
            p = tensors.get(f"{LOOKUP_PREFIX}{name}.params")
            c = tensors.get(f"{LOOKUP_PREFIX}{name}.categories")
            if p is None or c is None:
                raise EnlilError(
                    f"{source}: the sidecar's lookup names {name!r} but the weights lack "
                    f"{LOOKUP_PREFIX}{name}.params / .categories; copy both files again"
                )
            params[name] = np.asarray(p, np.float32)
            cats[name] = np.asarray(c, np.int64)
        scales = {n: np.asarray(s, np.float64) for n, s in spec.scales.items()}
        return cls(params, cats, scales, spec.k)

    def vote(
        self,
        phenomenon: str,
        units: npt.ArrayLike,
        *,
        exclude: npt.ArrayLike | None = None,
    ) -> npt.NDArray[np.float64]:
        """``[B, 3]`` category probabilities of the contexts nearest to *units* ``[B, d]``.

        Args:
            phenomenon: Which phenomenon's measured contexts vote.
            units: Perceived normalised contexts (extra columns beyond ``d`` are ignored).
            exclude: ``[B]`` a row of the measured contexts each query must not see (its
                own context, for leave-one-out figures), or -1.

        """
        if phenomenon not in self.params:
            raise EnlilError(f"lookup: no measured contexts of {phenomenon!r}")
        ref = self.params[phenomenon].astype(np.float64)
        cats = self.categories[phenomenon]
        scale = self.scales[phenomenon]
        q = np.atleast_2d(np.asarray(units, np.float64))[:, : ref.shape[1]]
        dist = np.sqrt((((q[:, None, :] - ref[None, :, :]) * scale) ** 2).sum(axis=2))
        if exclude is not None:
            ex = np.asarray(exclude, np.int64)
            hit = ex >= 0
            dist[np.flatnonzero(hit), ex[hit]] = np.inf
        return _vote(dist, cats, self.k)


def _vote(
    dist: npt.NDArray[np.float64], cats: npt.NDArray[np.int64], k: int
) -> npt.NDArray[np.float64]:
    """Distance-weighted vote of the *k* nearest columns of *dist* ``[B, N]``."""
    k = min(k, dist.shape[1])
    nearest = np.argpartition(dist, k - 1, axis=1)[:, :k]
    d = np.take_along_axis(dist, nearest, axis=1)
    w = np.where(np.isfinite(d), 1.0 / (d + 0.02), 0.0)
    out = np.full((len(dist), 3), _PRIOR)
    for c in range(3):
        out[:, c] += (w * (cats[nearest] == c)).sum(axis=1)
    result: npt.NDArray[np.float64] = out / out.sum(axis=1, keepdims=True)
    return result


def _loo_log_likelihood(
    params: npt.NDArray[np.float64], cats: npt.NDArray[np.int64], scale: np.ndarray, k: int
) -> float:
    dist = np.sqrt((((params[:, None, :] - params[None, :, :]) * scale) ** 2).sum(axis=2))
    np.fill_diagonal(dist, np.inf)
    probs = _vote(dist, cats, k)
    return float(np.log(probs[np.arange(len(cats)), cats]).mean())


def fit_scales(
    params: npt.ArrayLike, categories: npt.ArrayLike, *, k: int = 15, max_rows: int = 1500
) -> npt.NDArray[np.float64]:
    """Per-parameter distance scales maximising the leave-one-out likelihood of the vote.

    Coordinate ascent over :data:`_SCALES` per parameter (two sweeps), from all ones; at
    least one scale stays positive. Deterministic; on at most *max_rows* rows (a fixed
    subsample of more).
    """
    p = np.asarray(params, np.float64)
    c = np.asarray(categories, np.int64)
    if len(p) > max_rows:
        keep = np.random.default_rng(0).choice(len(p), max_rows, replace=False)
        p, c = p[keep], c[keep]
    d = p.shape[1]
    scale = np.ones(d)
    if len(p) < 3 or d == 0:
        return scale
    best = _loo_log_likelihood(p, c, scale, k)
    for _, j in itertools.product(range(2), range(d)):
        for value in _SCALES:
            trial = scale.copy()
            trial[j] = value
            if not trial.any():
                continue
            score = _loo_log_likelihood(p, c, trial, k)
            if score > best + 1e-9:
                best, scale = score, trial
    return scale


def lookup_probabilities(
    lookup: ContextLookup,
    phenomena: Sequence[str],
    params: npt.ArrayLike,
    phenomenon_probs: npt.ArrayLike,
    *,
    exclude: Mapping[str, npt.ArrayLike] | None = None,
) -> npt.NDArray[np.float64]:
    """``[B, 3]``: ``clear`` votes category 0, each phenomenon its nearest contexts.

    Args:
        lookup: The measured contexts.
        phenomena: The oracle's phenomena (the phenomenon head's classes after ``clear``).
        params: ``[B, D]`` the perceived normalised contexts (the regression head).
        phenomenon_probs: ``[B, 1 + P]`` the phenomenon head's probabilities.
        exclude: Per phenomenon, ``[B]`` rows to leave out (see :meth:`ContextLookup.vote`).

    """
    pp = np.asarray(phenomenon_probs, np.float64)
    out = np.zeros((len(pp), 3))
    out[:, 0] = pp[:, 0]
    for i, name in enumerate(phenomena):
        ex = None if exclude is None else exclude.get(name)
        out += pp[:, i + 1 : i + 2] * lookup.vote(name, params, exclude=ex)
    result: npt.NDArray[np.float64] = out / out.sum(axis=1, keepdims=True)
    return result


def mixed_probabilities(
    net_probs: npt.ArrayLike, lookup_probs: npt.ArrayLike, weight: float
) -> npt.NDArray[np.float64]:
    """``weight · net_probs + (1 - weight) · lookup_probs`` (rows sum to 1)."""
    out: npt.NDArray[np.float64] = weight * np.asarray(net_probs, np.float64) + (
        1.0 - weight
    ) * np.asarray(lookup_probs, np.float64)
    return out


def choose_mix(
    net_probs: npt.ArrayLike,
    lookups: Mapping[int, npt.ArrayLike],
    labels: npt.ArrayLike,
    *,
    weights: Sequence[float] = (0.0, 0.25, 0.5, 0.75, 1.0),
) -> tuple[int, float, float]:
    """The ``(k, weight)`` with the best macro-F1 on validation frames, and that macro-F1.

    Args:
        net_probs: ``[F, 3]`` the network's calibrated probabilities.
        lookups: k → ``[F, 3]`` the lookup's probabilities with k neighbours (leave-one-out).
        labels: ``[F]`` true categories.
        weights: The network's shares tried.

    Ties go to the larger weight (the network alone when the lookup does not help), then
    the smaller k.

    """
    from anunnaki.enlil._oracle_net import classification_metrics

    y = np.asarray(labels, np.int64)
    best: tuple[float, float, int] = (-1.0, -1.0, 0)
    for k in sorted(lookups):
        for w in weights:
            pred = mixed_probabilities(net_probs, lookups[k], w).argmax(axis=1)
            f1 = float(classification_metrics(pred, y)["macro_f1"])
            if (f1, w, -k) > (best[0], best[1], -best[2]):
                best = (f1, w, k)
    return best[2], best[1], best[0]
