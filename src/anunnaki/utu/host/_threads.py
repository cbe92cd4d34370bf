"""Actions off the loop's path: service requests in flight, each with its own deadline.

:class:`ThreadRunner` is the live :class:`~anunnaki.utu.cycle.ActionRunner` (see
:mod:`anunnaki.utu.cycle._actions` for why actions leave the loop). A request the actuator can
send without waiting (``request_start``: the bus actuator's, a transport's asynchronous query)
leaves from the step itself and its reply completes it: no thread in between, which takes a
thread hand-over off the reaction (``benchmarks/reaction.py``); given no reply by its timeout
it is reported failed. Any other request runs on one of a few worker threads; one whose
thread has not come back by its timeout plus a grace period is reported failed ("no reply
within …") and its thread abandoned, so even an actuator that ignores its own timeout cannot
hold the loop.
"""

from __future__ import annotations

import concurrent.futures as cf
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from anunnaki.utu.cycle._actions import ActionOutcome, Finished, Start

__all__ = ["ThreadRunner", "action_runner"]

log = logging.getLogger("anunnaki.utu")

#: Seconds a worker thread may overrun its action's timeout before the action is failed.
GRACE = 0.5
#: Seconds :meth:`ThreadRunner.submit` waits for an outcome by default (sim time, by hand):
#: ``None``, up to the action's own timeout — a run on sim time repeats itself however loaded
#: the machine is, and a dead or hung service still cannot hold it longer than that.
SETTLE: float | None = None


@dataclass
class _Flight:
    tactic: str
    index: int
    future: cf.Future[ActionOutcome]
    deadline: float  # time.monotonic()
    timeout: float
    threaded: bool = True  # on a worker thread (else a request sent without waiting)


class ThreadRunner:
    """Live actions on worker threads (``anunnaki-action``), each with a wall-clock deadline.

    Args:
        workers: Threads (an action holds one until its request returns or times out).
        on_done: Called from the worker thread when an action came back (e.g. the loop's
            ``wake``), so the loop takes the outcome without waiting for its period.
        grace: Seconds past an action's timeout before it is reported failed regardless.
        settle: Seconds :meth:`submit` waits for the outcome before leaving the action in
            flight (``None``: up to the action's timeout): a service that answers at once
            has its outcome recorded in the cycle that started it (as a run on sim time
            needs to repeat itself), a slow one holds the loop no longer than this.

    """

    def __init__(
        self,
        *,
        workers: int = 4,
        on_done: Callable[[], object] | None = None,
        grace: float = GRACE,
        settle: float | None = SETTLE,
    ) -> None:
        self._pool = cf.ThreadPoolExecutor(
            max_workers=workers, thread_name_prefix="anunnaki-action"
        )
        self._flights: list[_Flight] = []
        self._lock = threading.Lock()
        self.on_done = on_done
        self.grace = grace
        self.settle = settle
        self._closed = False

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
        """Send ``start``'s request here, else run ``call`` on a worker thread.

        Returns the outcome if it is back within ``settle`` seconds, else ``None``.
        """
        if self._closed:
            return ActionOutcome(False, "the loop is closing; action not performed")
        if start is not None:
            try:
                future = start()
            except Exception as exc:  # an actuator must never kill the loop
                return ActionOutcome(False, f"{type(exc).__name__}: {exc}")
            deadline = time.monotonic() + timeout
        else:
            future = self._pool.submit(call)
            deadline = time.monotonic() + timeout + self.grace
        wait = timeout if self.settle is None else min(self.settle, timeout)
        if future.done() or wait > 0:
            cf.wait([future], timeout=wait)
            if future.done():
                return _result(future)
        flight = _Flight(tactic, index, future, deadline, timeout, threaded=start is None)
        with self._lock:
            self._flights.append(flight)
        if self.on_done is not None:
            callback = self.on_done
            future.add_done_callback(lambda _f: callback())
        return None

    def finished(self, now: float) -> list[Finished]:
        """Outcomes of the actions that returned, and failures of those past their deadline."""
        clock = time.monotonic()
        out: list[Finished] = []
        with self._lock:
            keep: list[_Flight] = []
            for f in self._flights:
                if f.future.done():
                    out.append(Finished(f.tactic, f.index, _result(f.future)))
                elif clock >= f.deadline:
                    log.warning(
                        "action %d of %s did not come back within %.1f s; failed",
                        f.index,
                        f.tactic,
                        f.timeout,
                    )
                    detail = (  # a thread is abandoned; a request sent is given up
                        f"no reply within {f.timeout:g} s (abandoned)"
                        if f.threaded
                        else f"no reply within {f.timeout} s"
                    )
                    out.append(Finished(f.tactic, f.index, ActionOutcome(False, detail)))
                else:
                    keep.append(f)
            self._flights = keep
        return out

    @property
    def has_outcomes(self) -> bool:
        """Whether :meth:`finished` would hand something back now."""
        clock = time.monotonic()
        with self._lock:
            return any(f.future.done() or clock >= f.deadline for f in self._flights)

    @property
    def in_flight(self) -> int:
        """Actions submitted and not yet handed back."""
        with self._lock:
            return len(self._flights)

    def close(self) -> None:
        """Abandon in-flight actions; do not wait for their threads."""
        self._closed = True
        self._pool.shutdown(wait=False, cancel_futures=True)


def _result(future: cf.Future[ActionOutcome]) -> ActionOutcome:
    try:
        return future.result()
    except cf.CancelledError:
        return ActionOutcome(False, "cancelled")
    except Exception as exc:  # an actuator must never kill the loop
        return ActionOutcome(False, f"{type(exc).__name__}: {exc}")


def action_runner(actuator: object, on_done: Callable[[], object]) -> ThreadRunner | None:
    """Worker threads for an actuator whose requests wait (``blocking``), else ``None``.

    Every host runs such requests off its loop's path and is woken (``on_done``) when one
    comes back.
    """
    if getattr(actuator, "blocking", False):
        return ThreadRunner(on_done=on_done)
    return None
