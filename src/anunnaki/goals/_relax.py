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
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from bisect import bisect_right
from collections.abc import Iterable, Iterator, Sequence
from typing import Annotated, ClassVar, Final, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, field_validator, model_validator

__all__ = [
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

#: Default cap on the number of samples a :class:`History` keeps.
DEFAULT_MAXLEN: Final = 10_000

#: Two completions of an unknown current state "agree" when they differ by at most this.
_AGREE: Final = 1e-12


# =====================================================================================
# Specs
# =====================================================================================

_Number = Annotated[float, Field(strict=True)]
"""A float field that accepts ints and floats, but not booleans or strings."""


def _finite(name: str, value: float, example: str) -> None:
    if not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value}; write e.g. {example}")


def _check_tolerance(value: float) -> float:
    _finite("tolerance", value, "'tolerance: 0.5'")
    if value <= 0.0:
        raise ValueError(
            f"tolerance must be greater than 0, got {value}: it is the distance over which "
            "the utility falls from 1 to 0. Write a positive width such as 'tolerance: 0.5' "
            "(a requirement with no tolerance is crisp: use 'operator: shall')"
        )
    if not math.isfinite(1.0 / value):
        raise ValueError(f"tolerance {value} is too small to divide by; write e.g. 0.001")
    return value


def _check_within(value: float) -> float:
    _finite("within", value, "'within: 10.0'")
    if value < 0.0:
        raise ValueError(
            f"within must be 0 or more seconds, got {value}; write e.g. 'within: 10.0' "
            "(0 means: at once)"
        )
    return value


def _check_window(value: float | None) -> float | None:
    if value is None:
        return None
    _finite("window", value, "'window: 60.0'")
    if value <= 0.0:
        raise ValueError(
            f"window must be greater than 0 seconds, got {value}; write e.g. 'window: 60.0', "
            "or leave it out to judge the latest episode however long ago it was"
        )
    return value


def _check_expression(value: str, name: str, example: str) -> str:
    text = value.strip()
    if not text:
        raise ValueError(f"{name} must be a non-empty expression; write e.g. {example}")
    return text


_Tolerance = Annotated[_Number, AfterValidator(_check_tolerance)]
_Within = Annotated[_Number, AfterValidator(_check_within)]
_Window = Annotated[_Number | None, AfterValidator(_check_window)]


