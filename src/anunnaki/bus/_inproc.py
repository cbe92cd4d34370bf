"""The in-process bus: the same interface without a network, for tests and single-process runs.

Buses that share an :class:`InprocHub` see each other, like zenoh sessions on one network;
each bus opened without a hub gets its own. Messages are encoded and decoded exactly as on
zenoh (so a message that would not survive the wire fails here too), and delivery goes
through the same bounded queues and dispatcher threads. What it does not have is a network:
nothing is lost in transit and priorities only order the subscriber queues.
"""

from __future__ import annotations

import threading
from collections import Counter
from collections.abc import Callable

from anunnaki.bus._api import Bus, DataCallback, QueryCallback, TokenCallback
from anunnaki.bus._errors import BusConfigError
from anunnaki.bus._executor import Executor
from anunnaki.bus._keys import key_matches
from anunnaki.bus._qos import QoS

__all__ = ["InprocBus", "InprocHub"]


class _Receiver:
    __slots__ = ("key", "on_data")

    def __init__(self, key: str, on_data: DataCallback) -> None:
        self.key = key
        self.on_data = on_data


class _Link:
    """Runs ``undo`` once on close."""

    def __init__(self, undo: Callable[[], None]) -> None:
        self._undo: Callable[[], None] | None = undo
        self._lock = threading.Lock()

    def close(self) -> None:
        with self._lock:
            undo, self._undo = self._undo, None
        if undo is not None:
            undo()


class InprocHub:
    """The in-process 'network': buses attached to the same hub exchange messages.

    Create one and pass it to every bus that should meet (``open_bus("inproc", hub=hub)``),
    or reuse ``bus.hub``.

    Args:
        executor: Deliver every message of the hub's buses on this executor's thread, in
            publication order, instead of the buses' own threads (a simulated run,
            :mod:`anunnaki.bus._executor`).

    """

    def __init__(self, *, executor: Executor | None = None) -> None:
        self.executor = executor
        self._lock = threading.Lock()
        self._receivers: tuple[_Receiver, ...] = ()
        # key -> the receivers matching it, for the receivers of this snapshot (a new dict
        # replaces it whenever receivers change, so readers never see a stale route).
        self._routes: dict[str, tuple[_Receiver, ...]] = {}
        self._queryables: dict[str, list[QueryCallback]] = {}
        self._tokens: Counter[str] = Counter()
        self._watchers: tuple[_Receiver, ...] = ()

    def _deliver(self, key: str, payload: bytes, rank: int) -> None:
        routes = self._routes  # a snapshot: no lock on the hot path
        matched = routes.get(key)
        if matched is None:
            matched = tuple(r for r in self._receivers if key_matches(r.key, key))
            if routes is self._routes and len(routes) < 4096:
                routes[key] = matched
        for r in matched:
            r.on_data(key, payload, rank)

    def _matching(self, key: str) -> bool:
        return any(key_matches(r.key, key) for r in self._receivers)

    def _add_receiver(self, key: str, on_data: DataCallback) -> _Link:
        receiver = _Receiver(key, on_data)
        with self._lock:
            self._receivers = (*self._receivers, receiver)
            self._routes = {}

        def undo() -> None:
            with self._lock:
                self._receivers = tuple(r for r in self._receivers if r is not receiver)
                self._routes = {}

        return _Link(undo)

    def _add_queryable(self, key: str, on_query: QueryCallback) -> _Link:
        with self._lock:
            self._queryables.setdefault(key, []).append(on_query)

        def undo() -> None:
            with self._lock:
                handlers = self._queryables.get(key, [])
                if on_query in handlers:
                    handlers.remove(on_query)
                if not handlers:
                    self._queryables.pop(key, None)

        return _Link(undo)

    def _query_start(
        self, key: str, payload: bytes, on_reply: Callable[[bytes | None], None]
    ) -> None:
        with self._lock:
            handlers = self._queryables.get(key)
            handler = handlers[0] if handlers else None
        if handler is None:
            on_reply(None)
        else:
            handler(payload, on_reply)

    def _add_token(self, key: str) -> _Link:
        with self._lock:
            self._tokens[key] += 1
            if self._tokens[key] == 1:
                self._notify(key, True)

        def undo() -> None:
            with self._lock:
                self._tokens[key] -= 1
                if self._tokens[key] <= 0:
                    del self._tokens[key]
                    self._notify(key, False)

        return _Link(undo)

    def _notify(self, key: str, alive: bool) -> None:
        # Called under the lock, so every watcher sees events in one order; watchers only
        # enqueue, they never call back into the hub.
        for w in self._watchers:
            if key_matches(w.key, key):
                w.on_data(key, b"\x01" if alive else b"", 0)

    def _alive(self, key: str) -> set[str]:
        with self._lock:
            return {k for k in self._tokens if key_matches(key, k)}

    def _add_watch(self, key: str, on_change: TokenCallback) -> _Link:
        def on_data(k: str, payload: bytes, _rank: int) -> None:
            on_change(k, bool(payload))

        watcher = _Receiver(key, on_data)
        with self._lock:
            self._watchers = (*self._watchers, watcher)
            for k in self._tokens:
                if key_matches(key, k):
                    on_change(k, True)

        def undo() -> None:
            with self._lock:
                self._watchers = tuple(w for w in self._watchers if w is not watcher)

        return _Link(undo)


