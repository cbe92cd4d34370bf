"""Search strategies over the normalised context space ``[0, 1]^d``, as plugins.

A strategy proposes contexts in rounds (``ask``) and learns from their results (``tell``).
Every strategy is a deterministic function of its seed and of the results told, which is
what makes a search resumable: :func:`run_search` replays the archive's rounds into a
fresh strategy (checking each replayed proposal against the stored one) and carries on.

Built-ins in :data:`SEARCHES`: ``enlil`` (MAP-Elites with pyribs: a grid/CVT archive over
the context space whose objective peaks in the boundary category 1, so the search spreads
along the degraded band rather than over the common categories), ``random`` (uniform) and
``sobol`` (scrambled Sobol points, ``scipy.stats.qmc``).
"""

from __future__ import annotations

import warnings
from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from anunnaki.enlil._context import ContextResult, EnlilError
from anunnaki.errors import MissingExtraError
from anunnaki.plugins import Registry

__all__ = ["SEARCHES", "EnlilSearch", "RandomSearch", "Search", "SobolSearch"]

Array = npt.NDArray[np.float64]


class Search(ABC):
    """A search strategy over ``[0, 1]^d``.

    Args:
        dim: Number of parameters.
        seed: The only source of randomness.
        batch: Contexts per round.
        thresholds: The category thresholds (strategies may aim at a category's band).

    """

    name: ClassVar[str] = ""

    def __init__(
        self,
        dim: int,
        *,
        seed: int,
        batch: int = 16,
        thresholds: tuple[float, float] = (0.05, 0.10),
    ) -> None:
        if dim < 1 or batch < 1:
            raise EnlilError(f"{self.name}: need dim >= 1 and batch >= 1, got {dim}, {batch}")
        self.dim, self.seed, self.batch, self.thresholds = dim, seed, batch, thresholds
        self.asked = 0

    @abstractmethod
    def _propose(self, n: int) -> Array:
        """Return ``[n, dim]`` contexts in ``[0, 1]``."""

    def ask(self, n: int | None = None) -> Array:
        """Propose the next round (at most *n*, default :attr:`batch`)."""
        out = np.clip(np.asarray(self._propose(n or self.batch), np.float64), 0.0, 1.0)
        self.asked += len(out)
        return out

    def tell(self, params: Array, results: list[ContextResult]) -> None:  # noqa: B027
        """Learn from the round just asked (uninformed strategies ignore it)."""


class RandomSearch(Search):
    """Uniform random contexts; context *i* depends only on the seed and *i*."""

    name = "random"

    def _propose(self, n: int) -> Array:
        rows = [
            np.random.default_rng([self.seed, self.asked + i]).random(self.dim) for i in range(n)
        ]
        return np.asarray(rows, np.float64).reshape(n, self.dim)


class SobolSearch(Search):
    """Scrambled Sobol points (``scipy.stats.qmc.Sobol``), in sequence order."""

    name = "sobol"

    def __init__(self, dim: int, **kw: Any) -> None:
        super().__init__(dim, **kw)
        try:
            from scipy.stats import qmc
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise MissingExtraError("scipy", "enlil") from exc
        self._sobol = qmc.Sobol(d=dim, scramble=True, seed=self.seed)

    def _propose(self, n: int) -> Array:
        with warnings.catch_warnings():  # rounds need not be powers of 2: the order is kept
            warnings.simplefilter("ignore", UserWarning)
            return np.asarray(self._sobol.random(n), np.float64)


def _band_objective(drop: float, thresholds: tuple[float, float]) -> float:
    """1 in the middle of category 1's band, falling linearly with the distance to it."""
    low, high = thresholds
    mid, half = (low + high) / 2.0, max((high - low) / 2.0, 1e-9)
    return float(1.0 - abs(drop - mid) / half / 4.0)


class EnlilSearch(Search):
    """Diversity search aimed at the boundary category, on a pyribs ``GridArchive``.

    The archive's measures are the contexts themselves, on a grid of cells over ``[0, 1]^d``
    (coarser above 3 parameters); each cell keeps the context whose drop is closest to the
    middle of category 1's band (the objective). A round is a fraction ``explore`` of
    uniform contexts plus Gaussian mutations (``sigma``) of elites drawn with weights that
    favour boundary elites (``exp(sharpness * objective)``), so once a degraded context is
    found its neighbourhood is explored and the rare band gets many distinct cells. The
    first round is uniform.
    """

    name = "enlil"

    def __init__(
        self,
        dim: int,
        *,
        sigma: float = 0.06,
        explore: float = 0.25,
        sharpness: float = 8.0,
        **kw: Any,
    ) -> None:
        super().__init__(dim, **kw)
        try:
            from ribs.archives import GridArchive
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise MissingExtraError("ribs", "enlil") from exc
        per_axis = 20 if dim <= 2 else 10 if dim <= 3 else 4
        self.archive = GridArchive(
            solution_dim=dim, dims=[per_axis] * dim, ranges=[(0.0, 1.0)] * dim, seed=self.seed
        )
        self.sigma, self.explore, self.sharpness = sigma, explore, sharpness
        self._rng = np.random.default_rng([self.seed, 7])

    def _propose(self, n: int) -> Array:
        n = self.batch
        if self.archive.empty:
            return self._rng.random((n, self.dim))
        elites = self.archive.data()
        objective = np.asarray(elites["objective"], np.float64)
        weights = np.exp(self.sharpness * (objective - objective.max()))
        n_explore = round(self.explore * n)
        parents = self._rng.choice(len(objective), size=n - n_explore, p=weights / weights.sum())
        children = np.asarray(elites["solution"], np.float64)[parents]
        children = children + self._rng.normal(0.0, self.sigma, children.shape)
        fresh = self._rng.random((n_explore, self.dim))
        return np.asarray(np.clip(np.concatenate([children, fresh]), 0.0, 1.0), np.float64)

    def tell(self, params: Array, results: list[ContextResult]) -> None:
        objective = [_band_objective(r.drop, self.thresholds) for r in results]
        self.archive.add(np.asarray(params), np.asarray(objective), np.asarray(params))


SEARCHES: Registry[Search] = Registry(
    "search strategy", group="anunnaki.searches", hint="give --search enlil, random or sobol"
)
SEARCHES.register_lazy("enlil", "anunnaki.enlil._search:EnlilSearch")
SEARCHES.register_lazy("random", "anunnaki.enlil._search:RandomSearch")
SEARCHES.register_lazy("sobol", "anunnaki.enlil._search:SobolSearch")
