"""One thread of delivery for a simulated run: the bus's deterministic executor (issue #30).

A bus delivers on threads of its own by default: each callback subscriber, service and
liveliness watch has a dispatcher thread, as a live deployment needs (zenoh, the ROS bridges,
``--processes``). A simulation needs the opposite: one program, in order, that computes the
same thing however loaded the machine is. An in-process bus opened with an
:class:`Executor` (``open_bus("inproc", executor=ex)``, or ``InprocHub(executor=ex)`` for
every bus on a hub) has no such threads. Instead:

* every message published is **queued on the executor, in publication order** (FIFO, one
  item per message and subscriber); a subscriber's callback runs when the executor reaches
  it. Within one subscriber the most urgent message goes first, as live;
* a pull subscriber's doorbell (``on_ready``) and a liveliness watch's callback are queued
  the same way;
* a **service request is answered in the same drain**: on the executor's own thread by a
  direct call of the handler, nested in the requester's call (as rclpy answers a request
  made on its executor's thread); from any other thread (an operator's dashboard) it is
  queued, and the requester waits for the drain that answers it;
* :meth:`Executor.spin_until_idle` runs queued work until none is left, then the idle
  hooks (:meth:`Executor.on_idle`: e.g. Utu's step at the present instant), and again until
  both are quiet. The simulation calls it after it published an instant's messages and
  only then moves its clock on.

Node code is written once: a node declares handlers, and whether an executor or the
transport's threads call them is the deployment's business, as with rclpy's executors.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable

__all__ = ["Executor", "ExecutorOverrun"]

log = logging.getLogger("anunnaki.bus")

Work = Callable[[], object]


class ExecutorOverrun(RuntimeError):
    """A drain did not end: the nodes keep publishing to each other without end."""


class Executor:
    """Runs the work of every node on one thread, in a fixed order (see the module docstring).

    Args:
        limit: Most work items one :meth:`spin_until_idle` runs before it gives up
            (:class:`ExecutorOverrun`): two nodes answering each other forever would
            otherwise hold the run.

    The executor's thread is the one that calls :meth:`spin_until_idle` (the first call
    binds it; :meth:`bind` binds another). :meth:`post` may be called from any thread.

    """

    def __init__(self, *, limit: int = 1_000_000) -> None:
        if limit < 1:
            raise ValueError(f"limit must be >= 1, got {limit!r}")
        self.limit = limit
        self._queue: deque[Work] = deque()
        self._lock = threading.Lock()
        self._idle: list[Callable[[], bool]] = []
        self._thread: threading.Thread | None = None
        self._draining = False
        self.ran = 0  # work items run so far
        self.drains = 0  # calls of spin_until_idle
        self.errors = 0  # work items that raised (logged; the drain went on)
        self._closed = False

    # -- who runs it
    def bind(self, thread: threading.Thread | None = None) -> None:
        """Make ``thread`` (default: the calling one) the executor's thread."""
        self._thread = thread or threading.current_thread()

    def release(self) -> None:
        """Unbind the executor's thread (its run is over): any thread may drain it again.

        Drain first: a request posted by another thread waits for the drain that answers it.
        """
        self._thread = None

    @property
    def on_thread(self) -> bool:
        """Whether the calling thread is the executor's (unbound: any thread is)."""
        return self._thread is None or self._thread is threading.current_thread()

    # -- work
    def post(self, work: Work) -> None:
        """Queue ``work`` (a callable without arguments) after everything queued so far.

        After :meth:`close` nothing is queued any more.
        """
        with self._lock:
            if not self._closed:
                self._queue.append(work)

    def on_idle(self, hook: Callable[[], bool]) -> Callable[[], None]:
        """Call ``hook()`` whenever a drain found nothing queued; returns its removal.

        ``hook`` returns whether it did something (queued work, stepped): the drain then goes
        on, and asks every hook again once the queue is empty again. Hooks run in the
        order they were added.
        """
        self._idle.append(hook)

        def remove() -> None:
            if hook in self._idle:
                self._idle.remove(hook)

        return remove

    @property
    def pending(self) -> int:
        """Work items queued now."""
        return len(self._queue)

    def _next(self) -> Work | None:
        with self._lock:
            return self._queue.popleft() if self._queue else None

    def spin_until_idle(self) -> int:
        """Run queued work in order, then the idle hooks, until all are quiet.

        Returns the number of work items run. Work that raises is logged and counted
        (``errors``); the drain goes on. Called again from inside a drain (a handler that
        drains) it returns 0 at once: the outer drain runs what was queued.

        Raises:
            ExecutorOverrun: More than ``limit`` items in one call.
            RuntimeError: Called from a thread other than the executor's.

        """
        if self._thread is None:
            self.bind()
        elif self._thread is not threading.current_thread():
            raise RuntimeError(
                f"the executor runs on thread {self._thread.name!r}; "
                f"{threading.current_thread().name!r} may only post work to it"
            )
        if self._draining:
            return 0
        self._draining = True
        self.drains += 1
        ran = 0
        try:
            while True:
                work = self._next()
                if work is None:
                    if not any([hook() for hook in list(self._idle)]) and not self._queue:
                        return ran
                    continue
                ran += 1
                self.ran += 1
                if ran > self.limit:
                    raise ExecutorOverrun(
                        f"one drain ran more than {self.limit} work items: nodes keep "
                        "publishing to each other; look for a callback that answers its own "
                        "messages"
                    )
                try:
                    work()
                except Exception:
                    self.errors += 1
                    log.exception("executor: a work item raised; the drain goes on")
        finally:
            self._draining = False

    def close(self) -> None:
        """Drop what is queued and the idle hooks."""
        with self._lock:
            self._queue.clear()
            self._idle.clear()
            self._closed = True
