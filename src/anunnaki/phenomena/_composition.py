"""Compositions: several phenomena applied in order, as one phenomenon.

A composition's parameter space is the concatenation of its steps' spaces, each name prefixed
with the step's label (``fog.density``, ``raindrop.x``); a phenomenon used twice gets labels
``raindrop``, ``raindrop_2``, ... So a searcher sees one fixed-length vector, and "three
raindrops in fog" is just ``compose("fog", "raindrop", "raindrop", "raindrop")``.

A step may pin some of its parameters: ``compose(("rain", {"slant": 20}), "fog")`` keeps the
slant at 20 degrees and leaves it out of the search space.

A :class:`Composition` is built from phenomena (instances); names are resolved before, by
:func:`~anunnaki.phenomena.compose` and the ``+`` names of
:data:`~anunnaki.phenomena.PHENOMENA`, so that this module does not know the slot.

Each step gets its own seed, ``SeedSequence(seed).spawn(len(steps))[i]``, so adding or
changing a step never changes the randomness of the others.

A composition's occlusion mask combines its steps' (:meth:`Composition.occlusion_mask`).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, TypeAlias

import numpy as np

from anunnaki.phenomena._base import Image, Mask, Phenomenon, PhenomenonError

__all__ = ["Composition", "CompositionStep", "Step"]

#: What a composition step is given as: a phenomenon, or one with pinned parameters.
Step: TypeAlias = "Phenomenon | tuple[Phenomenon, Mapping[str, float]]"


@dataclass(frozen=True)
class CompositionStep:
    """One resolved step: its label (the parameter prefix), phenomenon and pinned parameters."""

    label: str
    phenomenon: Phenomenon
    fixed: Mapping[str, float]

    @property
    def free_names(self) -> tuple[str, ...]:
        """The step's parameter names that are part of the composition's space."""
        return tuple(n for n in self.phenomenon.param_names if n not in self.fixed)


def _child_seed(child: np.random.SeedSequence) -> int:
    return int(child.generate_state(1, dtype=np.uint64)[0])


class Composition(Phenomenon):
    """An ordered sequence of phenomena, itself a :class:`Phenomenon`.

    Args:
        *steps: Each a :class:`Phenomenon` instance or a ``(phenomenon, pinned_params)``
            pair (by name: :func:`~anunnaki.phenomena.compose`).

    Raises:
        PhenomenonError: No steps, a step that is no phenomenon, or invalid pinned
            parameters.

    """

    def __init__(self, *steps: Step) -> None:
        if not steps:
            raise PhenomenonError("a composition needs at least one step", phenomenon="compose")
        resolved: list[CompositionStep] = []
        used: dict[str, int] = {}
        for step in steps:
            target: Any
            fixed_raw: Mapping[str, Any]
            if isinstance(step, tuple):
                if len(step) != 2 or not isinstance(step[1], Mapping):
                    raise PhenomenonError(
                        f"a step with pinned parameters must be a (phenomenon, {{name: value}}) "
                        f"pair, got {step!r}",
                        phenomenon="compose",
                    )
                target, fixed_raw = step
            else:
                target, fixed_raw = step, {}
            if not isinstance(target, Phenomenon):
                raise PhenomenonError(
                    f"a composition step must be a phenomenon, got {type(target).__name__} "
                    "(compose() and the 'a+b' names take registered names)",
                    phenomenon="compose",
                )
            phenomenon = target
            fixed = _pin(phenomenon, fixed_raw)
            base = re.sub(r"\W", "_", phenomenon.name)
            used[base] = used.get(base, 0) + 1
            label = base if used[base] == 1 else f"{base}_{used[base]}"
            resolved.append(CompositionStep(label, phenomenon, fixed))
        self.steps: tuple[CompositionStep, ...] = tuple(resolved)
        self.name = "+".join(step.phenomenon.name for step in self.steps)
        self.params = tuple(
            step.phenomenon.spec(name).prefixed(step.label)
            for step in self.steps
            for name in step.free_names
        )
        self.stochastic = any(step.phenomenon.stochastic for step in self.steps)

    def split(self, params: Mapping[str, Any]) -> dict[str, dict[str, float]]:
        """Validate *params* and return each step's complete parameters, keyed by label."""
        valid = self.validate(params)
        return {
            step.label: {
                **step.fixed,
                **{name: valid[f"{step.label}.{name}"] for name in step.free_names},
            }
            for step in self.steps
        }

    def strength_params(self, strength: float) -> dict[str, float]:
        """Every step at the same strength (pinned parameters stay pinned)."""
        s = self._check_strength(strength)
        merged: dict[str, float] = {}
        for step in self.steps:
            sub = step.phenomenon.strength_params(s)
            merged.update({f"{step.label}.{name}": sub[name] for name in step.free_names})
        return self.validate(merged)

    def perturb(self, image: Image, params: dict[str, float], seed: int) -> Image:
        """Apply the steps in order, step *i* with the *i*-th spawned seed."""
        per_step = self.split(params)
        children = np.random.SeedSequence(seed).spawn(len(self.steps))
        out = image
        for step, child in zip(self.steps, children, strict=True):
            out = step.phenomenon.apply(out, per_step[step.label], _child_seed(child))
        return out

    def occlusion_mask(
        self, height: int, width: int, params: dict[str, float], seed: int
    ) -> Mask | None:
        """The steps' masks combined: a pixel is as hidden as all its steps together hide it.

        Step *i* is asked with the *i*-th spawned seed, as :meth:`perturb` applies it; a pixel
        that steps hide by shares ``m_i`` is hidden by ``1 - prod(1 - m_i)`` (two drops
        over it hide it at least as much as either). ``None`` when no step reports a mask.
        """
        per_step = self.split(params)
        children = np.random.SeedSequence(seed).spawn(len(self.steps))
        combined: Mask | None = None
        for step, child in zip(self.steps, children, strict=True):
            mask = step.phenomenon.occlusion(
                (height, width), per_step[step.label], _child_seed(child)
            )
            if mask is None:
                continue
            combined = (
                mask
                if combined is None
                else (1.0 - (1.0 - combined) * (1.0 - mask)).astype(np.float32)
            )
        return combined

    def __repr__(self) -> str:
        parts = [
            f"({step.phenomenon!r}, {dict(step.fixed)!r})" if step.fixed else repr(step.phenomenon)
            for step in self.steps
        ]
        return f"Composition({', '.join(parts)})"


def _pin(phenomenon: Phenomenon, fixed: Mapping[str, Any]) -> dict[str, float]:
    """Check pinned values against the step's specs (unknown names, bounds, finiteness)."""
    pinned: dict[str, float] = {}
    for key, value in fixed.items():
        spec = phenomenon.spec(key)  # raises for an unknown name, listing the valid ones
        pinned[key] = phenomenon._check_value(spec, value)
    return pinned