class _InprocSender:
    __slots__ = ("_hub", "_key", "_rank")

    def __init__(self, hub: InprocHub, key: str, rank: int) -> None:
        self._hub = hub
        self._key = key
        self._rank = rank

    def send(self, payload: bytes) -> None:
        self._hub._deliver(self._key, payload, self._rank)

    def matching(self) -> bool:
        return self._hub._matching(self._key)

    def close(self) -> None:
        pass


class InprocBus(Bus):
    """A bus inside one process (see the module docstring).

    Args:
        hub: The hub to attach to; a new private one when ``None``.
        namespace: Key prefix of this system.
        name: This bus's name in envelopes.
        clock: The clock written into envelopes.
        executor: Deliver on this executor (a new hub's; see :class:`InprocHub`).

    """

    kind = "inproc"

    def __init__(
        self,
        *,
        hub: InprocHub | None = None,
        namespace: str = "anunnaki",
        name: str | None = None,
        clock: Callable[[], float] | None = None,
        executor: Executor | None = None,
    ) -> None:
        if hub is not None and executor is not None and hub.executor is not executor:
            raise BusConfigError(
                "this hub delivers on another executor (or its buses' threads): give the "
                "executor to the hub (InprocHub(executor=...)) and none to the bus"
            )
        self._hub = hub if hub is not None else InprocHub(executor=executor)
        super().__init__(namespace=namespace, name=name, clock=clock)

    @property
    def executor(self) -> Executor | None:
        """The hub's executor (``None``: each subscriber and service has its thread)."""
        return self._hub.executor

    @property
    def hub(self) -> InprocHub:
        """The hub this bus is attached to (pass it to other buses to connect them)."""
        return self._hub

    def _declare_sender(self, key: str, qos: QoS) -> _InprocSender:
        return _InprocSender(self._hub, key, qos.rank)

    def _declare_receiver(self, key: str, on_data: DataCallback) -> _Link:
        return self._hub._add_receiver(key, on_data)

    def _declare_queryable(self, key: str, on_query: QueryCallback) -> _Link:
        return self._hub._add_queryable(key, on_query)

    def _query_start(
        self,
        key: str,
        payload: bytes,
        qos: QoS,
        timeout: float,
        on_reply: Callable[[bytes | None], None],
    ) -> None:
        self._hub._query_start(key, payload, on_reply)

    def _declare_token(self, key: str) -> _Link:
        return self._hub._add_token(key)

    def _query_tokens(self, key: str, timeout: float) -> set[str]:
        return self._hub._alive(key)

    def _declare_token_watch(self, key: str, on_change: TokenCallback) -> _Link:
        return self._hub._add_watch(key, on_change)

    def _close_transport(self) -> None:
        # Nothing left to do: Bus.close() closed every declared object, and with it every
        # receiver, queryable, token and watch this bus had on the hub.
        return None
