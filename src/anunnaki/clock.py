"""One clock for all of Utu: injected, never read from ``time`` inside the core.

* :class:`WallClock` — live runs: seconds since the epoch (``time.time``).
* :class:`ManualClock` — tests, replay and deterministic simulation: the caller sets it.
* :class:`SimClock` — ``use_sim_time``: the time a simulator last published on its clock
  topic (``/clock``). A simulation running at 0.3× real time advances this clock at 0.3×,
  so staleness deadlines and message rates, all measured on it, see no spurious silence.

Every clock has ``now() -> float`` (seconds) and ``wait(timeout)`` used by ``spin()`` loops
to sleep until something may have changed (a wall-clock wait; for a simulated clock the
timeout is converted by the last observed speed, bounded so a stalled simulator never blocks
shutdown).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from typing import Protocol, runtime_checkable

log = logging.getLogger("anunnaki.clock")

__all__ = ["Clock", "ManualClock", "SimClock", "WallClock"]


@runtime_checkable
class Clock(Protocol):
    """What Utu needs from a clock."""

    def now(self) -> float:
        """Current time in seconds."""
        ...


class WallClock:
    """Seconds since the epoch, from the operating system."""

    def now(self) -> float:
        """Current wall-clock time in seconds."""
        return time.time()

    def __repr__(self) -> str:
        return "WallClock()"


class ManualClock:
    """A clock the caller moves; never goes backwards."""

    def __init__(self, start: float = 0.0) -> None:
        self._t = float(start)

    def now(self) -> float:
        """The time last set."""
        return self._t

    def set(self, t: float) -> None:
        """Move to ``t`` (ignored if earlier than now)."""
        if t > self._t:
            self._t = float(t)

    def advance(self, dt: float) -> float:
        """Move forward by ``dt`` seconds; returns the new time."""
        if dt > 0:
            self._t += dt
        return self._t

    def __repr__(self) -> str:
        return f"ManualClock({self._t})"


class SimClock:
    """The simulation's time, as last published on its clock topic.

    Feed it with :meth:`update` (the Clock message's ``t``); until the first update ``now``
    returns ``start``. It also estimates the simulation's speed relative to the wall clock,
    which ``spin`` loops use to turn a simulated timeout into a real one.
    """

    def __init__(self, start: float = 0.0, *, max_jump: float | None = None) -> None:
        if max_jump is not None and not max_jump > 0:
            raise ValueError(f"max_jump must be > 0 seconds or None, got {max_jump!r}")
        self._t = float(start)
        self._lock = threading.Lock()
        self._wall: float | None = None
        self.speed = 1.0
        self.max_jump = max_jump
        #: Times refused as implausible (non-finite, or beyond ``max_jump`` ahead).
        self.refused = 0

    def now(self) -> float:
        """The latest simulation time received."""
        return self._t

    def update(self, t: float, wall: float | None = None) -> bool:
        """Take a new simulation time; ``False`` when it is refused.

        A time that goes backwards is ignored; one that is not finite, or (after the first
        update) more than ``max_jump`` seconds ahead of the current time, is refused and
        counted in :attr:`refused` (a forged ``/clock`` must not freeze time in the future).
        """
        wall = time.monotonic() if wall is None else wall
        with self._lock:
            if not math.isfinite(t) or (
                self.max_jump is not None and self._wall is not None and t > self._t + self.max_jump
            ):
                self.refused += 1
                if self.refused == 1:
                    log.warning(
                        "clock: refused the time %r (now %.3f; at most %s s ahead is plausible); "
                        "further refusals are counted, not logged",
                        t, self._t, self.max_jump,
                    )  # fmt: skip
                return False
            if t <= self._t:
                return True
            if self._wall is not None and wall > self._wall:
                inst = (t - self._t) / (wall - self._wall)
                self.speed = 0.8 * self.speed + 0.2 * inst
            self._t = float(t)
            self._wall = wall
            return True

    def __repr__(self) -> str:
        return f"SimClock({self._t})"
