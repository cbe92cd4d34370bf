"""The dashboard's operator token: how strong it must be, and how many guesses it allows."""

from __future__ import annotations

import collections
import math
import threading
import time

__all__ = ["MIN_TOKEN_BITS", "Throttle", "token_weakness"]

#: The least estimated strength of an operator token, in bits.
MIN_TOKEN_BITS = 128

_CLASSES: tuple[tuple[str, int], ...] = (
    ("abcdefghijklmnopqrstuvwxyz", 26),
    ("ABCDEFGHIJKLMNOPQRSTUVWXYZ", 26),
    ("0123456789", 10),
)


def token_weakness(token: str) -> str | None:
    """Why ``token`` is too weak to guard operator actions, or ``None`` when it will do.

    Its strength is estimated as ``length × log2(alphabet)``, the alphabet being the sum of
    the character classes it uses (lower case 26, upper case 26, digits 10, anything else
    33), and must reach :data:`MIN_TOKEN_BITS`; a token of one repeated character or with
    fewer than 8 distinct characters is refused whatever its length. A
    ``secrets.token_urlsafe(16)`` token (22 characters) passes.
    """
    if not token.strip():
        return "it is empty"
    alphabet = sum(size for chars, size in _CLASSES if any(c in chars for c in token))
    if any(not any(c in chars for chars, _ in _CLASSES) for c in token):
        alphabet += 33
    bits = len(token) * math.log2(max(alphabet, 2))
    if len(set(token)) < 8:
        return f"it uses {len(set(token))} distinct characters (at least 8)"
    if bits < MIN_TOKEN_BITS:
        return f"about {bits:.0f} bits, fewer than {MIN_TOKEN_BITS}"
    return None


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
