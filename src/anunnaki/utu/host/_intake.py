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

On simulation time a live host stamps each input with the simulated time in force when it
was published (:class:`SimStamps`, ROS's ``header.stamp`` done with the bus's envelopes), not
with the time of the step that takes it: an input that arrives an instant late is not taken
an instant late (issue #30).
"""

from __future__ import annotations

import bisect
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

from anunnaki.bus import Sample, Subscriber
from anunnaki.clock import Clock, SimClock
from anunnaki.messages import body_of

__all__ = [
    "CLOCK_QUEUE",
    "FIRST",
    "FLOOR",
    "IntakeBudget",
    "MonitoredTopics",
    "SimStamps",
    "clock_feed",
    "stamp_inputs",
    "take_clock",
    "take_inputs",
]

#: One input of a step: (topic, message body, arrival time or ``None`` for the step's time).
Input = tuple[str, dict[str, Any], float | None]
#: One message taken from a monitored topic, not stamped yet: (topic, sample).
Taken = tuple[str, Sample]

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


def take_inputs(subs: Mapping[str, Subscriber], limit: int) -> list[Taken]:
    """Take at most ``limit`` queued messages from each monitored topic's pull subscriber.

    Every host (the inline manager, the monitor node) takes its inputs here, then the
    simulation time (:func:`take_clock`), then stamps them (:func:`stamp_inputs`).
    """
    taken: list[Taken] = []
    for topic, sub in subs.items():
        for _ in range(limit):
            if (sample := sub.try_recv()) is None:
                break
            taken.append((topic, sample))
    return taken


def stamp_inputs(
    taken: Sequence[Taken], *, wall: bool, stamps: SimStamps | None = None
) -> list[Input]:
    """The inputs of ``taken``, each with its arrival time (``None``: the step's time).

    With ``wall``, an input keeps the sender's stamp. On simulation time, with ``stamps``
    (a live host), it takes the simulated time in force when its sender published it, where
    the sender's ``/clock`` history covers it; otherwise (no history, a deterministic step)
    the step's time. The monitor stage clamps either into the step.
    """
    out: list[Input] = []
    for topic, sample in taken:
        if wall:
            t: float | None = sample.sent_at
        elif stamps is not None:
            t = stamps.instant(sample.sender, sample.sent_at)
        else:
            t = None
        out.append((topic, body_of(sample.message), t))
    return out


class SimStamps:
    """The simulated time in force when a message was published, from the ``/clock`` heard.

    ROS stamps a message with the simulated time at publication (``header.stamp``); the bus
    carries no such field, but every envelope carries its sender's wall clock
    (:attr:`~anunnaki.bus.Sample.sent_at`), and a simulator publishes ``/clock`` before each
    instant's messages. So the instant of a message is the time of the last ``/clock`` its
    sender published before it: this keeps, for each sender, the last ``depth`` pairs
    (``/clock``'s ``sent_at``, its time), both monotone. The dashboard does the same
    (its ``SimTime``).

    Args:
        depth: Pairs kept per sender (a ``/clock`` at 100 Hz: seconds of history).
        senders: Senders kept at once; the one heard from longest ago is forgotten first.

    """

    def __init__(self, *, depth: int = 512, senders: int = 16) -> None:
        self._depth = depth
        self._senders = senders
        self._hist: dict[str, deque[tuple[float, float]]] = {}

    def record(self, sender: str, sent_at: float, t: float) -> None:
        """A ``/clock`` of ``sender`` published at ``sent_at`` says ``t`` (kept if monotone)."""
        hist = self._hist.get(sender)
        if hist is None:
            if len(self._hist) >= self._senders:
                del self._hist[min(self._hist, key=lambda k: self._hist[k][-1][0])]
            hist = self._hist[sender] = deque(maxlen=self._depth)
        if not hist or (sent_at >= hist[-1][0] and t >= hist[-1][1]):
            hist.append((sent_at, t))

    def instant(self, sender: str, sent_at: float) -> float | None:
        """The simulated time ``sender``'s clock said at ``sent_at`` (``None``: not known).

        Not known when the sender published no ``/clock`` heard here, or published the
        message before the oldest one kept.
        """
        hist = self._hist.get(sender)
        if not hist:
            return None
        i = bisect.bisect_right(hist, (sent_at, float("inf"))) - 1
        return hist[i][1] if i >= 0 else None


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

    def take(self, limit: int) -> list[Taken]:
        """At most ``limit`` queued messages of each topic (:func:`take_inputs`)."""
        return take_inputs(self.subs, limit)

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


def take_clock(clock: Clock, sub: Subscriber | None, stamps: SimStamps | None = None) -> None:
    """Apply the simulation times queued on ``sub`` (the ``/clock`` topic) to ``clock``.

    At most :data:`CLOCK_QUEUE` a call: a ``/clock`` flood must not hold the step. Nothing
    happens on a wall clock or without a subscriber. Each time the clock accepts is also
    recorded in ``stamps`` (with its sender and ``sent_at``).
    """
    if sub is None or not isinstance(clock, SimClock):
        return
    for _ in range(CLOCK_QUEUE):
        if (sample := sub.try_recv()) is None:
            break
        t = getattr(sample.message, "time", None)
        if isinstance(t, int | float) and clock.update(float(t)) and stamps is not None:
            stamps.record(sample.sender, sample.sent_at, float(t))
