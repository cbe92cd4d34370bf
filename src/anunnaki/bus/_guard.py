"""A platform's guard against losing its autonomic manager (issue #12).

A robot must not keep driving on its own judgement when the manager that watches it is gone:
:class:`LivelinessGuard` watches the liveliness tokens of the nodes it depends on (Utu's
``/utu_<node>`` tokens by default) and, once a node it has seen has been gone for longer than
``timeout`` seconds, calls ``on_lost`` once — the platform stops, hovers or lands by itself.
A node that comes back within the timeout (a restart) cancels it.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from anunnaki import topics
from anunnaki.bus._api import Bus

__all__ = ["LivelinessGuard"]

log = logging.getLogger("anunnaki.bus")


class LivelinessGuard:
    """Call ``on_lost(reason)`` once when a watched node has been gone ``timeout`` seconds.

    Args:
        bus: The bus whose liveliness to watch.
        on_lost: What the platform does (e.g. its run-stop); called on a timer thread.
        timeout: Seconds a seen node may be gone before ``on_lost`` (a restart fits in it).
        prefix: The watched nodes' names start with it (default Utu's, ``/utu_``).

    """

    def __init__(
        self,
        bus: Bus,
        on_lost: Callable[[str], object],
        *,
        timeout: float = 0.5,
        prefix: str = topics.UTU_NODE_PREFIX,
    ) -> None:
        if not timeout > 0:
            raise ValueError(f"timeout must be > 0 seconds, got {timeout!r}")
        self.timeout = timeout
        self.prefix = prefix
        self.fired: str | None = None  # the reason, once on_lost was called
        self._on_lost = on_lost
        self._lock = threading.Lock()
        self._seen: set[str] = set()
        self._gone: set[str] = set()
        self._timer: threading.Timer | None = None
        self._closed = False
        self._watch = bus.watch_liveliness(self._changed)

    def _changed(self, node: str, alive: bool) -> None:
        if not node.startswith(self.prefix):
            return
        with self._lock:
            if self._closed or self.fired is not None:
                return
            if alive:
                self._seen.add(node)
                self._gone.discard(node)
                if not self._gone and self._timer is not None:
                    self._timer.cancel()
                    self._timer = None
            elif node in self._seen:
                self._gone.add(node)
                if self._timer is None:
                    self._timer = threading.Timer(self.timeout, self._expired)
                    self._timer.daemon = True
                    self._timer.start()

    def _expired(self) -> None:
        with self._lock:
            if self._closed or not self._gone or self.fired is not None:
                return
            self.fired = reason = (
                f"{', '.join(sorted(self._gone))} gone for more than {self.timeout:g} s"
            )
        log.warning("liveliness guard: %s; the platform stops by itself", reason)
        try:
            self._on_lost(reason)
        except Exception:  # the guard must not die with the platform's handler
            log.exception("liveliness guard: on_lost raised")

    def close(self) -> None:
        """Stop watching (idempotent); a pending timer is cancelled."""
        with self._lock:
            self._closed = True
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
        self._watch.close()
