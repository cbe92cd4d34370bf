"""The node kit: one base class whose lifecycle the framework owns.

A node is a service on the bus — a Utu part, the LEC, an oracle, a bridge. Its lifecycle is
always the same, so :class:`Node` owns it, as py_trees owns ``tick()``; subclasses fill in
hooks:

1. **bring-up** (the constructor): :meth:`Node.declare` declares subscriptions and services;
   then — *last* — the node's liveliness token and its readiness service, so that a node
   that answers "ready" is fully up (guideline C9), and one that fails to come up raises
   and leaves nothing declared (B5);
2. **spin**: :meth:`Node.spin` calls :meth:`Node.spin_once` until stopped; the hook does what
   can be done now and says how long to wait; a message on a subscriber made with
   :meth:`Node.pull` wakes it at once (event-driven), and an exception in one round is
   logged and contained (the node lives on);
3. **close**: readiness and token go first (others stop counting on the node), then every
   declared object, then :meth:`Node.release` for what the subclass holds.

Example::

    class Echo(Node):
        def declare(self) -> None:
            self.inbox = self.pull("/echo/in", queue=16)

        def spin_once(self) -> float:
            while (sample := self.inbox.try_recv()) is not None:
                self.bus.publish("/echo/out", sample.message)
            return 0.5                     # nothing else to do: sleep until woken

    with open_bus("inproc") as bus, Echo(bus, token="/echo", ready="/echo/ready") as node:
        threading.Thread(target=node.spin, args=(stop,)).start()
"""

from __future__ import annotations

import logging
import os
import threading
from collections.abc import Callable
from typing import Any, Protocol, cast

from anunnaki._closing import Closing
from anunnaki.bus._api import Bus, Subscriber
from anunnaki.messages import Message

__all__ = ["Node"]

log = logging.getLogger("anunnaki.bus")


class _Closable(Protocol):
    def close(self) -> None: ...


class Node(Closing):
    """A node on the bus: declare, readiness, liveliness, spin, close.

    Args:
        bus: The bus (the node does not close it).
        token: The liveliness token held while the node is up (e.g. ``/utu_monitor``).
        ready: The readiness service (e.g. ``/utu/monitor/ready``); ``None`` for none.

    Subclasses set up their own state *before* calling ``super().__init__`` (or in
    :meth:`declare`), since :meth:`declare` runs inside it.

    """

    def __init__(self, bus: Bus, *, token: str | None, ready: str | None) -> None:
        self.bus = bus
        self.token = token
        self.ready = False
        self.cycles = 0
        #: Called at the start of every round of :meth:`spin` (e.g. a watchdog's beat).
        self.on_round: Callable[[], object] | None = None
        self._declared: list[_Closable] = []
        self._wake = threading.Event()
        self._closed = False
        try:
            self.declare()
            if token is not None:
                self.own(bus.liveliness_token(token))
            self.ready = True
            if ready is not None:
                self.own(bus.service(ready, self._ready_reply))
        except BaseException:
            self.close()
            raise

    # -- hooks --------------------------------------------------------------------------------
    def declare(self) -> None:
        """Hook, called once by the constructor: declare subscriptions and services."""

    def spin_once(self) -> float:
        """Hook, called by :meth:`spin`: do what can be done now; return seconds to wait.

        A wake-up (a message on a :meth:`pull` subscriber, :meth:`wake`) ends the wait early.
        """
        return 0.5

    def ready_info(self) -> dict[str, Any]:
        """Hook: extra fields of the readiness reply."""
        return {}

    def release(self) -> None:
        """Hook, called last by :meth:`close`: release what the node holds besides bus objects."""

    # -- helpers for subclasses -------------------------------------------------------------------
    def own(self, obj: Any) -> Any:
        """Close ``obj`` with the node (declared bus objects, watches, …)."""
        self._declared.append(obj)
        return obj

    def pull(
        self,
        topic: str,
        *,
        queue: int = 16,
        expect: type[Message] | tuple[type[Message], ...] | None = None,
    ) -> Subscriber:
        """A bounded pull subscriber whose arrivals wake :meth:`spin` (event-driven).

        With ``expect``, a message of another type is dropped and counted as malformed by
        the bus: a node's inputs are validated at the boundary.
        """
        sub = self.bus.subscribe(topic, queue=queue, expect=expect, on_ready=self.wake)
        return cast(Subscriber, self.own(sub))

    def wake(self) -> None:
        """Wake :meth:`spin` now (safe from any thread)."""
        if not self._wake.is_set():
            self._wake.set()

    @property
    def closed(self) -> bool:
        """Whether the node was closed."""
        return self._closed

    # -- the lifecycle --------------------------------------------------------------------------
    def _ready_reply(self, message: Any) -> dict[str, Any]:
        return {
            "ready": self.ready and not self._closed,
            "node": self.token,
            "pid": os.getpid(),
            "cycles": self.cycles,
            **self.ready_info(),
        }

    def spin(self, stop: threading.Event | None = None) -> None:
        """Run live until ``stop`` is set or the node is closed."""
        stop = stop or threading.Event()
        while not stop.is_set() and not self._closed:
            self._wake.clear()
            if self.on_round is not None:
                self.on_round()
            try:
                wait = self.spin_once()
            except Exception:  # one bad round must not kill the node (DESIGN: log, go on)
                log.exception("%s: a round failed; going on", self.token or type(self).__name__)
                wait = 0.05
            if wait > 0 and not stop.is_set():
                self._wake.wait(min(wait, 0.5))

    def close(self) -> None:
        """Withdraw readiness and token first, then everything else, then :meth:`release`."""
        if self._closed:
            return
        self._closed = True
        self.ready = False
        self._wake.set()  # a spinning thread returns now
        for obj in reversed(self._declared):
            try:
                obj.close()
            except Exception as exc:  # best effort at shutdown
                log.debug("%s: closing %r: %r", self.token, obj, exc)
        self._declared.clear()
        self.release()
