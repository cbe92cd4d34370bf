"""Sets of measured contexts for figures: ``random:N`` (uniform) and ``balanced:N``.

``anunnaki evaluate-detector --contexts random:N`` and ``anunnaki oracle evaluate`` both
draw contexts of a phenomenon, measure each one's F1, drop and category on a fixed batch
(:func:`anunnaki.enlil.evaluate_context`) and then report over them. A *random* set is
uniform over the normalised parameter space (what the paper's "random sampling of HSL
variations" figure shows); a *balanced* set has about N/3 contexts of each category, so
that the rare boundary category 1 weighs as much as the others in a macro-F1. Balanced sets
are drawn uniformly first; when category 0 or 1 is still short after ``max_draws`` uniform
draws (most of HSL's space compromises the rover's detector, for example), the rest is found
by bisection for category 1 on segments from the phenomenon's identity context (no effect,
category 0) to a measured category-2 context: the drop grows along the segment, so the band
in between is crossed, and the category-0 contexts met on the way are kept too.

Bisection stops at the first category-1 context, so a balanced set's category-1 contexts
(and many of its category-0 ones) sit near a band edge, where one more measurement on
other images may well give the other category. An *interior* set (``interior:N``, with a
``margin``) keeps only contexts whose measured drop lies farther than the margin from both
thresholds, and its bisection goes on towards the middle of category 1's band until it
lands inside the band's interior: the contexts whose category is well defined.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from anunnaki.datasets import Dataset
from anunnaki.enlil._context import (
    ContextResult,
    EnlilError,
    evaluate_context,
    normalise,
    resolve_phenomenon,
)
from anunnaki.lec import Detector
from anunnaki.phenomena import Phenomenon

__all__ = ["ContextDraw", "ContextSpec", "draw_contexts", "parse_contexts"]

ContextKind = Literal["random", "balanced", "interior"]
_SPEC = re.compile(r"^(random|balanced|interior):([0-9]+)$")


@dataclass(frozen=True)
class ContextSpec:
    """``random:N``, ``balanced:N`` or ``interior:N``: how many contexts, drawn how."""

    kind: ContextKind
    n: int

    def __str__(self) -> str:
        return f"{self.kind}:{self.n}"


def parse_contexts(text: str, kinds: Sequence[str] = ("random", "balanced")) -> ContextSpec:
    """Parse ``random:N`` / ``balanced:N`` (/ ``interior:N`` when in *kinds*).

    Raises:
        EnlilError: Another form, a kind not in *kinds*, or N < 1; the message shows the
            accepted forms.

    """
    match = _SPEC.match(text.strip())
    forms = " or ".join(f"{k}:N" for k in kinds)
    if match is None or match.group(1) not in kinds or int(match.group(2)) < 1:
        raise EnlilError(f"--contexts {text!r}: write {forms} with N >= 1, e.g. {kinds[0]}:50")
    kinds_by_name: dict[str, ContextKind] = {
        "random": "random", "balanced": "balanced", "interior": "interior"
    }  # fmt: skip
    return ContextSpec(kinds_by_name[match.group(1)], int(match.group(2)))


@dataclass(frozen=True)
class ContextDraw:
    """Measured contexts and how they were found.

    Attributes:
        results: One :class:`ContextResult` per context (order of drawing; balanced sets
            are interleaved by category).
        evaluations: Contexts measured to find them (> ``len(results)`` for balanced sets).
        short: Categories a balanced set could not fill: category → contexts missing.

    """

    results: list[ContextResult]
    evaluations: int
    short: dict[int, int]

    def counts(self) -> list[int]:
        """Contexts per category 0, 1, 2."""
        return [sum(r.category == c for r in self.results) for c in range(3)]


def draw_contexts(
    detector: Detector,
    batch: Dataset,
    phenomenon: str | Phenomenon,
    spec: ContextSpec,
    *,
    clean_f1: float,
    thresholds: tuple[float, float] = (0.05, 0.10),
    seed: int = 0,
    max_draws: int | None = None,
    margin: float = 0.0,
    **kwargs: Any,
) -> ContextDraw:
    """Draw and measure the contexts *spec* asks for (see the module docstring).

    Args:
        detector: The model assessed.
        batch: The fixed batch every context is measured on (:func:`fixed_batch`).
        phenomenon: Name, composition or instance.
        spec: ``random:N`` or ``balanced:N``.
        clean_f1: The model's F1 on the clean batch.
        thresholds: Relative drops of categories 1 and 2.
        seed: Draws and phenomenon seeds derive from it.
        max_draws: Uniform draws a balanced set may spend before it bisects segments
            (default ``3 * N``).
        margin: For ``interior:N``: how far from both thresholds a kept context's drop must
            lie (e.g. the measured drop noise); ignored by the other kinds.
        **kwargs: Passed to :func:`evaluate_context` (``score_threshold``, ``iou`` …).

    """
    phen = resolve_phenomenon(phenomenon)
    rng = np.random.default_rng(seed)
    d = len(phen.param_names)

    def measure(unit: npt.NDArray[np.float64]) -> ContextResult:
        return evaluate_context(
            detector, batch, phen, unit, clean_f1=clean_f1, thresholds=thresholds, seed=seed,
            **kwargs,
        )  # fmt: skip

    if spec.kind == "random":
        results = [measure(u) for u in rng.random((spec.n, d))]
        return ContextDraw(results, len(results), {})
    quota = [spec.n // 3 + (1 if c < spec.n % 3 else 0) for c in range(3)]
    budget = 3 * spec.n if max_draws is None else max_draws
    pools: list[list[ContextResult]] = [[], [], []]
    seen2: list[ContextResult] = []  # every category-2 context measured: segment ends
    evaluations = 0

    edge = margin if spec.kind == "interior" else 0.0

    def inside(result: ContextResult) -> bool:
        return all(abs(result.drop - t) > edge for t in thresholds) if edge > 0 else True

    def keep(result: ContextResult) -> None:
        if result.category == 2:
            seen2.append(result)
        if len(pools[result.category]) < quota[result.category] and inside(result):
            pools[result.category].append(result)

    while evaluations < budget and any(len(pools[c]) < quota[c] for c in range(3)):
        keep(measure(rng.random(d)))
        evaluations += 1
    identity = normalise(phen, phen.to_vector(phen.identity_params()))
    tries = 0
    # a margin of half the band or more leaves category 1 no interior: do not search for it
    wanted = (0, 1) if 2 * edge < thresholds[1] - thresholds[0] else (0,)
    while any(len(pools[c]) < quota[c] for c in wanted) and tries < spec.n + 2:
        tries += 1
        end = seen2[int(rng.integers(len(seen2)))].params if seen2 else rng.random(d)
        evaluations += _bisect(measure, keep, identity, end, band=thresholds, margin=edge)
    short = {c: quota[c] - len(pools[c]) for c in range(3) if len(pools[c]) < quota[c]}
    order = [pools[c][i] for i in range(max(quota)) for c in range(3) if i < len(pools[c])]
    return ContextDraw(order, evaluations, short)


def _bisect(
    measure: Callable[[npt.NDArray[np.float64]], ContextResult],
    keep: Callable[[ContextResult], None],
    low: npt.NDArray[np.float64],
    high: npt.NDArray[np.float64],
    *,
    band: tuple[float, float] = (0.05, 0.10),
    margin: float = 0.0,
) -> int:
    """Bisect the segment *low* (no effect) → *high* for category 1; keep what is measured.

    Stops at a drop inside the band shrunk by *margin* at both ends (with no margin: the
    first category-1 context); otherwise moves towards the band's middle.
    """
    a, b = 0.0, 1.0
    lo, hi = band[0] + margin, band[1] - margin
    middle = 0.5 * (band[0] + band[1])
    steps = 6 if margin <= 0 else 8  # down to 1/64 (1/256) of the segment
    for step in range(steps):
        t = 0.5 * (a + b)
        result = measure(np.clip(low + t * (high - low), 0.0, 1.0))
        keep(result)
        if result.category == 1 and (margin <= 0 or lo < result.drop < hi):
            return step + 1
        below = result.category == 0 or (result.category == 1 and result.drop <= middle)
        a, b = (t, b) if below else (a, t)
    return steps