class RelaxSpecBase(BaseModel):
    """Fields common to every RELAX spec.

    Attributes:
        unit: Unit of the observed value or of time, for display only (e.g. ``Hz``, ``s``).

    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    unit: str | None = None


class ShallSpec(RelaxSpecBase):
    """SHALL: the requirement must hold (crisp); utility is the value clamped to [0, 1]."""

    operator: Literal["shall"] = "shall"


class MayOrSpec(RelaxSpecBase):
    """MAY … OR: one or more alternatives; utility is the fuzzy OR (maximum) of theirs.

    Attributes:
        alternatives: Two or more expressions; the evaluator compiles and evaluates each.
            A YAML list is accepted and stored as a tuple.

    """

    operator: Literal["may_or"] = "may_or"
    alternatives: tuple[str, ...]

    @field_validator("alternatives")
    @classmethod
    def _two_or_more(cls, value: tuple[str, ...]) -> tuple[str, ...]:
        example = "'alternatives: [A2.lidar_ok, A3.sonar_ok]'"
        texts = tuple(_check_expression(v, "each of the alternatives", example) for v in value)
        if len(texts) < 2:
            raise ValueError(
                f"alternatives needs at least 2 expressions, got {len(texts)}; write e.g. "
                "'alternatives: [A2.lidar_ok, A3.sonar_ok]' (a single one is 'operator: shall')"
            )
        seen: set[str] = set()
        for text in texts:
            if text in seen:
                raise ValueError(f"alternative '{text}' appears twice; remove the duplicate")
            seen.add(text)
        return texts


Side = Literal["both", "at_least", "at_most"]


class _CloseToSpec(RelaxSpecBase):
    """Shared shape of the AS CLOSE AS POSSIBLE TO operators."""

    target: _Number
    tolerance: _Tolerance
    side: Side = "both"

    @field_validator("target")
    @classmethod
    def _finite_target(cls, value: float) -> float:
        _finite("target", value, "'target: 5.0'")
        return value

    @model_validator(mode="after")
    def _finite_edges(self) -> _CloseToSpec:
        if not (
            math.isfinite(self.target - self.tolerance)
            and math.isfinite(self.target + self.tolerance)
        ):
            raise ValueError("target ± tolerance overflows; use smaller numbers (another unit)")
        return self


class AsCloseAsPossibleToFrequencySpec(_CloseToSpec):
    """AS CLOSE AS POSSIBLE TO [frequency]: something repeats at a rate near ``target`` Hz.

    Attributes:
        target: The required frequency in Hz (> 0).
        tolerance: How far (Hz) the rate may stray before the utility reaches 0 (> 0).
        side: ``both`` (triangle around the target), ``at_least`` (only too slow is
            penalised) or ``at_most`` (only too fast is penalised).

    """

    operator: Literal["as_close_as_possible_to_frequency"] = "as_close_as_possible_to_frequency"

    @field_validator("target")
    @classmethod
    def _positive_frequency(cls, value: float) -> float:
        if value <= 0.0:
            raise ValueError(
                f"target is a frequency in Hz and must be greater than 0, got {value}; "
                "write e.g. 'target: 5.0'"
            )
        return value


class AsCloseAsPossibleToQuantitySpec(_CloseToSpec):
    """AS CLOSE AS POSSIBLE TO [quantity]: a countable quantity near ``target``.

    Attributes:
        target: The required quantity.
        tolerance: How far the quantity may stray before the utility reaches 0 (> 0).
        side: ``both``, ``at_least`` or ``at_most`` (as for the frequency operator).

    """

    operator: Literal["as_close_as_possible_to_quantity"] = "as_close_as_possible_to_quantity"


class _OrdinalSpec(RelaxSpecBase):
    """Shared shape of AS FEW / AS MANY AS POSSIBLE."""

    target: _Number
    tolerance: _Tolerance

    @field_validator("target")
    @classmethod
    def _finite_target(cls, value: float) -> float:
        _finite("target", value, "'target: 3'")
        return value

    @model_validator(mode="after")
    def _finite_edges(self) -> _OrdinalSpec:
        if not (
            math.isfinite(self.target - self.tolerance)
            and math.isfinite(self.target + self.tolerance)
        ):
            raise ValueError("target ± tolerance overflows; use smaller numbers (another unit)")
        return self


class AsFewAsPossibleSpec(_OrdinalSpec):
    """AS FEW AS POSSIBLE: a count should stay at or below ``target``.

    Attributes:
        target: The ideal maximum; utility is 1 at or below it.
        tolerance: Utility falls linearly to 0 at ``target + tolerance`` (> 0).

    """

    operator: Literal["as_few_as_possible"] = "as_few_as_possible"


class AsManyAsPossibleSpec(_OrdinalSpec):
    """AS MANY AS POSSIBLE: a count should reach at least ``target``.

    Attributes:
        target: The ideal minimum; utility is 1 at or above it.
        tolerance: Utility falls linearly to 0 at ``target - tolerance`` (> 0).

    """

    operator: Literal["as_many_as_possible"] = "as_many_as_possible"


class _EventSpec(RelaxSpecBase):
    """Shared shape of the temporal operators that relate the goal to an event."""

    event: str
    tolerance: _Tolerance
    window: _Window = None

    @field_validator("event")
    @classmethod
    def _event_expression(cls, value: str) -> str:
        return _check_expression(value, "event", "'event: A1.obstacle_detected'")


class EventuallySpec(RelaxSpecBase):
    """EVENTUALLY: the condition shall hold at some time within the last ``within`` seconds.

    Attributes:
        within: Seconds since the condition last held that still count as fully met (≥ 0).
        tolerance: Further seconds over which the utility falls from 1 to 0 (> 0).

    """

    operator: Literal["eventually"] = "eventually"
    within: _Within
    tolerance: _Tolerance


class UntilSpec(_EventSpec):
    """UNTIL: the condition shall hold until ``event`` occurs.

    Attributes:
        event: Expression of the event that discharges the obligation.
        tolerance: Seconds of not holding (summed) at which the utility reaches 0 (> 0).
        window: Optional sliding window in seconds; only its time counts. Without it the
            latest episode is judged however long ago it started.

    """

    operator: Literal["until"] = "until"


class BeforeSpec(_EventSpec):
    """BEFORE: the condition shall have held before ``event`` occurs.

    Attributes:
        event: Expression of the event.
        tolerance: Seconds of lateness (condition first holding after the event) at which
            the utility reaches 0 (> 0).
        window: Optional sliding window in seconds (≥ tolerance); older events are forgotten.

    """

    operator: Literal["before"] = "before"

    @model_validator(mode="after")
    def _window_covers_tolerance(self) -> BeforeSpec:
        if self.window is not None and self.window < self.tolerance:
            raise ValueError(
                f"window ({self.window}) must be at least tolerance ({self.tolerance}), or a "
                "late condition would be forgotten before it counts; "
                f"write 'window: {self.tolerance}' or more, or leave window out"
            )
        return self


class AfterSpec(_EventSpec):
    """AFTER: the condition shall hold after ``event`` occurs, within ``within`` seconds.

    Attributes:
        event: Expression of the event that triggers the obligation.
        within: Seconds after the event's onset by which the condition should hold (≥ 0).
        tolerance: Further seconds over which the utility falls from 1 to 0 (> 0).
        window: Optional sliding window in seconds (≥ within + tolerance); older events
            are forgotten.

    """

    operator: Literal["after"] = "after"
    within: _Within = 0.0

    @model_validator(mode="after")
    def _window_covers_deadline(self) -> AfterSpec:
        need = self.within + self.tolerance
        if self.window is not None and self.window < need:
            raise ValueError(
                f"window ({self.window}) must be at least within + tolerance ({need}), or a "
                "missing response would be forgotten before it counts; "
                f"write 'window: {need}' or more, or leave window out"
            )
        return self


class AsEarlyAsPossibleSpec(RelaxSpecBase):
    """AS EARLY AS POSSIBLE: the condition should (again) hold as soon as possible.

    Attributes:
        tolerance: Seconds of not holding at which the utility reaches 0 (> 0).

    """

    operator: Literal["as_early_as_possible"] = "as_early_as_possible"
    tolerance: _Tolerance


class AsLateAsPossibleSpec(RelaxSpecBase):
    """AS LATE AS POSSIBLE: the condition should be delayed as long as possible.

    Attributes:
        target: The desired minimum delay in seconds between two holding periods (> 0);
            a delay of ``target`` or more gives utility 1.

    """

    operator: Literal["as_late_as_possible"] = "as_late_as_possible"
    target: _Number

    @field_validator("target")
    @classmethod
    def _positive_delay(cls, value: float) -> float:
        _finite("target", value, "'target: 60.0'")
        if value <= 0.0 or not math.isfinite(1.0 / value):
            raise ValueError(
                f"target is the desired minimum delay in seconds and must be greater than 0, "
                f"got {value}; write e.g. 'target: 60.0'"
            )
        return value


RelaxSpec = Annotated[
    ShallSpec
    | MayOrSpec
    | AsCloseAsPossibleToFrequencySpec
    | AsCloseAsPossibleToQuantitySpec
    | AsFewAsPossibleSpec
    | AsManyAsPossibleSpec
    | EventuallySpec
    | UntilSpec
    | BeforeSpec
    | AfterSpec
    | AsEarlyAsPossibleSpec
    | AsLateAsPossibleSpec,
    Field(discriminator="operator"),
]
"""Any RELAX spec, told apart by its ``operator`` field (e.g. ``operator: eventually``)."""


# =====================================================================================
# History
# =====================================================================================


class History:
    """A bounded, append-only series of ``(t, holds)`` samples of one condition.

    The series is piecewise constant: a sample's state holds from its time until the next
    sample (the last one until "now"). ``holds`` is ``True``, ``False`` or ``None``
    (unknown). Only changes are stored: a sample equal to the previous state is merged into
    it, and a sample at the same instant as the previous one replaces it (the later wins).

    Args:
        samples: Initial ``(t, holds)`` pairs, appended in order.
        maxlen: The most samples kept (changes, after merging); beyond it the oldest are
            dropped, and operators then see a shorter past.

    Raises:
        ValueError: ``maxlen`` is below 2, or a sample is invalid (see :meth:`append`).

    """

    __slots__ = ("_latest", "_maxlen", "_t", "_v")

    def __init__(
        self,
        samples: Iterable[tuple[float, bool | None]] = (),
        *,
        maxlen: int = DEFAULT_MAXLEN,
    ) -> None:
        if maxlen < 2:
            raise ValueError(f"maxlen must be at least 2, got {maxlen}")
        self._maxlen = maxlen
        self._t: list[float] = []
        self._v: list[bool | None] = []
        self._latest: float | None = None
        for t, holds in samples:
            self.append(t, holds)

    @property
    def maxlen(self) -> int:
        """The most samples kept."""
        return self._maxlen

    @property
    def latest(self) -> float | None:
        """Time of the last appended sample (merged or not), or ``None`` if none yet."""
        return self._latest

    def __len__(self) -> int:
        return len(self._t)

    def __iter__(self) -> Iterator[tuple[float, bool | None]]:
        return iter(zip(self._t, self._v, strict=True))

    def __repr__(self) -> str:
        return f"History({list(self)!r}, maxlen={self._maxlen})"

    def append(self, t: float, holds: bool | None) -> None:
        """Record that from time ``t`` on the condition ``holds`` (``None``: unknown).

        Args:
            t: Time in seconds; finite and not earlier than the previous sample's.
            holds: The condition's state; any value other than ``None`` is taken as a bool.

        Raises:
            ValueError: ``t`` is not finite or goes back in time.

        """
        t = float(t)
        if not math.isfinite(t):
            raise ValueError(f"sample time must be finite, got {t}")
        if self._latest is not None and t < self._latest:
            raise ValueError(
                f"sample time {t} is earlier than the previous sample's ({self._latest}); "
                "samples must be appended in time order"
            )
        self._latest = t
        value = None if holds is None else bool(holds)
        ts, vs = self._t, self._v
        if ts and ts[-1] == t:
            ts.pop()
            vs.pop()
        if vs and vs[-1] is value:
            return
        ts.append(t)
        vs.append(value)
        if len(ts) > self._maxlen:
            del ts[0]
            del vs[0]

    def prune(self, before: float) -> None:
        """Drop samples older than ``before``, keeping the one in force at ``before``.

        Args:
            before: Cutoff time; ``-inf`` keeps everything.

        Raises:
            ValueError: ``before`` is NaN.

        """
        if math.isnan(before):
            raise ValueError("prune cutoff must not be NaN")
        i = bisect_right(self._t, before) - 1
        if i > 0:
            del self._t[:i]
            del self._v[:i]

    def state_at(self, t: float) -> bool | None:
        """Return the state in force at time ``t`` (``None``: unknown or before any sample)."""
        i = bisect_right(self._t, t) - 1
        return self._v[i] if i >= 0 else None

    # The queries below read the samples at or before ``now``.

    def last_held(self, now: float) -> float | None:
        """Return the last time at or before ``now`` the condition held (``now`` if it holds).

        Returns ``None`` if it never held. Unknown stretches do not count as holding.
        """
        view = self._view(-math.inf, now)
        return None if view is None else view.last_held(now)

    def last_onset(self, now: float) -> float | None:
        """Return the start of the latest holding stretch at or before ``now``, or ``None``.

        A stretch in force at the first sample is taken to start at that sample's time.
        """
        view = self._view(-math.inf, now)
        if view is None:
            return None
        i = view.latest_onset()
        return None if i < 0 else view.t[i]

    def first_held(self, start: float, now: float) -> float | None:
        """Return the first time in ``[start, now]`` the condition holds, or ``None``."""
        view = self._view(-math.inf, now)
        return None if view is None else view.first_held(start)

    def not_holding_time(self, start: float, end: float) -> float:
        """Return the seconds in ``[start, end]`` the condition was known not to hold.

        Unknown stretches and time before the first sample do not count.
        """
        view = self._view(-math.inf, end)
        return 0.0 if view is None else view.false_time(start, end)

    def _view(self, start: float, now: float) -> _View | None:
        """View the samples from the one in force at ``start`` to the last at or before ``now``."""
        hi = bisect_right(self._t, now)
        if hi == 0:
            return None
        lo = max(0, bisect_right(self._t, start, 0, hi) - 1)
        return _View(self._t, self._v, lo, hi, self._v[hi - 1])


class _View:
    """Samples ``[lo, hi)`` of a history, with the last one's state possibly completed."""

    __slots__ = ("hi", "lo", "t", "tail", "v")

    def __init__(
        self, t: list[float], v: list[bool | None], lo: int, hi: int, tail: bool | None
    ) -> None:
        self.t = t
        self.v = v
        self.lo = lo
        self.hi = hi
        self.tail = tail

    def completed(self, tail: bool) -> _View:
        return _View(self.t, self.v, self.lo, self.hi, tail)

    def has_known(self) -> bool:
        return any(self.v[i] is not None for i in range(self.lo, self.hi))

    def val(self, i: int) -> bool | None:
        return self.tail if i == self.hi - 1 else self.v[i]

    @property
    def first_time(self) -> float:
        return self.t[self.lo]

    def index_at(self, time: float) -> int:
        """Index of the sample in force at ``time``; ``lo - 1`` if before the view."""
        return bisect_right(self.t, time, self.lo, self.hi) - 1

    def last_true(self, before: int) -> int:
        """Largest index < ``before`` whose state holds, or -1."""
        for i in range(before - 1, self.lo - 1, -1):
            if self.val(i) is True:
                return i
        return -1

    def run_start(self, i: int) -> int:
        """First index of the holding stretch that contains index ``i``."""
        while i > self.lo and self.val(i - 1) is True:
            i -= 1
        return i

    def holds_now(self) -> bool:
        return self.tail is True

    def last_held(self, now: float) -> float | None:
        if self.tail is True:
            return now
        i = self.last_true(self.hi)
        return None if i < 0 else self.t[i + 1]

    def latest_onset(self) -> int:
        """Index where the latest holding stretch starts, or -1."""
        i = self.last_true(self.hi)
        return -1 if i < 0 else self.run_start(i)

    def previous_end(self, start: int) -> float | None:
        """End of the holding stretch before the one starting at index ``start``."""
        j = self.last_true(start)
        return None if j < 0 else self.t[j + 1]

    def held_within(self, a: float, b: float) -> bool:
        """Whether the state held at some instant of ``[a, b]``."""
        i = self.index_at(a)
        if i >= self.lo and self.val(i) is True:
            return True
        for k in range(max(i + 1, self.lo), self.hi):
            if self.t[k] > b:
                break
            if self.val(k) is True:
                return True
        return False

    def first_held(self, a: float) -> float | None:
        """First instant ≥ ``a`` (up to the view's end) at which the state holds."""
        i = self.index_at(a)
        if i >= self.lo and self.val(i) is True:
            return a
        for k in range(max(i + 1, self.lo), self.hi):
            if self.val(k) is True:
                return self.t[k]
        return None

    def false_time(self, a: float, b: float) -> float:
        """Seconds of ``[a, b]`` during which the state was known not to hold."""
        total = 0.0
        if b <= a:
            return total
        t, hi = self.t, self.hi
        for k in range(max(self.index_at(a), self.lo), hi):
            seg_start = a if t[k] < a else t[k]
            if seg_start >= b:
                break
            seg_end = b if k + 1 >= hi or t[k + 1] > b else t[k + 1]
            if self.val(k) is False:
                total += seg_end - seg_start
        return total


