"""RELAX operators over time: eventually, until, before, after, as early/late as possible.

A :class:`TemporalOperator` reads the :class:`~anunnaki.goals._history.History` of the
goal's condition (and of its event, where there is one) through a sliding view of the last
``horizon`` seconds, and applies the unknown-value rule of docs/relax.md: an unknown
current state is completed both ways and the results must agree. Apart from the atemporal
operators because this is where windows, episodes and deadlines are handled.
"""

from __future__ import annotations

import math
from abc import abstractmethod
from typing import ClassVar, Final, Literal

from anunnaki.goals._history import History, _View
from anunnaki.goals._relax_ops import RelaxOperator, _decay, _unit
from anunnaki.goals._relax_specs import (
    AfterSpec,
    AsLateAsPossibleSpec,
    BeforeSpec,
    RelaxSpecBase,
    UntilSpec,
    _EventSpec,
)

__all__ = ["TemporalOperator"]

#: Two completions of an unknown current state "agree" when they differ by at most this.
_AGREE: Final = 1e-12


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
