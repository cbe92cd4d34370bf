"""How many guesses at the dashboard's operator token a client gets.

How strong the token must be is :mod:`anunnaki.tokens`.
"""

from __future__ import annotations

import collections
import threading
import time

__all__ = ["Throttle"]


class Throttle:
    """Failed token attempts per client: past ``limit`` in ``window`` s, wait ``lockout`` s.

    Also across all clients (``limit × 4`` in the window), so that many addresses do not
    multiply the guesses. Thread-safe (FastAPI runs sync handlers in a thread pool).
    """

    def __init__(self, limit: int = 5, window: float = 60.0, lockout: float = 60.0) -> None:
        self.limit, self.window, self.lockout = limit, window, lockout
        self._failures: dict[str, collections.deque[float]] = {}
        self._all: collections.deque[float] = collections.deque(maxlen=limit * 4)
        self._lock = threading.Lock()

    def wait(self, host: str) -> float:
        """Seconds ``host`` must still wait before its next attempt (0: go ahead)."""
        now = time.monotonic()
        with self._lock:
            waits = [0.0]
            for times, limit in (
                (self._failures.get(host), self.limit),
                (self._all, self.limit * 4),
            ):
                if times is not None and len(times) >= limit and now - times[-limit] < self.window:
                    waits.append(times[-1] + self.lockout - now)
            return max(waits)

    def failed(self, host: str) -> None:
        """Count a failed attempt by ``host``."""
        now = time.monotonic()
        with self._lock:
            if host not in self._failures and len(self._failures) >= 4096:
                self._failures.clear()  # bounded memory under address churn
            self._failures.setdefault(host, collections.deque(maxlen=self.limit)).append(now)
            self._all.append(now)