# =====================================================================================
# Operators
# =====================================================================================


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


class TemporalOperator(RelaxOperator):
    """An operator on the history of a condition ``p`` (and of an event ``e``).

    Call :meth:`utility_at` with the histories and the current time. Only the samples from
    the one in force at ``now - horizon`` on are read, so pruning each history at
    ``now - horizon`` never changes a result.

    Attributes:
        needs_event: Whether the operator reads an event history ``e``.

    """

    __slots__ = ()

    kind: ClassVar[Literal["temporal"]] = "temporal"
    needs_event: ClassVar[bool] = False

    @property
    def event(self) -> str | None:
        """The event expression, for operators that relate the goal to an event."""
        event = getattr(self.spec, "event", None)
        return event if isinstance(event, str) else None

    def utility_at(self, p: History, e: History | None, now: float) -> float | None:
        """Return the utility at time ``now``, in [0, 1], or ``None`` when unknown.

        Args:
            p: History of the goal's condition.
            e: History of the event (ignored by operators without one).
            now: Current time in seconds; samples after it are ignored.

        Returns:
            The utility, or ``None`` if a history has no known sample in view or the result
            depends on a current state that is unknown.

        Raises:
            ValueError: ``now`` is not finite, or the operator needs ``e`` and got ``None``.

        """
        if not math.isfinite(now):
            raise ValueError(f"now must be finite, got {now}")
        start = now - self.horizon
        pv = p._view(start, now)
        if pv is None or not pv.has_known():
            return None
        ev: _View | None = None
        if self.needs_event:
            if e is None:
                raise ValueError(f"{self.operator} needs the history of its event {self.event!r}")
            ev = e._view(start, now)
            if ev is None or not ev.has_known():
                return None
        p_views = _completions(pv)
        e_views: tuple[_View | None, ...] = (None,) if ev is None else _completions(ev)
        result: float | None = None
        for pc in p_views:
            for ec in e_views:
                u = self._evaluate(pc, ec, now)
                if u is None:
                    return None
                if result is None:
                    result = u
                elif abs(u - result) > _AGREE:
                    return None
        return result

    @abstractmethod
    def _evaluate(self, p: _View, e: _View | None, now: float) -> float | None:
        """Return the utility with every current state known (``None``: not observable)."""


