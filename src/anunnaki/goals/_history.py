"""Timestamped samples of one condition, and the sliding view temporal operators read.

:class:`History` is the bounded, piecewise-constant series the evaluator appends to (one
per condition a temporal goal reads); :class:`_View` is the window of it from the sample
in force at ``now - horizon`` up to ``now``, with the queries the temporal operators are
written in (last time held, latest onset, time not holding, ...). It is a data structure
with no RELAX semantics of its own, hence its own module.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Iterable, Iterator
from typing import Final

__all__ = ["DEFAULT_MAXLEN", "History"]

#: Default cap on the number of samples a :class:`History` keeps.
DEFAULT_MAXLEN: Final = 10_000


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
