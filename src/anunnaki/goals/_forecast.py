"""Anticipatory attributes: a monitored field extrapolated to the end of a route.

A binding's agent may declare ``forecasts:`` (docs/goal-models.md, "Forecasts"): each one
names a field the agent publishes (``of``), a ``window`` in seconds, and the ``distance``
still to cover and the ``speed`` covering it (attributes, or numbers). Its value is::

    value + rate × distance / speed

where ``value`` is the field's latest sample and ``rate`` its change per second over the
samples of the last ``window`` seconds (the first and last of them: ``(v_last - v_first) /
(t_last - t_first)``). The battery's level forecast over the metres still to fly at cruise
speed is the battery expected at the end of the flight.

Everything comes from the samples' times, which are the messages' (the simulated clock's in
a simulated run), never from a wall clock: the same inputs in the same order give the same
forecasts, so a run's decision log replays them. A forecast is unknown (``None``) while its
field, distance or speed is, or before the window holds two samples at different times.
"""

from __future__ import annotations

from collections import deque

__all__ = ["Forecaster", "forecast"]


def forecast(value: float, rate: float, distance: float, speed: float) -> float:
    """``value`` after ``distance / speed`` seconds of change at ``rate`` per second."""
    return value + rate * distance / speed


def _number(v: object) -> float | None:
    """``v`` as a float when it is a real number (not a boolean), else ``None``."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        return None
    return float(v)


class Forecaster:
    """One forecast's samples of its field and its value.

    Args:
        window: Seconds of samples the rate of change is estimated over.

    """

    __slots__ = ("samples", "window")

    def __init__(self, window: float) -> None:
        self.window = float(window)
        self.samples: deque[tuple[float, float]] = deque()

    def sample(self, t: float, value: object) -> None:
        """Keep one sample of the field at ``t`` (a value that is no number is skipped)."""
        v = _number(value)
        if v is None:
            return
        s = self.samples
        s.append((t, v))
        while s and s[0][0] < t - self.window:
            s.popleft()

    def rate(self) -> float | None:
        """The field's change per second over the window (``None``: under two instants)."""
        s = self.samples
        if len(s) < 2 or s[-1][0] <= s[0][0]:
            return None
        return (s[-1][1] - s[0][1]) / (s[-1][0] - s[0][0])

    def value(self, current: object, distance: object, speed: object) -> float | None:
        """The forecast from the field's ``current`` value, or ``None`` when unknown."""
        v, d, sp, r = _number(current), _number(distance), _number(speed), self.rate()
        if v is None or d is None or sp is None or r is None or sp <= 0 or d < 0:
            return None
        return forecast(v, r, d, sp)