_BOTH: Final = (True, False)


def _completions(view: _View) -> tuple[_View, ...]:
    if view.tail is None:
        return tuple(view.completed(x) for x in _BOTH)
    return (view,)


class _Eventually(TemporalOperator):
    """EVENTUALLY within W, tolerance T: by the gap g since the condition last held."""

    __slots__ = ("_inv", "_within")

    def __init__(self, spec: RelaxSpecBase, within: float, tolerance: float) -> None:
        super().__init__(spec, horizon=within + tolerance)
        self._within = within
        self._inv = 1.0 / tolerance

    def _evaluate(self, p: _View, e: _View | None, now: float) -> float:
        held = p.last_held(now)
        reference = p.first_time if held is None else held
        return _decay(now - reference - self._within, self._inv)


class _EventOperator(TemporalOperator):
    """Common parts of UNTIL, BEFORE and AFTER."""

    __slots__ = ("_inv", "_window")

    needs_event: ClassVar[bool] = True

    def __init__(self, spec: _EventSpec, horizon: float) -> None:
        super().__init__(spec, horizon=horizon)
        self._window = spec.window
        self._inv = 1.0 / spec.tolerance

    def _latest_event(self, e: _View, now: float) -> tuple[float, float] | None:
        """``(onset, episode start)`` of the event's latest occurrence in view, or None.

        The episode start is the end of the event's previous occurrence (or the first
        sample's time), but never before the window.
        """
        s = e.latest_onset()
        if s < 0:
            return None
        onset = e.t[s]
        start = e.previous_end(s)
        if start is None:
            start = e.first_time
        if self._window is not None:
            window_start = now - self._window
            if onset < window_start:
                return None
            start = max(start, window_start)
        return onset, start


