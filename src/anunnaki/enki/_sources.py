"""Context sources: what perturbs each training frame of a fine-tune (``TrainConfig.perturb``).

A source is called on every training image, after the zoom, flip and recolouring of the
training loop, with a random stream of its own (:data:`anunnaki.lec.Perturb`): arms that
differ only in their source train on the same images, in the same order, with the same
geometric augmentation. With probability ``clean`` the image stays clean; otherwise:

- :class:`ArchiveContexts` (Enki): one of the selected contexts, uniformly;
- :class:`UniformContexts` (random-context augmentation): a context drawn uniformly over the
  phenomenon's normalised parameter space ``[0, 1]^d``;
- :class:`CorruptionMix` (AugMix-style): a phenomenon of the library drawn uniformly, at a
  random strength (:class:`anunnaki.lec.Augmenter`'s rule);
- :class:`MixedContexts` (one model for several domains): one of several sources drawn by
  weight, which then perturbs the frame (e.g. the Enki selections of every domain at once).
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from anunnaki.enki._errors import EnkiError
from anunnaki.enlil import resolve_phenomenon, to_phenomenon_vector
from anunnaki.phenomena import PHENOMENA, Phenomenon

__all__ = ["ArchiveContexts", "ContextSource", "CorruptionMix", "MixedContexts", "UniformContexts"]

Image = npt.NDArray[np.uint8]


class ContextSource(abc.ABC):
    """Base of the sources: the clean share, the call, a JSON description.

    Args:
        clean: Share of training frames left clean, in ``[0, 1)``.

    """

    kind = "source"

    def __init__(self, *, clean: float = 0.3) -> None:
        if not 0.0 <= clean < 1.0:
            raise EnkiError(f"the clean share must be in [0, 1), got {clean}")
        self.clean = clean

    @abc.abstractmethod
    def perturb(self, image: Image, rng: np.random.Generator) -> Image:
        """Return *image* under one context of this source (never clean)."""

    def __call__(self, image: Image, rng: np.random.Generator) -> Image:
        """The training loop's hook: clean with probability ``clean``, else :meth:`perturb`."""
        if rng.random() < self.clean:
            return image
        return self.perturb(image, rng)

    def describe(self) -> dict[str, Any]:
        """What the sidecar records about the source."""
        return {"kind": self.kind, "clean": self.clean}


def _apply(phen: Phenomenon, unit: npt.NDArray[np.float64], image: Image, seed: int) -> Image:
    params = phen.from_vector(to_phenomenon_vector(phen, unit))
    return phen.apply(image, params, seed=seed)


class ArchiveContexts(ContextSource):
    """Enki's source: the contexts selected from an archive (:func:`select_contexts`).

    Args:
        phenomenon: The phenomenon (or composition) the contexts are of.
        contexts: ``[n, d]`` normalised contexts.
        clean: Share of clean frames.

    """

    kind = "archive"

    def __init__(
        self, phenomenon: str | Phenomenon, contexts: npt.ArrayLike, *, clean: float = 0.3
    ) -> None:
        super().__init__(clean=clean)
        self.phenomenon = resolve_phenomenon(phenomenon)
        self.contexts = np.asarray(contexts, np.float64)
        d = len(self.phenomenon.param_names)
        if self.contexts.ndim != 2 or self.contexts.shape[1] != d or len(self.contexts) == 0:
            raise EnkiError(
                f"{self.phenomenon.name}: give at least one context of {d} parameters "
                f"{list(self.phenomenon.param_names)}, got shape {self.contexts.shape}"
            )

    def perturb(self, image: Image, rng: np.random.Generator) -> Image:
        """One of the contexts, drawn uniformly."""
        unit = self.contexts[int(rng.integers(len(self.contexts)))]
        return _apply(self.phenomenon, unit, image, int(rng.integers(2**31 - 1)))

    def describe(self) -> dict[str, Any]:
        """Kind, clean share, phenomenon and number of contexts."""
        return super().describe() | {
            "phenomenon": self.phenomenon.name,
            "contexts": len(self.contexts),
        }


