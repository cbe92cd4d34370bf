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

from collections.abc import Callable, Iterable, Mapping
from typing import Any

from anunnaki.bus import Subscriber
from anunnaki.clock import Clock, SimClock
from anunnaki.messages import body_of

__all__ = [
    "CLOCK_QUEUE",
    "FIRST",
    "FLOOR",
    "IntakeBudget",
    "MonitoredTopics",
    "clock_feed",
    "take_clock",
    "take_inputs",
]

#: One input of a step: (topic, message body, arrival time or ``None`` for the step's time).
Input = tuple[str, dict[str, Any], float | None]

FLOOR = 16
"""Inputs per topic per step that a budget never cuts (a 20 Hz topic brings 1 per step)."""

FIRST = 64
"""The limit until a step has measured what an input costs (then it follows the budget)."""

CLOCK_QUEUE = 64
"""Depth of a host's ``/clock`` queue, and how many times a step applies at most."""


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


def take_inputs(subs: Mapping[str, Subscriber], limit: int, *, wall: bool) -> list[Input]:
    """Take at most ``limit`` queued messages from each monitored topic's pull subscriber.

    With ``wall``, an input keeps the sender's stamp (a simulation clock is another timebase:
    the input then takes the step's time); the monitor stage clamps it into the step.
    Every host (the inline manager, the monitor node) takes its inputs here.
    """
    inputs: list[Input] = []
    for topic, sub in subs.items():
        for _ in range(limit):
            if (sample := sub.try_recv()) is None:
                break
            inputs.append((topic, body_of(sample.message), sample.sent_at if wall else None))
    return inputs


class MonitoredTopics:
    """The bounded pull subscribers of the topics a host monitors (guideline S1), by topic.

    Every host (the inline manager, the monitor node) keeps its inputs here: a flood on one
    topic cannot starve the others, and a step takes what arrived before it.

    Args:
        subscribe: Declares the host's pull subscriber of one topic (with the host's
            doorbell, closed with the host).

    """

    def __init__(self, subscribe: Callable[[str], Subscriber]) -> None:
        self._subscribe = subscribe
        self.subs: dict[str, Subscriber] = {}

    def watch(self, topics: Iterable[str]) -> None:
        """Subscribe each of ``topics`` not watched yet (a reload may watch new ones)."""
        for topic in topics:
            if topic not in self.subs:
                self.subs[topic] = self._subscribe(topic)

    def take(self, limit: int, *, wall: bool) -> list[Input]:
        """At most ``limit`` queued messages of each topic (:func:`take_inputs`)."""
        return take_inputs(self.subs, limit, wall=wall)

    def queues(self) -> list[Subscriber]:
        """The bounded queues, one a topic."""
        return list(self.subs.values())

    @property
    def pending(self) -> bool:
        """Whether a message waits on any topic."""
        return any(sub.pending for sub in self.subs.values())

    def __len__(self) -> int:
        return len(self.subs)


def clock_feed(
    clock: Clock, topic: str, subscribe: Callable[[str, int], Subscriber]
) -> Subscriber | None:
    """The ``/clock`` queue of a host whose clock is the simulation's (else ``None``).

    ``subscribe(topic, depth)`` declares the host's pull subscriber; :func:`take_clock`
    applies what it holds at the start of each step, after the inputs: a message published
    after its instant's ``/clock`` is never stamped with an earlier time.
    """
    return subscribe(topic, CLOCK_QUEUE) if isinstance(clock, SimClock) else None


def take_clock(clock: Clock, sub: Subscriber | None) -> None:
    """Apply the simulation times queued on ``sub`` (the ``/clock`` topic) to ``clock``.

    At most :data:`CLOCK_QUEUE` a call: a ``/clock`` flood must not hold the step. Nothing
    happens on a wall clock or without a subscriber.
    """
    if sub is None or not isinstance(clock, SimClock):
        return
    for _ in range(CLOCK_QUEUE):
        if (sample := sub.try_recv()) is None:
            break
        t = getattr(sample.message, "time", None)
        if isinstance(t, int | float):
            clock.update(float(t))