class _Until(_EventOperator):
    """UNTIL: by the time the condition did not hold in the current or latest episode."""

    __slots__ = ()

    def __init__(self, spec: UntilSpec) -> None:
        super().__init__(spec, horizon=math.inf if spec.window is None else spec.window)

    def _evaluate(self, p: _View, e: _View | None, now: float) -> float:
        assert e is not None
        if e.holds_now():
            s = e.run_start(e.hi - 1)
            end = e.t[s]
            start = e.previous_end(s)
        else:
            end = now
            start = e.last_held(now)
        if start is None:
            start = e.first_time
        if self._window is not None:
            start = max(start, now - self._window)
        return _decay(p.false_time(start, end), self._inv)


class _Before(_EventOperator):
    """BEFORE: 1 if the condition held in the episode up to the event, else by lateness."""

    __slots__ = ()

    def __init__(self, spec: BeforeSpec) -> None:
        super().__init__(spec, horizon=math.inf if spec.window is None else spec.window)

    def _evaluate(self, p: _View, e: _View | None, now: float) -> float:
        assert e is not None
        latest = self._latest_event(e, now)
        if latest is None:
            return 1.0
        onset, start = latest
        if p.held_within(start, onset):
            return 1.0
        first = p.first_held(onset)
        late = (now if first is None else first) - onset
        return _decay(late, self._inv)


