"""RELAX operators: fuzzy membership functions that turn observations into utilities.

RELAX (Whittle et al., paper §2.5, Table 1) lets a requirement say how much deviation it
tolerates. Here each operator maps what is observed to a utility in ``[0, 1]`` through a
membership function whose shape comes from the goal model. See docs/relax.md for every
operator's formula and a worked example.

The design has two layers:

* **Specs** — pydantic models, one per operator, in the discriminated union
  :data:`RelaxSpec` (tag: ``operator``). The goal-model schema embeds it as
  ``relax: RelaxSpec | None``; the specs only check shapes (positive tolerances, finite
  numbers, non-empty expressions) and say what to write instead.
* **Operators** — what :func:`build_operator` makes from a spec. They are pure: no clock,
  no I/O, no state besides the precomputed shape, so the evaluator, tests and replay get the
  same number for the same input. There are three kinds, told apart by class (and
  :attr:`RelaxOperator.kind`):

  - :class:`AtemporalOperator` (``shall``, ``as_close_as_possible_to_*``,
    ``as_few_as_possible``, ``as_many_as_possible``): ``utility(value) -> float``. The
    evaluator calls these tens of thousands of times per second, so each is a few float
    operations on values precomputed in ``__init__``, on a class with ``__slots__``.
  - :class:`MayOrOperator` (``may_or``): the fuzzy OR of the alternatives' values, with
    Kleene's rule for unknown ones.
  - :class:`TemporalOperator` (``eventually``, ``until``, ``before``, ``after``,
    ``as_early_as_possible``, ``as_late_as_possible``):
    ``utility_at(p, e, now) -> float | None`` over a :class:`History` of timestamped
    samples of the condition ``p`` (and of the event ``e`` where there is one).

Temporal operators are meant for a monitor that runs forever, so they look at a *sliding*
view of the past: the samples from the one in force at ``now - horizon`` up to ``now``.
Each operator's :attr:`~RelaxOperator.horizon` says how many seconds that is (``inf`` when
the verdict of the latest episode must be remembered however old it is); the evaluator may
call ``history.prune(now - op.horizon)`` after each evaluation without changing any result,
and :class:`History` additionally caps its length so memory stays bounded.

Unknown values follow one rule everywhere (docs/relax.md, "Unknown values"):

1. If a history the operator reads has no known sample in its view, the result is ``None``.
2. A past stretch whose state is unknown is never taken as holding. Where not-holding time
   is *summed* (``until``) it does not count either; where a delay or gap is *measured* to
   or from a holding stretch, it is simply time that passes.
3. If the current state (the last sample at or before ``now``) is unknown, the operator is
   evaluated with that stretch completed as holding and as not holding (for each condition
   read); if the results agree, that is the result, otherwise ``None``.

The RELAX code is split by responsibility: the specs in :mod:`anunnaki.goals._relax_specs`,
the samples and their sliding views in :mod:`anunnaki.goals._history`, the operators on
values in :mod:`anunnaki.goals._relax_ops`, the operators over time in
:mod:`anunnaki.goals._relax_temporal`. This module builds an operator from its spec
(:func:`build_operator`) and gathers the names the rest of :mod:`anunnaki.goals` uses.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Final

from anunnaki.goals._history import DEFAULT_MAXLEN, History
from anunnaki.goals._relax_ops import (
    AtemporalOperator,
    MayOrOperator,
    RelaxOperator,
    _Clamp,
    _RampDown,
    _RampUp,
    _Triangle,
)
from anunnaki.goals._relax_specs import (
    AfterSpec,
    AsCloseAsPossibleToFrequencySpec,
    AsCloseAsPossibleToQuantitySpec,
    AsEarlyAsPossibleSpec,
    AsFewAsPossibleSpec,
    AsLateAsPossibleSpec,
    AsManyAsPossibleSpec,
    BeforeSpec,
    EventuallySpec,
    MayOrSpec,
    RelaxSpec,
    RelaxSpecBase,
    ShallSpec,
    UntilSpec,
)
from anunnaki.goals._relax_temporal import (
    TemporalOperator,
    _After,
    _AsLate,
    _Before,
    _Eventually,
    _Until,
)

__all__ = [
    "DEFAULT_MAXLEN",
    "AfterSpec",
    "AsCloseAsPossibleToFrequencySpec",
    "AsCloseAsPossibleToQuantitySpec",
    "AsEarlyAsPossibleSpec",
    "AsFewAsPossibleSpec",
    "AsLateAsPossibleSpec",
    "AsManyAsPossibleSpec",
    "AtemporalOperator",
    "BeforeSpec",
    "EventuallySpec",
    "History",
    "MayOrOperator",
    "MayOrSpec",
    "RelaxOperator",
    "RelaxSpec",
    "RelaxSpecBase",
    "ShallSpec",
    "TemporalOperator",
    "UntilSpec",
    "build_operator",
]


def build_operator(spec: RelaxSpecBase) -> RelaxOperator:
    """Build the operator a spec describes.

    Args:
        spec: Any member of :data:`RelaxSpec`.

    Returns:
        An :class:`AtemporalOperator`, :class:`MayOrOperator` or :class:`TemporalOperator`.

    Raises:
        TypeError: ``spec`` is not a RELAX spec.

    """
    for cls in type(spec).__mro__:
        builder = _BUILDERS.get(cls)
        if builder is not None:
            return builder(spec)
    raise TypeError(f"not a RELAX spec: {spec!r}")


def _close_to(
    spec: AsCloseAsPossibleToFrequencySpec | AsCloseAsPossibleToQuantitySpec,
) -> RelaxOperator:
    if spec.side == "at_least":
        return _RampUp(spec, spec.target, spec.tolerance)
    if spec.side == "at_most":
        return _RampDown(spec, spec.target, spec.tolerance)
    return _Triangle(spec, spec.target, spec.tolerance)


#: Which operator each kind of spec builds.
_BUILDERS: Final[dict[type[RelaxSpecBase], Callable[[Any], RelaxOperator]]] = {
    ShallSpec: _Clamp,
    MayOrSpec: MayOrOperator,
    AsCloseAsPossibleToFrequencySpec: _close_to,
    AsCloseAsPossibleToQuantitySpec: _close_to,
    AsFewAsPossibleSpec: lambda spec: _RampDown(spec, spec.target, spec.tolerance),
    AsManyAsPossibleSpec: lambda spec: _RampUp(spec, spec.target, spec.tolerance),
    EventuallySpec: lambda spec: _Eventually(spec, spec.within, spec.tolerance),
    UntilSpec: _Until,
    BeforeSpec: _Before,
    AfterSpec: _After,
    AsEarlyAsPossibleSpec: lambda spec: _Eventually(spec, 0.0, spec.tolerance),
    AsLateAsPossibleSpec: _AsLate,
}
