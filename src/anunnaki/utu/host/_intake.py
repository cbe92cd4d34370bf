"""How much a live step takes from a flooded topic: a time budget per step (issue #12).

A step analyses every input it takes (each recorded and evaluated), so under a flood a step
that takes a full queue (``intake``, 1,024 by default) lasts hundreds of milliseconds on a
loaded machine — and time-driven checks (staleness, deadlines) wait for it. A live loop
therefore takes from each topic only as many inputs as fit in half a period at the cost an
input has had lately; the rest waits in the topic's bounded queue (or is dropped and counted
by the bus). A topic that publishes a few messages per period is never cut: the limit does
not go below :data:`FLOOR`.

Only live loops on the wall clock budget their intake; a step driven by ``step(now)`` (tests,
simulation, replay) takes ``intake`` per topic, so it stays deterministic.
"""

from __future__ import annotations

__all__ = ["FIRST", "FLOOR", "IntakeBudget"]

FLOOR = 16
"""Inputs per topic per step that a budget never cuts (a 20 Hz topic brings 1 per step)."""

FIRST = 64
"""The limit until a step has measured what an input costs (then it follows the budget)."""


class IntakeBudget:
    """The per-topic intake that keeps a step within ``budget`` seconds.

    Args:
        budget: Seconds a step may spend on its inputs (a live loop gives half its period).
        ceiling: Never more than this per topic (the configuration's ``intake``).
        smoothing: Weight of the newest step in the running cost per input.

    """

    def __init__(self, budget: float, *, ceiling: int, smoothing: float = 0.3) -> None:
        if not budget > 0:
            raise ValueError(f"budget must be > 0 seconds, got {budget!r}")
        self.budget = budget
        self.ceiling = max(1, int(ceiling))
        self.smoothing = smoothing
        self.cost = 0.0  # seconds per input, as measured lately (0: not yet)

    def limit(self) -> int:
        """Inputs to take from each topic in the next step."""
        if self.cost <= 0:
            return min(FIRST, self.ceiling)
        fits = int(self.budget / self.cost)
        return max(min(FLOOR, self.ceiling), min(self.ceiling, fits))

    def spent(self, inputs: int, seconds: float) -> None:
        """A step took ``inputs`` inputs and lasted ``seconds`` (small steps say little)."""
        if inputs < FLOOR or seconds < 0:
            return
        cost = seconds / inputs
        self.cost = cost if self.cost <= 0 else self.cost + self.smoothing * (cost - self.cost)