class _After(_EventOperator):
    """AFTER: by the delay from the event's latest onset to the condition holding."""

    __slots__ = ("_within",)

    def __init__(self, spec: AfterSpec) -> None:
        super().__init__(spec, horizon=math.inf if spec.window is None else spec.window)
        self._within = spec.within

    def _evaluate(self, p: _View, e: _View | None, now: float) -> float:
        assert e is not None
        latest = self._latest_event(e, now)
        if latest is None:
            return 1.0
        onset = latest[0]
        first = p.first_held(onset)
        delay = (now if first is None else first) - onset
        return _decay(delay - self._within, self._inv)


class _AsLate(TemporalOperator):
    """AS LATE AS POSSIBLE: by the delay before the current holding stretch began."""

    __slots__ = ("_inv",)

    def __init__(self, spec: AsLateAsPossibleSpec) -> None:
        super().__init__(spec, horizon=math.inf)
        self._inv = 1.0 / spec.target

    def _evaluate(self, p: _View, e: _View | None, now: float) -> float | None:
        if not p.holds_now():
            return 1.0
        s = p.run_start(p.hi - 1)
        if s == p.lo:
            return None
        reference = p.previous_end(s)
        if reference is None:
            reference = p.first_time
        return _unit((p.t[s] - reference) * self._inv)


