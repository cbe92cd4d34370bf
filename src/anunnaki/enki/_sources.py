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
  weight, which then perturbs the frame (e.g. the Enki selections of every domain at once);
- :class:`ArchiveMix` (the archive as a distribution): with probability ``share`` one of the
  selected contexts moved by Gaussian jitter (in ``[0, 1]^d``, clipped), else a uniform
  context;
- :class:`WorstOfK` (hardness judged against the network being trained): *k* candidate
  frames of an inner source, of which the training loop keeps the one with the highest loss
  under the current network (:class:`anunnaki.lec.CandidatePerturb`), or one at random
  (the control with the same rendering cost).

Where the phenomenon reports an occlusion mask (a raindrop: ``Phenomenon.occlusion``), a
source returns ``(image, mask)`` instead of the image (:data:`Perturbed`, as
:data:`anunnaki.lec.Perturb` allows): the training loop then turns the boxes the phenomenon
hides into ignore boxes (``TrainConfig.ignore``), for every source and worst-of-k's every
candidate alike. A phenomenon without a mask gives the image alone, as before.

By name (``anunnaki robustify --source``, benchmarks/robustify.py): :data:`CONTEXT_SOURCES`
builds ``archive``, ``archive_mix``, ``uniform`` and ``corruption_mix`` from a
:class:`SourceSpec`, and :func:`make_source` wraps one in :class:`WorstOfK` when asked.
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from anunnaki.enki._errors import EnkiError
from anunnaki.enlil import resolve_phenomenon, to_phenomenon_vector
from anunnaki.phenomena import PHENOMENA, Mask, Phenomenon
from anunnaki.plugins import Registry

__all__ = [
    "CONTEXT_SOURCES",
    "ArchiveContexts",
    "ArchiveMix",
    "ContextSource",
    "CorruptionMix",
    "MixedContexts",
    "SourceSpec",
    "UniformContexts",
    "WorstOfK",
    "make_source",
]

Image = npt.NDArray[np.uint8]
#: A perturbed frame: the image, or ``(image, mask)`` with the phenomenon's occlusion mask
#: where it reports one (the boxes it hides become ignore boxes in training).
Perturbed = Image | tuple[Image, Mask]


def _with_mask(out: Image, mask: Mask | None) -> Perturbed:
    return out if mask is None else (out, mask)


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
    def perturb(self, image: Image, rng: np.random.Generator) -> Perturbed:
        """Return *image* under one context of this source (never clean).

        With the phenomenon's occlusion mask where it has one: ``(image, mask)``.
        """

    def __call__(self, image: Image, rng: np.random.Generator) -> Perturbed:
        """The training loop's hook: clean with probability ``clean``, else :meth:`perturb`."""
        if rng.random() < self.clean:
            return image
        return self.perturb(image, rng)

    def describe(self) -> dict[str, Any]:
        """What the sidecar records about the source."""
        return {"kind": self.kind, "clean": self.clean}


def _apply(phen: Phenomenon, unit: npt.NDArray[np.float64], image: Image, seed: int) -> Perturbed:
    """*image* under the context *unit*, with the occlusion mask of that very draw, if any."""
    params = phen.from_vector(to_phenomenon_vector(phen, unit))
    out = phen.apply(image, params, seed=seed)
    return _with_mask(out, phen.occlusion(image.shape, params, seed))


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

    def perturb(self, image: Image, rng: np.random.Generator) -> Perturbed:
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

    def draw(self, rng: np.random.Generator) -> npt.NDArray[np.float64]:
        """One normalised context, uniform over ``[0, 1]^d`` (a subclass may restrict it)."""
        return rng.random(len(self.phenomenon.param_names))

    def perturb(self, image: Image, rng: np.random.Generator) -> Perturbed:
        """A context of :meth:`draw`."""
        unit = self.draw(rng)
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

    def perturb(self, image: Image, rng: np.random.Generator) -> Perturbed:
        """A random phenomenon of the library at a random strength (the Augmenter's draws)."""
        return _with_mask(*self.augmenter.occluded(image, rng))

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

    def perturb(self, image: Image, rng: np.random.Generator) -> Perturbed:
        """A frame of one inner source, drawn by weight."""
        k = int(rng.choice(len(self.sources), p=self.weights))
        return self.sources[k].perturb(image, rng)

    def describe(self) -> dict[str, Any]:
        """Kind, clean share, the inner sources (each described) and their weights."""
        return super().describe() | {
            "sources": [s.describe() for s in self.sources],
            "weights": [round(float(x), 6) for x in self.weights],
        }


