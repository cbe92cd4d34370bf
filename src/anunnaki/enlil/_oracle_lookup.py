"""The perceived context → category lookup of a behavior oracle: a drop surrogate.

A context's behavior category comes from the model's relative F1 drop under it, measured on
a fixed batch of images. The drop is (nearly) a smooth function of the context, but one
measurement is noisy: the same context measured on another batch of 32 images often lands in
another category near the thresholds (measured in docs/enlil.md). So rather than trusting
each archived category, :class:`ContextLookup` fits, per phenomenon, a Gaussian process to
``log(drop + 0.02)`` over the normalised contexts (Enlil's archive rows, hundreds per
phenomenon): an anisotropic RBF kernel whose length scales, signal and noise variance
maximise the marginal likelihood. Its predictive mean and variance (noise included) give the
probability of each category, ``P(drop <= t1)``, ``P(t1 < drop <= t2)``, ``P(drop > t2)``:
denoised labels for training (:func:`anunnaki.enlil.train_oracle` uses them as soft
targets) and, at run time, a lookup from the context the network perceives.

:func:`lookup_probabilities` weighs each phenomenon's answer by the phenomenon head's
probability (``clear`` answers category 0); :func:`mixed_probabilities` blends it with the
category head, ``w · p_head + (1 - w) · p_lookup``, and :func:`choose_mix` picks ``w`` (and a
boost of category 1, the thin band a macro-F1 weighs as much as the others) on validation
frames, never on the test split.

The lookup travels inside the oracle's safetensors file (``lookup.NAME.params`` ``[N, d]``
and ``lookup.NAME.targets`` ``[N]``, float64) with the kernels in the sidecar
(:class:`LookupSpec`); nothing is pickled. At most :data:`MAX_ROWS` rows per phenomenon are
kept (a fixed subsample), so one lookup costs well under a millisecond.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field

from anunnaki.enlil._context import EnlilError
from anunnaki.enlil._oracle_metrics import classification_metrics
from anunnaki.errors import MissingExtraError

__all__ = [
    "LOOKUP_PREFIX",
    "ContextLookup",
    "Kernel",
    "LookupSpec",
    "boosted",
    "choose_mix",
    "fit_kernel",
    "kept_rows",
    "lookup_probabilities",
    "mixed_probabilities",
]

#: Tensor names of the lookup in an oracle's safetensors file start with this.
LOOKUP_PREFIX = "lookup."
#: The surrogate models ``log(drop + OFFSET)``.
OFFSET = 0.02
#: Rows kept per phenomenon (a fixed subsample of more).
MAX_ROWS = 800
#: Rows the kernel's hyper-parameters are fitted on (a fixed subsample of more).
FIT_ROWS = 300
_JITTER = 1e-6
#: A lookup predicts in float32 when that moves no predictive standard deviation by more
#: than this (relative) at its stored contexts; otherwise in float64.
WHITEN_RTOL = 1e-4
#: A phenomenon the phenomenon head gives at most this probability is not looked up (its
#: share goes to the others when the row is renormalised).
MIN_SHARE = 0.01


def _ndtr(x: np.ndarray) -> np.ndarray:
    try:
        from scipy.special import ndtr
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise MissingExtraError("the oracle's context lookup (scipy)", "oracle") from exc
    out: np.ndarray = ndtr(x)
    return out


class Kernel(BaseModel):
    """One phenomenon's Gaussian process: RBF kernel and constant mean.

    Attributes:
        lengthscales: One per parameter (normalised units).
        signal: Kernel variance.
        noise: Noise variance (a measurement's scatter around the smooth drop).
        mean: Constant prior mean of ``log(drop + 0.02)``.

    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    lengthscales: list[float]
    signal: float = Field(gt=0.0)
    noise: float = Field(gt=0.0)
    mean: float


class LookupSpec(BaseModel):
    """The lookup's settings in an oracle's sidecar.

    Attributes:
        weight: The category head's share in the mix (1: the head alone, 0: the lookup).
        boost: Log-multiplier of category 1's probability before the argmax (0: none).
        thresholds: Relative drops of categories 1 and 2.
        kernels: Per phenomenon, its Gaussian process.
        rows: Measured contexts kept per phenomenon.
        chosen_on: What *weight* and *boost* were chosen on, and the figures there.

    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    weight: float = Field(ge=0.0, le=1.0)
    boost: float = 0.0
    thresholds: tuple[float, float] = (0.05, 0.10)
    kernels: dict[str, Kernel]
    rows: dict[str, int] = Field(default_factory=dict)
    chosen_on: dict[str, float | int | str] = Field(default_factory=dict)


def _targets(drops: npt.ArrayLike) -> npt.NDArray[np.float64]:
    return np.log(np.clip(np.asarray(drops, np.float64), 0.0, 1.0) + OFFSET)


def kept_rows(n: int, most: int = MAX_ROWS) -> npt.NDArray[np.int64]:
    """The rows of *n* measured contexts a lookup keeps: all, or a fixed subsample of *most*."""
    if n <= most:
        return np.arange(n)
    return np.sort(np.random.default_rng(0).choice(n, most, replace=False))


def fit_kernel(params: npt.ArrayLike, drops: npt.ArrayLike) -> Kernel:
    """The kernel maximising the marginal likelihood of ``log(drop + 0.02)`` at *params*.

    L-BFGS (scipy) over log length scales (bounded to ``[0.01, 5]``), signal and noise, on
    at most :data:`FIT_ROWS` of the contexts (a fixed subsample).

    Raises:
        EnlilError: Fewer than 3 contexts, or shapes that do not match.

    """
    try:
        from scipy.linalg import LinAlgError, cho_factor, cho_solve
        from scipy.optimize import minimize
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise MissingExtraError("the oracle's context lookup (scipy)", "oracle") from exc
    x = np.asarray(params, np.float64)
    y = _targets(drops)
    if x.ndim != 2 or len(x) != len(y) or len(x) < 3:
        raise EnlilError(
            f"the context lookup needs [N, d] contexts and N drops with N >= 3, got "
            f"{x.shape} and {y.shape}"
        )
    keep = kept_rows(len(x), FIT_ROWS)
    x, y = x[keep], y[keep]
    d, mean = x.shape[1], float(y.mean())
    r = y - mean
    var = max(float(y.var()), 1e-4)

    def unpack(theta: np.ndarray) -> Kernel:
        return Kernel(
            lengthscales=[float(v) for v in np.exp(theta[:d])],
            signal=float(np.exp(theta[d])),
            noise=float(np.exp(theta[d + 1])),
            mean=mean,
        )

    sq = (x[:, None, :] - x[None, :, :]) ** 2  # [N, N, d]

    def nll(theta: np.ndarray) -> tuple[float, np.ndarray]:
        """Negative log marginal likelihood and its gradient in the log parameters."""
        ls2 = np.exp(2.0 * theta[:d])
        rbf = np.exp(theta[d]) * np.exp(-0.5 * (sq / ls2).sum(axis=2))
        noise = float(np.exp(theta[d + 1]))
        k = rbf.copy()
        k[np.diag_indices_from(k)] += noise + _JITTER
        try:
            factor = cho_factor(k, lower=True, check_finite=False)
        except LinAlgError:
            return 1e12, np.zeros_like(theta)
        alpha = cho_solve(factor, r, check_finite=False)
        w = cho_solve(factor, np.eye(len(r)), check_finite=False) - np.outer(alpha, alpha)
        wr = w * rbf
        grad = np.empty_like(theta)
        grad[:d] = 0.5 * np.einsum("ij,ijk->k", wr, sq) / ls2
        grad[d] = 0.5 * wr.sum()
        grad[d + 1] = 0.5 * noise * np.trace(w)
        value = float(0.5 * r @ alpha + np.log(np.diag(factor[0])).sum())
        return value, grad

    start = np.r_[np.full(d, math.log(0.2)), math.log(var), math.log(0.1 * var)]
    bounds = [(math.log(0.01), math.log(5.0))] * d + [
        (math.log(var) - 6, math.log(var) + 4),
        (math.log(var) - 10, math.log(var) + 2),
    ]
    result = minimize(
        nll, start, jac=True, method="L-BFGS-B", bounds=bounds, options={"maxiter": 100}
    )
    return unpack(result.x)


@dataclass
class _Fitted:
    """One phenomenon's process, ready to predict.

    A frame's lookup is on the oracle's per-frame path, so what does not depend on the
    query is computed once here: the contexts divided by the length scales, the weights
    ``alpha = K⁻¹ (y - m)`` and the whitening ``W = L⁻¹`` of the Cholesky factor ``K = L Lᵀ``,
    stored transposed (``whiten = Wᵀ``), so that the predictive variance is
    ``s + n - ‖k Wᵀ‖²``. ``whiten`` is float32, half the memory traffic of the one
    matrix-vector product per query, when that keeps every predictive standard deviation
    within :data:`WHITEN_RTOL` of float64's at the stored contexts themselves (the smallest
    variances, where float32's rounding counts most); otherwise float64 (a process with
    little noise). The full inverse, used only to leave rows out
    (:meth:`ContextLookup.predict`'s *exclude*), is computed on first use.
    """

    params: npt.NDArray[np.float64]
    targets: npt.NDArray[np.float64]
    kernel: Kernel
    scaled: npt.NDArray[np.float64] = field(init=False)
    factor: npt.NDArray[np.floating[Any]] = field(init=False)
    alpha: npt.NDArray[np.float64] = field(init=False)
    whiten: npt.NDArray[np.floating[Any]] = field(init=False)
    _inverse: npt.NDArray[np.float64] | None = field(default=None, init=False)

    def __post_init__(self) -> None:
        from scipy.linalg import cho_solve, solve_triangular

        self.scaled = self.params / np.asarray(self.kernel.lengthscales, np.float64)
        k = self.cross(self.params)
        k[np.diag_indices_from(k)] += self.kernel.noise + _JITTER
        self.factor = np.linalg.cholesky(k)
        self.alpha = cho_solve(
            (self.factor, True), self.targets - self.kernel.mean, check_finite=False
        )
        eye = np.eye(len(k))
        double = np.ascontiguousarray(
            solve_triangular(self.factor, eye, lower=True, check_finite=False).T
        )
        probe = self.cross(self.params[kept_rows(len(self.params), 64)])
        self.whiten = double
        exact = self.std(probe)
        self.whiten = double.astype(np.float32)
        if np.max(np.abs(self.std(probe) / exact - 1.0)) > WHITEN_RTOL:
            self.whiten = double

    def std(self, cross: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """``[B]`` the predictive standard deviations (noise included) at ``cross`` ``[B, N]``.

        One query (a frame at run time) goes through BLAS's triangular ``trmv``, which reads
        only the triangle of ``W`` that is not zero: half the memory of a full product, and
        about half the time once the network has flushed the cache. Batches use ``gemm``.
        """
        k = cross.astype(self.whiten.dtype, copy=False)
        if len(k) == 1:
            from scipy.linalg.blas import get_blas_funcs

            trmv = get_blas_funcs("trmv", (self.whiten,))  # about 1 µs
            v = trmv(self.whiten.T, k[0], lower=1)[None, :]  # whiten.T: W, Fortran order
        else:
            v = k @ self.whiten
        var = self.variance_prior - np.einsum("ij,ij->i", v, v).astype(np.float64)
        out: npt.NDArray[np.float64] = np.sqrt(np.maximum(var, 1e-9))
        return out

    @property
    def variance_prior(self) -> float:
        """The variance of a measurement far from every stored context: signal + noise."""
        return self.kernel.signal + self.kernel.noise

    @property
    def inverse(self) -> npt.NDArray[np.float64]:
        """``K⁻¹`` (noise included), for leave-one-out queries."""
        if self._inverse is None:
            from scipy.linalg import cho_solve

            eye = np.eye(len(self.factor))
            self._inverse = cho_solve((self.factor, True), eye, check_finite=False)
        return self._inverse

    def cross(self, units: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """``[B, N]`` the kernel between the queries *units* ``[B, d]`` and the stored rows."""
        q = units / np.asarray(self.kernel.lengthscales, np.float64)
        diff = q[:, None, :] - self.scaled[None, :, :]
        out: npt.NDArray[np.float64] = self.kernel.signal * np.exp(
            -0.5 * np.einsum("bnd,bnd->bn", diff, diff)
        )
        return out


@dataclass(frozen=True)
class ContextLookup:
    """Gaussian-process drop surrogates per phenomenon, and the category probabilities.

    Attributes:
        params: Phenomenon → ``[N, d]`` normalised contexts.
        targets: Phenomenon → ``[N]`` their ``log(drop + 0.02)``.
        kernels: Phenomenon → its :class:`Kernel`.
        thresholds: Relative drops of categories 1 and 2.

    """

    params: Mapping[str, npt.NDArray[np.float64]]
    targets: Mapping[str, npt.NDArray[np.float64]]
    kernels: Mapping[str, Kernel]
    thresholds: tuple[float, float] = (0.05, 0.10)
    _fitted: dict[str, _Fitted] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        for name, p in self.params.items():
            t = self.targets.get(name)
            kernel = self.kernels.get(name)
            if t is None or kernel is None:
                raise EnlilError(f"lookup: phenomenon {name!r} lacks targets or a kernel")
            if p.ndim != 2 or len(p) == 0 or t.shape != (len(p),):
                raise EnlilError(
                    f"lookup: {name!r} has params {p.shape} and targets {t.shape}; they must "
                    "be [N, d] and [N] with N > 0"
                )
            if len(kernel.lengthscales) != p.shape[1]:
                raise EnlilError(
                    f"lookup: {name!r}'s kernel has {len(kernel.lengthscales)} length scales "
                    f"for {p.shape[1]} parameters"
                )
        for name in self.params:  # prepared now, not on the first frame assessed
            self._process(name)
        _ndtr(np.zeros(1))

    @classmethod
    def from_contexts(
        cls,
        contexts: Mapping[str, tuple[npt.ArrayLike, npt.ArrayLike]],
        *,
        thresholds: tuple[float, float] = (0.05, 0.10),
    ) -> ContextLookup:
        """Fit one process per phenomenon to ``{phenomenon: (params [N, d], drops [N])}``."""
        params, targets, kernels = {}, {}, {}
        for name, (p, drops) in contexts.items():
            x = np.asarray(p, np.float64)
            keep = kept_rows(len(x))
            kernels[name] = fit_kernel(x, drops)
            params[name] = x[keep]
            targets[name] = _targets(drops)[keep]
        return cls(params, targets, kernels, thresholds)

    def tensors(self) -> dict[str, npt.NDArray[np.float64]]:
        """The arrays to store in the oracle's safetensors file."""
        out: dict[str, npt.NDArray[np.float64]] = {}
        for name in self.params:
            out[f"{LOOKUP_PREFIX}{name}.params"] = np.ascontiguousarray(self.params[name])
            out[f"{LOOKUP_PREFIX}{name}.targets"] = np.ascontiguousarray(self.targets[name])
        return out

    def spec(
        self, weight: float, boost: float, chosen_on: Mapping[str, float | int | str]
    ) -> LookupSpec:
        """The sidecar settings for this lookup mixed with weight *weight*."""
        return LookupSpec(
            weight=float(weight),
            boost=float(boost),
            thresholds=self.thresholds,
            kernels=dict(self.kernels),
            rows={n: len(p) for n, p in self.params.items()},
            chosen_on=dict(chosen_on),
        )

    @classmethod
    def from_tensors(
        cls, tensors: Mapping[str, np.ndarray], spec: LookupSpec, *, source: str = "<oracle>"
    ) -> ContextLookup:
        """Rebuild from a file's tensors and its sidecar's :class:`LookupSpec`."""
        params, targets = {}, {}
        for name in spec.kernels:
            p = tensors.get(f"{LOOKUP_PREFIX}{name}.params")
            t = tensors.get(f"{LOOKUP_PREFIX}{name}.targets")
            if p is None or t is None:
                raise EnlilError(
                    f"{source}: the sidecar's lookup names {name!r} but the weights lack "
                    f"{LOOKUP_PREFIX}{name}.params / .targets; copy both files again"
                )
            params[name] = np.asarray(p, np.float64)
            targets[name] = np.asarray(t, np.float64)
        return cls(params, targets, dict(spec.kernels), spec.thresholds)

    def _process(self, name: str) -> _Fitted:
        if name not in self.params:
            raise EnlilError(f"lookup: no measured contexts of {name!r}")
        if name not in self._fitted:
            self._fitted[name] = _Fitted(self.params[name], self.targets[name], self.kernels[name])
        return self._fitted[name]

    def predict(
        self, phenomenon: str, units: npt.ArrayLike, *, exclude: npt.ArrayLike | None = None
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Predictive mean and standard deviation (noise included) of ``log(drop + 0.02)``.

        Args:
            phenomenon: Whose process.
            units: ``[B, d]`` normalised contexts (extra columns beyond ``d`` are ignored).
            exclude: ``[B]`` a stored row each query must not use (its own context, for
                leave-one-out figures), or -1.

        """
        gp = self._process(phenomenon)
        q = np.atleast_2d(np.asarray(units, np.float64))[:, : gp.params.shape[1]]
        k = gp.cross(q)
        mean = gp.kernel.mean + k @ gp.alpha
        std = gp.std(k)
        if exclude is not None:
            ex = np.asarray(exclude, np.int64)
            rows = np.flatnonzero(ex >= 0)
            if len(rows):
                col = gp.inverse[:, ex[rows]].T  # [b, N]
                diag = gp.inverse[ex[rows], ex[rows]]
                ka = np.einsum("ij,ij->i", k[rows], col)
                mean[rows] -= ka * gp.alpha[ex[rows]] / diag
                std[rows] = np.sqrt(std[rows] ** 2 + ka**2 / diag)
        return mean, std

    def vote(
        self, phenomenon: str, units: npt.ArrayLike, *, exclude: npt.ArrayLike | None = None
    ) -> npt.NDArray[np.float64]:
        """``[B, 3]`` the probabilities of categories 0, 1, 2 at *units* (see :meth:`predict`)."""
        mean, std = self.predict(phenomenon, units, exclude=exclude)
        t1, t2 = (math.log(t + OFFSET) for t in self.thresholds)
        p0 = _ndtr((t1 - mean) / std)
        p2 = 1.0 - _ndtr((t2 - mean) / std)
        out = np.stack([p0, np.clip(1.0 - p0 - p2, 0.0, 1.0), p2], axis=1)
        result: npt.NDArray[np.float64] = out / out.sum(axis=1, keepdims=True)
        return result


def lookup_probabilities(
    lookup: ContextLookup,
    phenomena: Sequence[str],
    params: npt.ArrayLike,
    phenomenon_probs: npt.ArrayLike,
    *,
    exclude: Mapping[str, npt.ArrayLike] | None = None,
) -> npt.NDArray[np.float64]:
    """``[B, 3]``: ``clear`` answers category 0, each phenomenon its surrogate.

    Args:
        lookup: The surrogates.
        phenomena: The oracle's phenomena (the phenomenon head's classes after ``clear``).
        params: ``[B, D]`` the perceived normalised contexts (the regression head).
        phenomenon_probs: ``[B, 1 + P]`` the phenomenon head's probabilities.
        exclude: Per phenomenon, ``[B]`` rows to leave out (see :meth:`ContextLookup.predict`).

    A phenomenon whose probability is at most :data:`MIN_SHARE` is skipped for that frame.

    """
    pp = np.asarray(phenomenon_probs, np.float64)
    q = np.asarray(params, np.float64)
    out = np.zeros((len(pp), 3))
    out[:, 0] = pp[:, 0]
    for i, name in enumerate(phenomena):
        share = pp[:, i + 1]
        rows = np.flatnonzero(share > MIN_SHARE)  # skip the phenomena the frame lacks
        if len(rows) == 0:
            continue
        ex = None if exclude is None or name not in exclude else np.asarray(exclude[name])[rows]
        out[rows] += share[rows, None] * lookup.vote(name, q[rows], exclude=ex)
    result: npt.NDArray[np.float64] = out / out.sum(axis=1, keepdims=True)
    return result


def mixed_probabilities(
    head: npt.ArrayLike, looked_up: npt.ArrayLike, weight: float
) -> npt.NDArray[np.float64]:
    """``weight · head + (1 - weight) · looked_up`` (rows sum to 1)."""
    out: npt.NDArray[np.float64] = weight * np.asarray(head, np.float64) + (
        1.0 - weight
    ) * np.asarray(looked_up, np.float64)
    return out


def boosted(probs: npt.ArrayLike, boost: float) -> npt.NDArray[np.float64]:
    """Category 1's probability times ``exp(boost)``, renormalised."""
    p = np.array(probs, np.float64)
    if boost:
        p[..., 1] *= math.exp(boost)
        p /= p.sum(axis=-1, keepdims=True)
    return p


def choose_mix(
    head: npt.ArrayLike,
    looked_up: npt.ArrayLike,
    labels: npt.ArrayLike,
    *,
    weights: Sequence[float] = (0.0, 0.25, 0.5, 0.75, 1.0),
    boosts: Sequence[float] = (0.0, 0.5, 1.0, 1.5),
) -> tuple[float, float, float]:
    """The ``(weight, boost)`` with the best macro-F1 on validation frames, and that macro-F1.

    Args:
        head: ``[F, 3]`` the category head's calibrated probabilities.
        looked_up: ``[F, 3]`` the lookup's (leave-one-out).
        labels: ``[F]`` true categories.
        weights: The head's shares tried.
        boosts: Category-1 boosts tried.

    Ties go to the larger weight (the head alone when the lookup does not help), then the
    smaller boost.

    """
    y = np.asarray(labels, np.int64)
    best: tuple[float, float, float] = (-1.0, 1.0, 0.0)
    for w in weights:
        mixed = mixed_probabilities(head, looked_up, w)
        for b in boosts:
            f1 = float(classification_metrics(boosted(mixed, b).argmax(axis=1), y)["macro_f1"])
            if (f1, w, -b) > (best[0], best[1], -best[2]):
                best = (f1, w, b)
    return best[1], best[2], best[0]
