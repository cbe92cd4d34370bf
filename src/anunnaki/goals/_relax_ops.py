"""RELAX operators on values: the operator base, the atemporal shapes and ``may_or``.

:class:`RelaxOperator` is what every built operator shares (spec, horizon, kind). The
atemporal operators (``shall``, ``as_close_as_possible_to_*``, ``as_few_as_possible``,
``as_many_as_possible``) map one observed value to a utility through a clamp, a ramp or a
triangle precomputed in ``__init__`` — the evaluator's hot path, kept to a few float
operations. :class:`MayOrOperator` is the fuzzy OR of alternatives, three-valued by
Kleene's rule. Operators over time live in :mod:`anunnaki.goals._relax_temporal`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import ClassVar, Literal

from anunnaki.goals._relax_specs import MayOrSpec, RelaxSpecBase

__all__ = ["AtemporalOperator", "MayOrOperator", "RelaxOperator"]


def _unit(u: float) -> float:
    """Clamp to [0, 1]; NaN gives 0."""
    if u >= 1.0:
        return 1.0
    if u > 0.0:
        return u
    return 0.0


def _decay(x: float, inv: float) -> float:
    """``1 - x * inv`` clamped to [0, 1]: 1 for x ≤ 0, 0 for x ≥ 1/inv."""
    return _unit(1.0 - x * inv)


class RelaxOperator(ABC):
    """A built RELAX operator (see :func:`build_operator`).

    Attributes:
        spec: The spec it was built from.
        horizon: Seconds of history the operator reads (0 for atemporal ones, ``inf`` when
            it must remember the latest episode however old it is).
        operator: The operator's name as written in the spec, e.g. ``eventually``.
        kind: ``atemporal``, ``alternatives`` or ``temporal`` — which method to call.

    """

    __slots__ = ("horizon", "operator", "spec")

    kind: ClassVar[Literal["atemporal", "alternatives", "temporal"]]

    def __init__(self, spec: RelaxSpecBase, horizon: float = 0.0) -> None:
        self.spec = spec
        self.horizon = horizon
        self.operator: str = str(getattr(spec, "operator", type(spec).__name__))

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.spec!r})"


class AtemporalOperator(RelaxOperator):
    """An operator on one observed value: ``utility(value) -> float`` in [0, 1].

    The value is what the goal's ``utility`` expression yields (booleans as 0/1). It must
    not be ``None``: the evaluator handles unknown values before calling. NaN gives 0.
    """

    __slots__ = ()

    kind: ClassVar[Literal["atemporal"]] = "atemporal"

    @abstractmethod
    def utility(self, value: float) -> float:
        """Return the utility of ``value``, in [0, 1]."""


class _Clamp(AtemporalOperator):
    """SHALL: the value clamped to [0, 1]."""

    __slots__ = ()

    def utility(self, value: float) -> float:
        """Return the value clamped to [0, 1] (a crisp expression already yields 0 or 1)."""
        if value >= 1.0:
            return 1.0
        if value > 0.0:
            return value
        return 0.0


class _RampUp(AtemporalOperator):
    """0 at ≤ ``target - tolerance``, 1 at ≥ ``target``, linear between."""

    __slots__ = ("_inv", "_lo")

    def __init__(self, spec: RelaxSpecBase, target: float, tolerance: float) -> None:
        super().__init__(spec)
        self._lo = target - tolerance
        self._inv = 1.0 / tolerance

    def utility(self, value: float) -> float:
        """``(value - (target - tolerance)) / tolerance`` clamped to [0, 1]."""
        u = (value - self._lo) * self._inv
        if u >= 1.0:
            return 1.0
        if u > 0.0:
            return u
        return 0.0


class _RampDown(AtemporalOperator):
    """1 at ≤ ``target``, 0 at ≥ ``target + tolerance``, linear between."""

    __slots__ = ("_hi", "_inv")

    def __init__(self, spec: RelaxSpecBase, target: float, tolerance: float) -> None:
        super().__init__(spec)
        self._hi = target + tolerance
        self._inv = 1.0 / tolerance

    def utility(self, value: float) -> float:
        """``((target + tolerance) - value) / tolerance`` clamped to [0, 1]."""
        u = (self._hi - value) * self._inv
        if u >= 1.0:
            return 1.0
        if u > 0.0:
            return u
        return 0.0


class _Triangle(AtemporalOperator):
    """1 at ``target``, 0 at ``target ± tolerance`` and beyond, linear between."""

    __slots__ = ("_inv", "_target")

    def __init__(self, spec: RelaxSpecBase, target: float, tolerance: float) -> None:
        super().__init__(spec)
        self._target = target
        self._inv = 1.0 / tolerance

    def utility(self, value: float) -> float:
        """``1 - |value - target| / tolerance`` clamped to [0, 1]."""
        u = 1.0 - abs(value - self._target) * self._inv
        if u > 0.0:
            return u
        return 0.0


class MayOrOperator(RelaxOperator):
    """MAY … OR: the fuzzy OR of the alternatives' values, three-valued (Kleene).

    Attributes:
        alternatives: The alternatives' expressions, in the order values are expected.

    """

    __slots__ = ("alternatives",)

    kind: ClassVar[Literal["alternatives"]] = "alternatives"

    def __init__(self, spec: MayOrSpec) -> None:
        super().__init__(spec)
        self.alternatives: tuple[str, ...] = spec.alternatives

    def utility_of_alternatives(self, values: Sequence[float | None]) -> float | None:
        """Return the fuzzy OR: the maximum of the known values (NaN and below 0 count as 0).

        Kleene's rule decides unknown values: 1.0 as soon as one value is fully met (≥ 1),
        even if others are unknown; otherwise ``None`` if any value is unknown, else the
        maximum (0.0 for no values at all).

        Args:
            values: One value per alternative, in the order of :attr:`alternatives`,
                booleans as 0/1 (any number of values is accepted).

        """
        best = 0.0
        unknown = False
        for x in values:
            if x is None:
                unknown = True
            elif x >= 1.0:
                return 1.0
            elif x > best:
                best = x
        return None if unknown else best