def build_operator(spec: RelaxSpecBase) -> RelaxOperator:
    """Build the operator a spec describes.

    Args:
        spec: Any member of :data:`RelaxSpec`.

    Returns:
        An :class:`AtemporalOperator`, :class:`MayOrOperator` or :class:`TemporalOperator`.

    Raises:
        TypeError: ``spec`` is not a RELAX spec.

    """
    match spec:
        case ShallSpec():
            return _Clamp(spec)
        case MayOrSpec():
            return MayOrOperator(spec)
        case AsCloseAsPossibleToFrequencySpec() | AsCloseAsPossibleToQuantitySpec():
            if spec.side == "at_least":
                return _RampUp(spec, spec.target, spec.tolerance)
            if spec.side == "at_most":
                return _RampDown(spec, spec.target, spec.tolerance)
            return _Triangle(spec, spec.target, spec.tolerance)
        case AsFewAsPossibleSpec():
            return _RampDown(spec, spec.target, spec.tolerance)
        case AsManyAsPossibleSpec():
            return _RampUp(spec, spec.target, spec.tolerance)
        case EventuallySpec():
            return _Eventually(spec, spec.within, spec.tolerance)
        case UntilSpec():
            return _Until(spec)
        case BeforeSpec():
            return _Before(spec)
        case AfterSpec():
            return _After(spec)
        case AsEarlyAsPossibleSpec():
            return _Eventually(spec, 0.0, spec.tolerance)
        case AsLateAsPossibleSpec():
            return _AsLate(spec)
    raise TypeError(f"not a RELAX spec: {spec!r}")
