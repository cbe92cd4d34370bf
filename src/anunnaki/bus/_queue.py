"""A bounded, priority-aware queue: the memory bound of every subscriber (guideline S1).

Transport threads push (never block, never run user code); a dispatcher thread or the pull API
pops. When the queue is full it evicts according to ``drop``:

* ``"oldest"`` (latest-value semantics): the oldest item of the least urgent priority present
  goes, the new item stays;
* ``"newest"``: the new item is refused, unless it is more urgent than something queued, in
  which case the newest item of the least urgent priority present goes.

An item less urgent than everything queued is always the one refused. Pops hand out the most
urgent item first, in arrival order within a priority.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from typing import Generic, Literal, TypeVar

__all__ = ["DropPolicy", "PriorityQueue"]

T = TypeVar("T")
DropPolicy = Literal["oldest", "newest"]
_RANKS = 4


class PriorityQueue(Generic[T]):
    """Bounded multi-lane queue; lane 0 is the most urgent.

    Args:
        maxlen: The bound on the number of queued items (>= 1).
        drop: ``"oldest"`` or ``"newest"`` (see the module docstring).

    """

    def __init__(self, maxlen: int, drop: DropPolicy = "oldest") -> None:
        if maxlen < 1:
            raise ValueError(f"queue bound must be >= 1, got {maxlen}")
        if drop not in ("oldest", "newest"):
            raise ValueError(f"drop must be 'oldest' or 'newest', got {drop!r}")
        self.maxlen = maxlen
        self.drop = drop
        self._lanes: list[deque[T]] = [deque() for _ in range(_RANKS)]
        self._len = 0
        self._cond = threading.Condition(threading.Lock())
        self._closed = False
        self.high_water = 0

    def __len__(self) -> int:
        return self._len

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called."""
        return self._closed

    def push(self, item: T, rank: int = 2) -> T | None:
        """Queue ``item`` with priority ``rank`` (0 most urgent … 3 least).

        Returns:
            The item that was dropped to respect the bound (possibly ``item`` itself), or
            ``None`` when nothing was dropped. A closed queue drops ``item``.

        """
        rank = min(max(rank, 0), _RANKS - 1)
        with self._cond:
            if self._closed:
                return item
            victim: T | None = None
            if self._len >= self.maxlen:
                lowest = max(r for r in range(_RANKS) if self._lanes[r])
                if rank > lowest or (rank == lowest and self.drop == "newest"):
                    return item
                lane = self._lanes[lowest]
                victim = lane.popleft() if self.drop == "oldest" else lane.pop()
                self._len -= 1
            self._lanes[rank].append(item)
            self._len += 1
            self.high_water = max(self.high_water, self._len)
            self._cond.notify()
            return victim

    def pop(self, timeout: float | None = None) -> T | None:
        """Pop the most urgent item, waiting up to ``timeout`` s (``None``: until closed).

        Returns:
            The item, or ``None`` on timeout or when the queue is closed.

        """
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._cond:
            while True:
                if self._closed:
                    return None
                if self._len:
                    for lane in self._lanes:
                        if lane:
                            self._len -= 1
                            return lane.popleft()
                if deadline is None:
                    self._cond.wait()
                else:
                    remaining = deadline - time.monotonic()
                    if remaining <= 0:
                        return None
                    self._cond.wait(remaining)

    def close(self) -> list[T]:
        """Close the queue, wake every waiter, and return the items still queued."""
        with self._cond:
            self._closed = True
            left = [item for lane in self._lanes for item in lane]
            for lane in self._lanes:
                lane.clear()
            self._len = 0
            self._cond.notify_all()
            return left