class UniformContexts(ContextSource):
    """Random-context augmentation: contexts uniform over ``[0, 1]^d`` of one phenomenon."""

    kind = "uniform"

    def __init__(self, phenomenon: str | Phenomenon, *, clean: float = 0.3) -> None:
        super().__init__(clean=clean)
        self.phenomenon = resolve_phenomenon(phenomenon)

    def perturb(self, image: Image, rng: np.random.Generator) -> Image:
        """A uniformly random context."""
        unit = rng.random(len(self.phenomenon.param_names))
        return _apply(self.phenomenon, unit, image, int(rng.integers(2**31 - 1)))

    def describe(self) -> dict[str, Any]:
        """Kind, clean share and phenomenon."""
        return super().describe() | {"phenomenon": self.phenomenon.name}


class CorruptionMix(ContextSource):
    """A corruption mix: each frame a random phenomenon of the library at a random strength.

    Args:
        phenomena: The library (default: every registered phenomenon).
        exclude: Names left out (a family held out from training).
        clean: Share of clean frames.

    """

    kind = "corruption_mix"

    def __init__(
        self,
        phenomena: Sequence[str | Phenomenon] | None = None,
        *,
        exclude: Sequence[str] = (),
        clean: float = 0.3,
    ) -> None:
        super().__init__(clean=clean)
        from anunnaki.lec import Augmenter

        names = list(phenomena) if phenomena is not None else list(PHENOMENA.names())
        for name in exclude:
            PHENOMENA.create(name)  # an unknown name fails, listing the valid ones
        kept = [p for p in names if (p if isinstance(p, str) else p.name) not in set(exclude)]
        if not kept:
            raise EnkiError(f"the corruption mix has no phenomenon left after excluding {exclude}")
        self.augmenter = Augmenter(kept, probability=1.0)

    def perturb(self, image: Image, rng: np.random.Generator) -> Image:
        """A random phenomenon of the library at a random strength."""
        return self.augmenter(image, rng)

    def describe(self) -> dict[str, Any]:
        """Kind, clean share and the library."""
        return super().describe() | {"phenomena": self.augmenter.names}


class MixedContexts(ContextSource):
    """Several sources in one: each perturbed frame goes to one of them, drawn by weight.

    The training set of one model for several domains: e.g. the Enki selection of every
    domain, ``MixedContexts([ArchiveContexts("hsl", a), ArchiveContexts("fog", b)])``. The
    clean share is this source's own (the inner sources' ``clean`` is not used: a drawn
    source always perturbs, :meth:`ContextSource.perturb`).

    Args:
        sources: The inner sources (at least one).
        weights: Their relative weights (default: equal).
        clean: Share of clean frames.

    """

    kind = "mixed"

    def __init__(
        self,
        sources: Sequence[ContextSource],
        *,
        weights: Sequence[float] | None = None,
        clean: float = 0.3,
    ) -> None:
        super().__init__(clean=clean)
        self.sources = list(sources)
        if not self.sources:
            raise EnkiError("a mixed context source needs at least one source")
        w = np.ones(len(self.sources)) if weights is None else np.asarray(weights, np.float64)
        if (
            w.shape != (len(self.sources),)
            or not np.all(np.isfinite(w))
            or w.min() < 0
            or (w.sum() <= 0)
        ):
            raise EnkiError(
                f"give one non-negative weight per source ({len(self.sources)}), at least one "
                f"positive; got {list(np.atleast_1d(w))}"
            )
        self.weights = w / w.sum()

    def perturb(self, image: Image, rng: np.random.Generator) -> Image:
        """A frame of one inner source, drawn by weight."""
        k = int(rng.choice(len(self.sources), p=self.weights))
        return self.sources[k].perturb(image, rng)

    def describe(self) -> dict[str, Any]:
        """Kind, clean share, the inner sources (each described) and their weights."""
        return super().describe() | {
            "sources": [s.describe() for s in self.sources],
            "weights": [round(float(x), 6) for x in self.weights],
        }
