"""When a topic last spoke, how often it speaks, and whether it is stale: one definition.

The evaluator (what a goal's ``rate(A)`` and staleness mean), Utu's TopicWatch and the
dashboard's monitor pane all read a topic's freshness through this module, so a rate
shown on the dashboard is the rate a RELAX-ed goal was judged on.

* **stale**: a topic is stale at ``now`` when it never spoke, or when ``now - last`` exceeds
  its staleness (the binding's ``staleness`` in seconds; strictly greater: a message exactly
  ``staleness`` ago still counts);
* **rate**: messages per second from the inter-arrival times of the last ``window``
  intervals, ``n / span``; while the topic is silent for longer than the mean interval the
  open gap counts too, so the rate decays continuously toward 0 instead of jumping (a
  per-second count would hide a 4.5–5.0 Hz ramp). Unknown (``None``) with fewer than two
  arrivals or all arrivals at one instant.
"""

from __future__ import annotations

from collections import deque

__all__ = ["RateEstimator", "TopicFreshness", "is_stale"]


def is_stale(last: float | None, now: float, staleness: float) -> bool:
    """Whether a topic that last spoke at ``last`` (``None``: never) is stale at ``now``."""
    return last is None or now - last > staleness


class RateEstimator:
    """Message frequency (Hz) from the inter-arrival times of the last ``window`` intervals."""

    __slots__ = ("arrivals",)

    def __init__(self, window: int = 20) -> None:
        self.arrivals: deque[float] = deque(maxlen=window + 1)

    def arrive(self, t: float) -> None:
        """Count one arrival at ``t`` (seconds, non-decreasing)."""
        self.arrivals.append(t)

    def rate(self, now: float) -> float | None:
        """The rate at ``now``; decays through a silence longer than the mean interval."""
        a = self.arrivals
        n = len(a) - 1
        if n < 1:
            return None
        span = a[-1] - a[0]
        if span <= 0.0:
            # All at one instant (a backlog a step took at once is stamped at that step's
            # time): n intervals in the time since then, or unknown if no time has passed.
            span = now - a[0]
            return n / span if span > 0.0 else None
        gap = now - a[-1]
        mean = span / n
        if gap > mean:
            span += gap - mean
        return n / span

    def in_gap(self, now: float) -> bool:
        """Whether the topic has been silent for longer than its mean interval."""
        a = self.arrivals
        n = len(a) - 1
        return n >= 1 and now - a[-1] > (a[-1] - a[0]) / n


class TopicFreshness:
    """One topic's freshness: last arrival, count, rate, staleness.

    Args:
        staleness: Seconds of silence after which the topic's values are unknown.
        window: Intervals the rate is measured over (the goal model's ``rate_window``).

    """

    __slots__ = ("_rate", "count", "last", "staleness")

    def __init__(self, staleness: float, *, window: int = 20) -> None:
        self.staleness = staleness
        self.last: float | None = None
        self.count = 0
        self._rate = RateEstimator(window)

    def arrive(self, t: float) -> None:
        """Count one message arriving at ``t``."""
        self.last = t
        self.count += 1
        self._rate.arrive(t)

    def stale(self, now: float) -> bool:
        """Whether the topic is stale at ``now`` (see the module docstring)."""
        return is_stale(self.last, now, self.staleness)

    def deadline(self) -> float | None:
        """When the topic goes stale unless it speaks again (``None``: it never spoke)."""
        return None if self.last is None else self.last + self.staleness

    def rate(self, now: float) -> float | None:
        """Messages per second at ``now`` (see the module docstring)."""
        return self._rate.rate(now)
