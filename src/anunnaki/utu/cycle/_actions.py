"""How an action's outcome comes back to the cycle, and the actions it performs through.

A live loop must never wait on the managed system: a mode change to a robot that is alive
but does not answer held every cycle for its 2 s timeout, and monitoring and analysis
stopped with it. The :class:`~anunnaki.utu.Executor` hands each request (any action whose
``send()`` gives a :class:`~anunnaki.tactics.ServiceRequest`: ``request``, ``change_mode``,
``swap_model``, …) to an :class:`ActionRunner` and goes on; the
tactic stays ``running`` while its action is in flight, and the next cycle that finds the
outcome records it (``action`` decision) and continues with the tactic's next action — or
fails the tactic and escalates when the action was refused, timed out or met a dead service.

* ``ThreadRunner`` (live, in :mod:`anunnaki.utu.host`): an actuator that can send a request
  without waiting (``request_start``, as the bus actuator does) sends it from the step itself
  and the reply completes it, with no thread between; any other request runs on one of a few
  worker threads;
* :class:`ReplayRunner` (:func:`~anunnaki.utu.replay`): gives each action the outcome the run
  recorded, at the instant the run took it, so a replay takes the same decisions at the
  same times.

Publications and notifications do not wait on anyone (a notification is sent in the
background already) and stay on the loop.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any, Protocol

from anunnaki.tactics import Notice

__all__ = [
    "ActionOutcome",
    "ActionRunner",
    "Actuator",
    "Finished",
    "RecordedOutcome",
    "ReplayRunner",
    "Start",
]

#: A request sent without waiting: called once, it returns the future its outcome completes.
Start = Callable[[], "Future[ActionOutcome]"]


@dataclass(frozen=True)
class ActionOutcome:
    """The result of one action."""

    ok: bool
    detail: str = ""
    reply: dict[str, Any] | None = None


class Actuator(Protocol):
    """How actions reach the managed system."""

    def publish(self, topic: str, payload: Mapping[str, Any]) -> ActionOutcome:
        """Publish a message on a topic."""
        ...

    def request(self, service: str, payload: Mapping[str, Any], timeout: float) -> ActionOutcome:
        """Request a service and wait for the reply."""
        ...

    def notify(self, action: Notice, tactic: str, now: float) -> ActionOutcome:
        """Send a notice (what a ``notify`` action sends; may complete in the background)."""
        ...


@dataclass(frozen=True)
class Finished:
    """An action that came back: which tactic, which of its actions, and how it went."""

    tactic: str
    index: int
    outcome: ActionOutcome


class ActionRunner(Protocol):
    """Runs actions off the loop and hands back their outcomes when a cycle asks."""

    def submit(
        self,
        tactic: str,
        index: int,
        call: Callable[[], ActionOutcome],
        timeout: float,
        now: float,
        *,
        attempt: int = 0,
        start: Start | None = None,
    ) -> ActionOutcome | None:
        """Start one action; its outcome now, or ``None`` while it is in flight.

        ``call`` performs it and waits; ``start``, where the actuator has one, sends the
        same request without waiting (a runner that can takes it instead of a thread).
        """
        ...

    def finished(self, now: float) -> list[Finished]:
        """The actions that came back (or overran their deadline), in submission order."""
        ...

    def close(self) -> None:
        """Stop taking work; in-flight actions are abandoned."""
        ...


@dataclass(frozen=True)
class RecordedOutcome:
    """One action's outcome as a run recorded it (its ``action`` decision)."""

    t: float
    tactic: str
    index: int
    ok: bool
    detail: str
    attempt: int | None = None  # which start of the tactic (None: an older log)


class ReplayRunner:
    """Each action gets its recorded outcome, at the instant the run took it.

    An action is matched with the recorded outcome of the same tactic, start (attempt) and
    action index — an action in flight when the run was killed has none, and a restarted
    run goes on with the next one. Recorded at the instant it was started (a run whose
    actions ran on the loop, or that came back within the step), the outcome is given at
    once; recorded later, it is handed back by the first cycle at or after that instant —
    the cycle the run took it in.
    An action the run never recorded (the log ends first) succeeds at once.
    """

    def __init__(self, recorded: Iterable[RecordedOutcome], *, tolerance: float = 1e-9) -> None:
        self._recorded: dict[tuple[str, int | None, int], deque[RecordedOutcome]] = {}
        for r in recorded:
            self._recorded.setdefault((r.tactic, r.attempt, r.index), deque()).append(r)
        self._pending: list[RecordedOutcome] = []
        self.tolerance = tolerance

    def submit(
        self,
        tactic: str,
        index: int,
        call: Callable[[], ActionOutcome],
        timeout: float,
        now: float,
        *,
        attempt: int = 0,
        start: Start | None = None,
    ) -> ActionOutcome | None:
        """The recorded outcome now, or ``None`` until the instant the run took it."""
        queue = self._recorded.get((tactic, attempt, index)) or self._recorded.get(
            (tactic, None, index)
        )
        if not queue:
            return ActionOutcome(True, "not recorded (the log ends first)")
        rec = queue.popleft()
        if rec.t <= now + self.tolerance:
            return ActionOutcome(rec.ok, rec.detail)
        self._pending.append(rec)
        return None

    def finished(self, now: float) -> list[Finished]:
        """The recorded outcomes due by ``now``."""
        due = [r for r in self._pending if r.t <= now + self.tolerance]
        self._pending = [r for r in self._pending if r.t > now + self.tolerance]
        return [Finished(r.tactic, r.index, ActionOutcome(r.ok, r.detail)) for r in due]

    def close(self) -> None:
        """Nothing runs: nothing to stop."""