class ArchiveMix(ContextSource):
    """The archive as a distribution: jittered elites mixed with uniform contexts.

    Each perturbed frame draws, with probability *share*, one of the *contexts* (the
    selected elites of an Enlil archive, :func:`~anunnaki.enki.select_contexts`) uniformly and
    adds Gaussian noise of standard deviation *jitter* to every coordinate of its normalised
    vector, clipped to ``[0, 1]``; otherwise a context uniform over ``[0, 1]^d`` (the random
    diversity AugMix and PRIME keep beside a targeted source). A context inside *exclude* (a
    held-out box) is drawn again.

    Args:
        phenomenon: The phenomenon (or composition) the contexts are of.
        contexts: ``[n, d]`` normalised contexts (the elites).
        share: Share of perturbed frames from the elites, in ``[0, 1]`` (0.5: half and half).
        jitter: Standard deviation of the noise, in normalised units (0.1: about the gap
            between neighbouring elites of a 64-context selection in 3 parameters).
        clean: Share of clean frames.
        exclude: ``[d, 2]`` lower and upper bounds of a box no drawn context may lie in.

    """

    kind = "archive_mix"

    #: Draws of one context before a box that leaves no room is reported.
    MAX_TRIES = 10_000

    def __init__(
        self,
        phenomenon: str | Phenomenon,
        contexts: npt.ArrayLike,
        *,
        share: float = 0.5,
        jitter: float = 0.1,
        clean: float = 0.3,
        exclude: npt.ArrayLike | None = None,
    ) -> None:
        super().__init__(clean=clean)
        self.elites = ArchiveContexts(phenomenon, contexts, clean=clean)
        self.phenomenon = self.elites.phenomenon
        d = len(self.phenomenon.param_names)
        if not 0.0 <= share <= 1.0 or not jitter >= 0.0:
            raise EnkiError(
                f"archive_mix: the share must be in [0, 1] and the jitter >= 0; got share "
                f"{share}, jitter {jitter}"
            )
        self.share, self.jitter = float(share), float(jitter)
        self.exclude = None if exclude is None else np.asarray(exclude, np.float64)
        if self.exclude is not None and self.exclude.shape != (d, 2):
            raise EnkiError(
                f"archive_mix: exclude is a [d, 2] box of {d} parameters "
                f"{list(self.phenomenon.param_names)}, got shape {self.exclude.shape}"
            )

    @property
    def contexts(self) -> npt.NDArray[np.float64]:
        """The elites, ``[n, d]``."""
        return self.elites.contexts

    def draw(self, rng: np.random.Generator) -> tuple[npt.NDArray[np.float64], bool]:
        """One normalised context, and whether it came from the elites."""
        d = len(self.phenomenon.param_names)
        for _ in range(self.MAX_TRIES):
            if rng.random() < self.share:
                elite = self.contexts[int(rng.integers(len(self.contexts)))]
                unit = np.clip(elite + rng.normal(0.0, self.jitter, d), 0.0, 1.0)
                from_elites = True
            else:
                unit, from_elites = rng.random(d), False
            box = self.exclude
            if box is None or not np.all((unit >= box[:, 0]) & (unit <= box[:, 1])):
                return unit, from_elites
        raise EnkiError(
            f"archive_mix: {self.MAX_TRIES} draws in a row fell in the excluded box "
            f"{self.exclude.tolist() if self.exclude is not None else None}; give a smaller box"
        )

    def perturb(self, image: Image, rng: np.random.Generator) -> Perturbed:
        """A jittered elite or a uniform context (:meth:`draw`)."""
        unit, _ = self.draw(rng)
        return _apply(self.phenomenon, unit, image, int(rng.integers(2**31 - 1)))

    def describe(self) -> dict[str, Any]:
        """Kind, clean share, phenomenon, number of elites, share, jitter (and the box)."""
        out = super().describe() | {
            "phenomenon": self.phenomenon.name,
            "contexts": len(self.contexts),
            "share": self.share,
            "jitter": self.jitter,
        }
        if self.exclude is not None:
            out["excluded_box"] = self.exclude.tolist()
        return out


