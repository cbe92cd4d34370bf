"""One evaluation of Enlil's search: a context's F1, drop and category on a fixed batch.

A *context* is a point of a phenomenon's parameter space. The search works in the
normalised cube ``[0, 1]^d`` (each parameter scaled by its ``bounds()``), so the archive,
the grid of cells and the learned oracle's regression target share one scale;
:func:`to_phenomenon_vector` and :func:`normalise` convert between the two.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from anunnaki import lec  # lec.evaluate_detector, lec.predict: torch at first call
from anunnaki.datasets import Dataset, load_split
from anunnaki.errors import AnunnakiError
from anunnaki.lec import Detector
from anunnaki.oracles import category_for_drop
from anunnaki.phenomena import PHENOMENA, CameraEncoding, Phenomenon

__all__ = [
    "ContextResult",
    "EnlilError",
    "evaluate_context",
    "fixed_batch",
    "normalise",
    "relative_drop",
    "resolve_phenomenon",
    "to_phenomenon_vector",
]


class EnlilError(AnunnakiError):
    """Bad input to Enlil (a vector, a batch, an archive); the message says how to fix it."""


@dataclass(frozen=True)
class ContextResult:
    """What one context does to the model.

    Attributes:
        params: The context as a normalised vector in ``[0, 1]^d`` (phenomenon order).
        f1: The model's F1 on the fixed batch under the context.
        drop: Relative F1 drop ``max(0, (clean_f1 - f1) / clean_f1)``.
        category: Behavior category of the drop (docs/oracles.md): 0, 1 or 2.

    """

    params: npt.NDArray[np.float64]
    f1: float
    drop: float
    category: int


def resolve_phenomenon(phenomenon: str | Phenomenon) -> Phenomenon:
    """Return the phenomenon for a registry name or composition (``rain+brightness``)."""
    return PHENOMENA.create(phenomenon) if isinstance(phenomenon, str) else phenomenon


def _bounds(phen: Phenomenon) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    b = np.asarray(phen.bounds(), dtype=np.float64).reshape(-1, 2)
    return b[:, 0], b[:, 1]


def _check_unit(
    phen: Phenomenon, vector: Sequence[float] | npt.ArrayLike
) -> npt.NDArray[np.float64]:
    array = np.asarray(vector, dtype=np.float64)
    d = len(phen.param_names)
    if array.shape != (d,):
        raise EnlilError(
            f"{phen.name}: a context vector needs shape ({d},) for parameters "
            f"{list(phen.param_names)}, got shape {array.shape}"
        )
    if not np.all(np.isfinite(array)) or np.any(array < 0.0) or np.any(array > 1.0):
        raise EnlilError(
            f"{phen.name}: normalised context {array.tolist()} must be finite and in [0, 1] "
            "for every parameter (scale by the phenomenon's bounds() first, see normalise())"
        )
    return array


def to_phenomenon_vector(
    phenomenon: str | Phenomenon, unit: Sequence[float] | npt.ArrayLike
) -> npt.NDArray[np.float64]:
    """Map a normalised vector in ``[0, 1]^d`` to the phenomenon's own parameter vector."""
    phen = resolve_phenomenon(phenomenon)
    array = _check_unit(phen, unit)
    low, high = _bounds(phen)
    raw = low + array * (high - low)
    return np.clip(raw, low, high)


def normalise(
    phenomenon: str | Phenomenon, vector: Sequence[float] | npt.ArrayLike
) -> npt.NDArray[np.float64]:
    """Map a phenomenon parameter vector (``to_vector`` order) into ``[0, 1]^d``."""
    phen = resolve_phenomenon(phenomenon)
    array = np.asarray(vector, dtype=np.float64)
    if array.shape != (len(phen.param_names),):
        raise EnlilError(
            f"{phen.name}: a parameter vector needs shape ({len(phen.param_names)},) for "
            f"{list(phen.param_names)}, got shape {array.shape}"
        )
    low, high = _bounds(phen)
    span = np.where(high > low, high - low, 1.0)
    return np.clip((array - low) / span, 0.0, 1.0)


def relative_drop(clean_f1: float, f1: float) -> float:
    """``max(0, (clean_f1 - f1) / clean_f1)``; 0 when the clean F1 is 0 (nothing to lose)."""
    if clean_f1 <= 0.0:
        return 0.0
    return max(0.0, (clean_f1 - f1) / clean_f1)


def fixed_batch(
    dataset: str | Path | Dataset, split: str = "val", n: int = 32, seed: int = 0
) -> Dataset:
    """The fixed batch every context is measured on: *n* images of *split*, drawn by *seed*.

    Args:
        dataset: A dataset folder (anything :func:`anunnaki.datasets.load_split` reads) or
            an already loaded split (then *split* is ignored).
        split: The split to draw from (``val`` for the search, ``test`` for figures).
        n: Images in the batch; the whole split when it has fewer.
        seed: Which images (sorted indices, so the batch does not depend on draw order).

    Returns:
        The batch with its images decoded and held in memory: every context is measured
        on the same images, so they are read from disk once, not once per context.

    Raises:
        EnlilError: *n* is not positive or the split is empty.

    """
    if n <= 0:
        raise EnlilError(f"fixed_batch: n must be a positive number of images, got {n}")
    data = dataset if isinstance(dataset, Dataset) else load_split(dataset, split)
    if len(data) == 0:
        raise EnlilError(f"fixed_batch: split {split!r} of {dataset} has no images")
    if n >= len(data):
        return data.in_memory()
    rng = np.random.default_rng(seed)
    chosen = np.sort(rng.choice(len(data), size=n, replace=False))
    return data.subset(chosen).in_memory()


def evaluate_context(
    detector: Detector,
    batch: Dataset,
    phenomenon: str | Phenomenon,
    vector: Sequence[float] | npt.ArrayLike,
    *,
    clean_f1: float,
    thresholds: tuple[float, float] = (0.05, 0.10),
    seed: int,
    encoding: CameraEncoding | None = None,
    **kwargs: Any,
) -> ContextResult:
    """Measure one context: the model's F1 on *batch* perturbed by *phenomenon* at *vector*.

    Args:
        detector: The model assessed.
        batch: The fixed batch (:func:`fixed_batch`).
        phenomenon: Name, composition name or instance.
        vector: The context, normalised to ``[0, 1]^d`` (see :func:`to_phenomenon_vector`).
        clean_f1: The model's F1 on the unperturbed batch (the reference of the drop).
        thresholds: Relative drops above which the category is 1 and 2.
        seed: Image *i* of the batch gets the phenomenon with seed ``seed + i``.
        encoding: The camera's encoding, applied after the phenomenon (*clean_f1* must
            have been measured through it too).
        **kwargs: Passed to :func:`anunnaki.lec.evaluate_detector` (``iou``, ``batch_size``).

    Raises:
        EnlilError: The vector has the wrong shape or leaves ``[0, 1]``.

    """
    phen = resolve_phenomenon(phenomenon)
    unit = _check_unit(phen, vector)
    params = phen.from_vector(to_phenomenon_vector(phen, unit))
    metrics = lec.evaluate_detector(
        detector, batch, phenomenon=phen, params=params, seed=seed, encoding=encoding, **kwargs
    )
    f1 = float(metrics.f1)
    drop = relative_drop(clean_f1, f1)
    return ContextResult(
        params=unit.copy(), f1=f1, drop=drop, category=category_for_drop(drop, thresholds)
    )