class WorstOfK(ContextSource):
    """k candidate frames of an inner source; the training loop keeps the hardest.

    An :class:`anunnaki.lec.CandidatePerturb`: for each training frame that is not left clean
    (this source's own ``clean`` share; the inner source's is not used), the inner source
    renders *k* candidates. With ``select="hardest"`` the training loop keeps the one with
    the highest detector loss on the frame's own boxes under the network being trained (k
    no-grad forward passes, counted as ``select_forwards`` beside the optimiser steps);
    with ``select="random"`` one drawn at random (the same rendering, no selection: the
    control arm). Called without a network (:meth:`perturb`) it picks at random.

    Args:
        inner: The source the candidates come from.
        k: Candidates per perturbed frame (at least 2).
        select: ``"hardest"`` or ``"random"``.
        clean: Share of clean frames.

    """

    kind = "worst_of_k"

    def __init__(
        self,
        inner: ContextSource,
        *,
        k: int = 4,
        select: Literal["hardest", "random"] = "hardest",
        clean: float = 0.3,
    ) -> None:
        super().__init__(clean=clean)
        if k < 2 or select not in ("hardest", "random"):
            raise EnkiError(
                f"worst-of-k needs k >= 2 candidates and select 'hardest' or 'random'; got "
                f"k={k}, select={select!r}"
            )
        self.inner, self.k = inner, int(k)
        self.select: Literal["hardest", "random"] = select

    def candidates(self, image: Image, rng: np.random.Generator) -> list[Perturbed]:
        """The image alone (with probability ``clean``), else *k* frames of the inner source.

        Each frame with its occlusion mask where the phenomenon has one: the loop scores
        and trains each candidate with the boxes it hides as ignore boxes.
        """
        if rng.random() < self.clean:
            return [image]
        return [self.inner.perturb(image, rng) for _ in range(self.k)]

    def perturb(self, image: Image, rng: np.random.Generator) -> Perturbed:
        """Without a network to judge: *k* candidates rendered, one kept at random."""
        found = [self.inner.perturb(image, rng) for _ in range(self.k)]
        return found[int(rng.integers(self.k))]

    def describe(self) -> dict[str, Any]:
        """Kind, clean share, k, the selection and the inner source (described)."""
        return super().describe() | {
            "k": self.k,
            "select": self.select,
            "inner": self.inner.describe(),
        }


@dataclass(frozen=True)
class SourceSpec:
    """What a source built by name (:data:`CONTEXT_SOURCES`) is built from.

    Attributes:
        phenomenon: The domain's phenomenon (or composition).
        contexts: ``[n, d]`` normalised contexts selected from the archive (the elites);
            sources that do not use them ignore them.
        clean: Share of clean training frames.
        share: ``archive_mix``: share of perturbed frames from the elites.
        jitter: ``archive_mix``: standard deviation of the elites' jitter (normalised units).

    """

    phenomenon: str
    contexts: Any = None
    clean: float = 0.3
    share: float = 0.5
    jitter: float = 0.1

    def elites(self, name: str) -> npt.NDArray[np.float64]:
        """The contexts, refused when there are none."""
        if self.contexts is None or len(self.contexts) == 0:
            raise EnkiError(f"the {name} source needs the contexts selected from an archive")
        return np.asarray(self.contexts, np.float64)


def _archive(spec: SourceSpec) -> ContextSource:
    """Enki's first recipe: the selected contexts, each drawn uniformly (no jitter, no mix)."""
    return ArchiveContexts(spec.phenomenon, spec.elites("archive"), clean=spec.clean)


def _archive_mix(spec: SourceSpec) -> ContextSource:
    return ArchiveMix(
        spec.phenomenon, spec.elites("archive_mix"), share=spec.share, jitter=spec.jitter,
        clean=spec.clean,
    )  # fmt: skip


def _uniform(spec: SourceSpec) -> ContextSource:
    return UniformContexts(spec.phenomenon, clean=spec.clean)


def _corruption_mix(spec: SourceSpec) -> ContextSource:
    return CorruptionMix(clean=spec.clean)


#: Context sources by name (a :class:`~anunnaki.plugins.Registry`): each factory takes one
#: keyword, ``spec`` (:class:`SourceSpec`). Built in: ``archive`` (the selected contexts),
#: ``archive_mix`` (:class:`ArchiveMix`), ``uniform`` (:class:`UniformContexts`),
#: ``corruption_mix`` (:class:`CorruptionMix` over the whole library). Third parties add
#: theirs under the ``anunnaki.context_sources`` entry-point group.
CONTEXT_SOURCES: Registry[ContextSource] = Registry(
    "context source",
    group="anunnaki.context_sources",
    kind=ContextSource,
    error=EnkiError,
    logger="anunnaki.enki",
)
for _name, _factory in (
    ("archive", _archive),
    ("archive_mix", _archive_mix),
    ("uniform", _uniform),
    ("corruption_mix", _corruption_mix),
):
    CONTEXT_SOURCES.register(_factory, name=_name)


def make_source(
    name: str,
    spec: SourceSpec,
    *,
    k: int = 1,
    select: Literal["hardest", "random"] = "hardest",
) -> ContextSource:
    """The source *name* of :data:`CONTEXT_SOURCES`, wrapped in :class:`WorstOfK` if ``k > 1``.

    Args:
        name: A registered source name.
        spec: What it is built from.
        k: Candidates per perturbed frame; 1: the source itself.
        select: Worst-of-k's choice (``"hardest"``, or ``"random"`` for the control).

    Raises:
        EnkiError: An unknown name (listing the valid ones), or bad options.

    """
    if k < 1:
        raise EnkiError(f"k is the number of candidates per frame, at least 1; got {k}")
    source = CONTEXT_SOURCES.create(name, spec=spec)
    if k == 1:
        return source
    return WorstOfK(source, k=k, select=select, clean=spec.clean)
