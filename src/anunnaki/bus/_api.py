"""The bus interface, shared by both implementations.

:class:`Bus` holds everything that does not depend on the transport: naming, encoding, QoS,
bounded queues and dispatcher threads, services, stats, logging and closing. A transport
(in-process hub or zenoh session) implements seven small hooks (``_declare_sender``,
``_declare_receiver``, ``_declare_queryable``, ``_query_start``, ``_declare_token``,
``_query_tokens``, ``_declare_token_watch``) plus ``_close_transport``. So the two buses
cannot drift apart in behaviour: one contract suite tests both.

Threads: transport callbacks only push raw bytes into a bounded queue (they never decode or
run user code), and each callback subscriber, service and liveliness watch has one daemon
dispatcher thread that decodes and calls user code. Every bus registers an ``atexit`` close,
so an interpreter never hangs on exit even if a bus was left open.
"""

from __future__ import annotations

import atexit
import functools
import logging
import math
import os
import secrets
import socket
import threading
import time
import weakref
from abc import ABC, abstractmethod
from collections import defaultdict
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import Future
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal, Protocol

from pydantic import ValidationError

from anunnaki._closing import Closing
from anunnaki.bus._codec import Envelope, decode_envelope, encode_envelope
from anunnaki.bus._errors import (
    BusClosedError,
    BusConfigError,
    BusError,
    BusTimeout,
    MalformedMessage,
    ServiceError,
)
from anunnaki.bus._executor import Executor
from anunnaki.bus._keys import (
    NODE_SEGMENT,
    lenient_name,
    node_key,
    service_key,
    validate_name,
    validate_namespace,
    validate_pattern,
)
from anunnaki.bus._qos import Priority, QoS, qos_for
from anunnaki.bus._queue import DropPolicy, PriorityQueue
from anunnaki.errors import validation_message
from anunnaki.messages import Generic, Message, MessageError, ServiceReply

__all__ = [
    "Bus",
    "BusStats",
    "LivelinessToken",
    "LivelinessWatch",
    "Publisher",
    "Sample",
    "Service",
    "Subscriber",
]

logger = logging.getLogger("anunnaki.bus")

#: Raw data from a transport: (key, payload, priority rank).
DataCallback = Callable[[str, bytes, int], None]
ReplyFn = Callable[[bytes], None]
QueryCallback = Callable[[bytes, ReplyFn], None]
TokenCallback = Callable[[str, bool], None]
MessageLike = Message | Mapping[str, Any]
Handler = Callable[[Message], "MessageLike | None"]


class _Link(Protocol):
    def close(self) -> None: ...


class _Sender(Protocol):
    def send(self, payload: bytes) -> None: ...

    def matching(self) -> bool: ...

    def close(self) -> None: ...


# --- helpers --------------------------------------------------------------------------------


def as_message(obj: object) -> Message:
    """Return a :class:`Message` as is; wrap a mapping into :class:`Generic`.

    Raises:
        MessageError: Anything else, or a mapping that is not a JSON object.

    """
    if isinstance(obj, Message):
        return obj
    if isinstance(obj, Mapping):
        try:
            return Generic(data=dict(obj))
        except ValidationError as exc:
            first = exc.errors(include_url=False)[0]
            where = ".".join(str(p) for p in first["loc"][1:]) or "data"
            raise MessageError(f"not a JSON object: {where}: {validation_message(first)}") from None
    raise MessageError(
        f"expected an anunnaki.messages.Message or a mapping, got {type(obj).__name__}"
    )


class _RateLimitedLog:
    """At most one record per key and interval; the next one says how many were suppressed."""

    def __init__(self, log: logging.Logger, interval: float = 5.0) -> None:
        self._log = log
        self._interval = interval
        self._lock = threading.Lock()
        self._state: dict[tuple[str, str], tuple[float, int]] = {}

    def warning(self, key: tuple[str, str], msg: str, *args: object, exc: bool = False) -> None:
        now = time.monotonic()
        with self._lock:
            last, suppressed = self._state.get(key, (-math.inf, 0))
            if now - last < self._interval:
                self._state[key] = (last, suppressed + 1)
                return
            self._state[key] = (now, 0)
        if suppressed:
            msg += " (%d similar messages suppressed)"
            args = (*args, suppressed)
        self._log.warning(msg, *args, exc_info=exc)


@dataclass(frozen=True)
class BusStats:
    """Counters of one bus, per topic (or service) name.

    Attributes:
        published: Messages published, by topic.
        delivered: Messages handed to a subscriber's callback or ``recv``, by topic.
        dropped: Messages evicted by a full subscriber queue, by topic.
        malformed: Undecodable or invalid messages dropped, by topic or service.
        errors: Exceptions raised by callbacks and service handlers, by topic or service.

    """

    published: dict[str, int] = field(default_factory=dict)
    delivered: dict[str, int] = field(default_factory=dict)
    dropped: dict[str, int] = field(default_factory=dict)
    malformed: dict[str, int] = field(default_factory=dict)
    errors: dict[str, int] = field(default_factory=dict)

    def totals(self) -> dict[str, int]:
        """Return the sum of each counter over all topics."""
        return {
            name: sum(getattr(self, name).values())
            for name in ("published", "delivered", "dropped", "malformed", "errors")
        }


_COUNTERS = Literal["published", "delivered", "dropped", "malformed", "errors"]


class _Stats:
    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._c: dict[str, defaultdict[str, int]] = {
            n: defaultdict(int)
            for n in ("published", "delivered", "dropped", "malformed", "errors")
        }

    def count(self, counter: _COUNTERS, topic: str, n: int = 1) -> None:
        with self._lock:
            self._c[counter][topic] += n

    def snapshot(self) -> BusStats:
        with self._lock:
            return BusStats(**{k: dict(v) for k, v in self._c.items()})


@dataclass(frozen=True, slots=True)
class Sample:
    """One message as a subscriber receives it.

    Attributes:
        topic: The ROS-style topic it was published on (useful with patterns).
        message: The decoded, validated message.
        sent_at: The sender's clock at publication, in seconds.
        seq: The sender's counter for this topic.
        sender: The sending bus's name.
        key: The bus key it travelled on.

    """

    topic: str
    message: Message
    sent_at: float
    seq: int
    sender: str
    key: str


def _default_name() -> str:
    return f"{socket.gethostname()}-{os.getpid()}-{secrets.token_hex(2)}"


def _close_ref(ref: weakref.ReferenceType[Bus]) -> None:
    bus = ref()
    if bus is not None:
        bus.close()


# --- declared objects -----------------------------------------------------------------------


class _Declared(Closing):
    """A context manager with an idempotent :meth:`close`."""

    _closed: bool

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called (or the bus closed)."""
        return self._closed

    def close(self) -> None:  # pragma: no cover - overridden
        """Undeclare the object; calling it again does nothing."""
        raise NotImplementedError


def _join(thread: threading.Thread | None, what: str) -> None:
    if thread is None or thread is threading.current_thread():
        return
    thread.join(timeout=2.0)
    if thread.is_alive():
        logger.warning("%s: its callback is still running after close; left behind", what)


class Publisher(_Declared):
    """Publishes messages on one topic (declared by :meth:`Bus.publisher`).

    The QoS comes from the QoS table (topic class and message type) unless the publisher
    overrides priority or reliability.
    """

    def __init__(
        self,
        bus: Bus,
        topic: str,
        *,
        priority: Priority | None = None,
        reliable: bool | None = None,
    ) -> None:
        self._bus = bus
        self.topic = validate_name(topic, "topic")
        self.key = bus.namespace + self.topic
        self._priority = priority
        self._reliable = reliable
        self.qos = qos_for(self.topic, priority=priority, reliable=reliable)
        self._qos_by_type: dict[str, QoS] = {}
        self._seq = 0
        self._lock = threading.Lock()
        self._closed = False
        # Declared now so that the network learns of the publisher (and matching works).
        self._senders: dict[QoS, _Sender] = {self.qos: bus._declare_sender(self.key, self.qos)}

    def qos_for(self, message: Message) -> QoS:
        """Return the QoS a message of this type gets on this publisher."""
        name = message.type_name()
        qos = self._qos_by_type.get(name)
        if qos is None:
            qos = qos_for(self.topic, name, priority=self._priority, reliable=self._reliable)
            self._qos_by_type[name] = qos
        return qos

    def has_subscribers(self) -> bool:
        """Tell whether a subscriber anywhere on the bus matches this topic now."""
        with self._lock:
            sender = self._senders.get(self.qos)
        return sender is not None and sender.matching()

    def wait_for_subscribers(self, timeout: float = 2.0) -> bool:
        """Wait until a subscriber matches this topic (declarations travel asynchronously).

        On zenoh, a publisher learns of a new subscriber slightly before its data route is
        in place (zenoh issue #495): messages put within about a millisecond of the match
        can be lost. So after the match this waits the transport's settle time (20 ms on
        zenoh, none in-process) before returning.

        Returns:
            Whether one matched within ``timeout`` seconds.

        """
        deadline = time.monotonic() + timeout
        while not self.has_subscribers():
            remaining = deadline - time.monotonic()
            if remaining <= 0 or self._closed:
                return False
            self._bus._closed.wait(min(0.005, remaining))
        if self._bus._settle_time > 0:
            self._bus._closed.wait(self._bus._settle_time)
        return True

    def put(self, message: MessageLike) -> None:
        """Publish one message (a :class:`Message`, or a mapping sent as :class:`Generic`).

        Raises:
            MessageError: Not a message, or not serialisable.
            BusClosedError: The publisher or its bus is closed.

        """
        msg = as_message(message)
        qos = self.qos_for(msg)
        with self._lock:
            if self._closed:
                raise BusClosedError(f"publisher of {self.topic} is closed")
            seq = self._seq
            self._seq += 1
            sender = self._senders.get(qos)
            if sender is None:
                sender = self._bus._declare_sender(self.key, qos)
                self._senders[qos] = sender
        payload = encode_envelope(Envelope(msg, self._bus._now(), seq, self._bus.name))
        sender.send(payload)
        self._bus._stats.count("published", self.topic)

    def put_raw(self, payload: bytes) -> None:
        """Publish bytes that are already in the wire format (bridges, trace replay).

        Nothing is checked here; receivers validate as always (and drop and count what is
        malformed). The publisher's topic QoS applies.

        Raises:
            BusClosedError: The publisher or its bus is closed.

        """
        if not isinstance(payload, bytes | bytearray | memoryview):
            raise MessageError(f"put_raw takes bytes, got {type(payload).__name__}")
        with self._lock:
            if self._closed:
                raise BusClosedError(f"publisher of {self.topic} is closed")
            sender = self._senders[self.qos]
        sender.send(bytes(payload))
        self._bus._stats.count("published", self.topic)

    def close(self) -> None:
        """Undeclare the publisher."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            senders = list(self._senders.values())
            self._senders.clear()
        for s in senders:
            s.close()
        self._bus._forget(self)


class Subscriber(_Declared):
    """Receives the messages of a topic or pattern (declared by :meth:`Bus.subscribe`).

    Messages wait in a bounded queue (``queue`` items, most urgent first, see
    :mod:`anunnaki.bus._queue`). With a callback, one dispatcher thread calls it for each
    message; without one, pull with :meth:`recv`, :meth:`try_recv` or iteration.
    """

    def __init__(
        self,
        bus: Bus,
        pattern: str,
        callback: Callable[[Sample], object] | None = None,
        *,
        queue: int = 16,
        drop: DropPolicy = "oldest",
        expect: type[Message] | tuple[type[Message], ...] | None = None,
        on_ready: Callable[[], object] | None = None,
    ) -> None:
        if callback is not None and not callable(callback):
            raise BusConfigError(f"callback must be callable, got {type(callback).__name__}")
        if not isinstance(queue, int) or isinstance(queue, bool) or queue < 1:
            raise BusConfigError(f"queue must be an integer >= 1, got {queue!r}")
        if drop not in ("oldest", "newest"):
            raise BusConfigError(f"drop must be 'oldest' or 'newest', got {drop!r}")
        if expect is not None:
            types = expect if isinstance(expect, tuple) else (expect,)
            if not types or not all(isinstance(t, type) and issubclass(t, Message) for t in types):
                raise BusConfigError(f"expect must be Message types, got {expect!r}")
        self._bus = bus
        self.pattern = validate_pattern(pattern, "topic")
        self.key = bus.namespace + self.pattern
        self._callback = callback
        self._on_ready = on_ready
        self._expect = expect
        self._queue: PriorityQueue[tuple[str, bytes]] = PriorityQueue(queue, drop)
        self._closed = False
        self._lock = threading.Lock()
        self.dropped = 0
        self._thread: threading.Thread | None = None
        self._executor = bus.executor
        self._link = bus._declare_receiver(self.key, self._on_data)
        if callback is not None and self._executor is None:
            self._thread = threading.Thread(
                target=self._dispatch, name=f"anunnaki-bus-sub:{self.pattern}", daemon=True
            )
            self._thread.start()

    @property
    def pending(self) -> int:
        """Messages waiting in the queue now."""
        return len(self._queue)

    @property
    def high_water(self) -> int:
        """The largest queue length seen (never above the bound)."""
        return self._queue.high_water

    @property
    def bound(self) -> int:
        """The queue bound."""
        return self._queue.maxlen

    def _on_data(self, key: str, payload: bytes, rank: int) -> None:
        victim = self._queue.push((key, payload), rank)
        if self._executor is not None:  # one thread of delivery: the executor's, in order
            if self._callback is not None:
                self._executor.post(self._deliver_one)
            elif self._on_ready is not None:
                self._executor.post(self._ring)
        elif self._on_ready is not None:
            self._ring()
        if victim is not None and not self._queue.closed:
            topic = lenient_name(victim[0], self._bus._prefix)
            with self._lock:
                self.dropped += 1
            self._bus._stats.count("dropped", topic)
            self._bus._log.warning(
                ("dropped", self.pattern),
                "subscriber %s: queue of %d full, dropped a message of %s",
                self.pattern,
                self._queue.maxlen,
                topic,
            )

    def _ring(self) -> None:
        assert self._on_ready is not None
        try:
            self._on_ready()
        except Exception:  # a doorbell must never break delivery
            self._bus._stats.count("errors", self.pattern)

    def _next(self, timeout: float | None) -> Sample | None:
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            item = self._queue.pop(remaining)
            if item is None:
                return None
            key, payload = item
            topic = lenient_name(key, self._bus._prefix)
            try:
                env = decode_envelope(payload)
                if self._expect is not None and not isinstance(env.message, self._expect):
                    raise MalformedMessage(f"expected {_type_names(self._expect)}, got {env.type}")
            except MalformedMessage as exc:
                self._bus._malformed(topic, str(exc))
                continue
            self._bus._stats.count("delivered", topic)
            return Sample(topic, env.message, env.t, env.seq, env.sender, key)

    def _dispatch(self) -> None:
        while True:
            sample = self._next(None)
            if sample is None:
                return
            self._call(sample)

    def _deliver_one(self) -> None:
        """The executor's work item: the next queued message to the callback, if any is left."""
        if not self._closed and (sample := self._next(0.0)) is not None:
            self._call(sample)

    def _call(self, sample: Sample) -> None:
        callback = self._callback
        assert callback is not None
        try:
            callback(sample)
        except Exception:
            self._bus._stats.count("errors", sample.topic)
            self._bus._log.warning(
                ("callback", self.pattern),
                "subscriber %s: callback raised on a message of %s",
                self.pattern,
                sample.topic,
                exc=True,
            )

    def _pull_check(self) -> None:
        if self._callback is not None:
            raise BusError(
                f"subscriber {self.pattern} delivers to its callback; "
                "recv() is for subscribers declared without one"
            )

    def recv(self, timeout: float | None = None) -> Sample:
        """Return the next message, waiting up to ``timeout`` seconds (``None``: forever).

        Raises:
            BusTimeout: Nothing arrived in time.
            BusClosedError: The subscriber is closed.

        """
        self._pull_check()
        sample = self._next(timeout)
        if sample is None:
            if self._queue.closed:
                raise BusClosedError(f"subscriber {self.pattern} is closed")
            raise BusTimeout(f"no message on {self.pattern} within {timeout} s")
        return sample

    def try_recv(self) -> Sample | None:
        """Return the next message if one is waiting, else ``None``."""
        self._pull_check()
        return self._next(0.0)

    def __iter__(self) -> Iterator[Sample]:
        """Yield messages until the subscriber is closed."""
        self._pull_check()
        while True:
            sample = self._next(None)
            if sample is None:
                return
            yield sample

    def close(self) -> None:
        """Undeclare the subscriber; queued messages are discarded."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._link.close()
        self._queue.close()
        _join(self._thread, f"subscriber {self.pattern}")
        self._bus._forget(self)


def _type_names(expect: type[Message] | tuple[type[Message], ...]) -> str:
    types = expect if isinstance(expect, tuple) else (expect,)
    return " or ".join(t.type_name() for t in types)


class Service(_Declared):
    """Answers requests on one service name (declared by :meth:`Bus.service`).

    The handler runs on the service's own thread, one request at a time. Its return value
    (a :class:`Message`, a mapping sent as :class:`Generic`, or ``None`` for
    ``ServiceReply(ok=True)``) is the reply; an exception becomes an error reply
    (``ServiceReply(ok=False, error=...)``), logged and counted, and the service goes on.
    Requests beyond ``queue`` waiting ones are refused with an error reply at once.
    """

    def __init__(self, bus: Bus, name: str, handler: Handler, *, queue: int = 16) -> None:
        if not callable(handler):
            raise BusConfigError(f"handler must be callable, got {type(handler).__name__}")
        if not isinstance(queue, int) or isinstance(queue, bool) or queue < 1:
            raise BusConfigError(f"queue must be an integer >= 1, got {queue!r}")
        self._bus = bus
        self.name = validate_name(name, "service")
        self.key = service_key(self.name, bus.namespace)
        self._handler = handler
        self._queue: PriorityQueue[tuple[bytes, ReplyFn]] = PriorityQueue(queue, "newest")
        self._seq = 0
        self._closed = False
        self._lock = threading.Lock()
        self._executor = bus.executor
        self._thread: threading.Thread | None = None
        self._link = bus._declare_queryable(self.key, self._on_query)
        if self._executor is None:
            self._thread = threading.Thread(
                target=self._serve, name=f"anunnaki-bus-srv:{self.name}", daemon=True
            )
            self._thread.start()

    @property
    def pending(self) -> int:
        """Requests waiting for the handler now."""
        return len(self._queue)

    def _error_reply(self, error: str) -> bytes:
        with self._lock:
            seq = self._seq
            self._seq += 1
        reply = ServiceReply(ok=False, error=error)
        return encode_envelope(Envelope(reply, self._bus._now(), seq, self._bus.name))

    def _on_query(self, payload: bytes, reply: ReplyFn) -> None:
        executor = self._executor
        if executor is not None:  # answered in the same drain (see anunnaki.bus._executor)
            if self._closed:
                _safe_reply(reply, self._error_reply("service closed"), self.name)
            elif executor.on_thread:  # a direct call, nested in the requester's
                _safe_reply(reply, self._answer(payload), self.name)
            else:  # another thread asks: the executor's next drain answers
                executor.post(lambda: _safe_reply(reply, self._answer(payload), self.name))
            return
        refused = self._queue.push((payload, reply), 0)
        if refused is not None:
            busy = "service closed" if self._queue.closed else "service busy: request refused"
            _safe_reply(refused[1], self._error_reply(busy), self.name)

    def _serve(self) -> None:
        while True:
            item = self._queue.pop(None)
            if item is None:
                return
            payload, reply = item
            _safe_reply(reply, self._answer(payload), self.name)

    def _answer(self, payload: bytes) -> bytes:
        try:
            request = decode_envelope(payload)
        except MalformedMessage as exc:
            self._bus._malformed(self.name, str(exc))
            return self._error_reply(f"malformed request: {exc}")
        try:
            result = self._handler(request.message)
            message = ServiceReply(ok=True) if result is None else as_message(result)
            with self._lock:
                seq = self._seq
                self._seq += 1
            return encode_envelope(Envelope(message, self._bus._now(), seq, self._bus.name))
        except Exception as exc:
            self._bus._stats.count("errors", self.name)
            self._bus._log.warning(
                ("handler", self.name), "service %s: handler raised", self.name, exc=True
            )
            return self._error_reply(f"{type(exc).__name__}: {exc}")

    def close(self) -> None:
        """Undeclare the service; waiting requests get a "service closed" error reply."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._link.close()
        for _payload, reply in self._queue.close():
            _safe_reply(reply, self._error_reply("service closed"), self.name)
        _join(self._thread, f"service {self.name}")
        self._bus._forget(self)


def _no_reply(service: str, timeout: float, deadline: float) -> BusTimeout:
    """A request given up: the service is not up, or (past ``deadline``) it did not answer."""
    if time.monotonic() >= deadline:  # it is up, and did not answer in time
        return BusTimeout(f"no reply from service {service!r} within {timeout} s")
    return BusTimeout(f"no reply from service {service!r}: it is not up")


def _safe_reply(reply: ReplyFn, data: bytes, name: str) -> None:
    try:
        reply(data)
    except Exception as exc:  # the requester or the session is gone
        logger.debug("service %s: reply not sent: %s", name, exc)


class LivelinessToken(_Declared):
    """Declares that a node is alive while held (declared by :meth:`Bus.liveliness_token`).

    Others see the node vanish when the token is closed, the bus closes, or the process dies
    (zenoh notices a killed process through its dropped connection).
    """

    def __init__(self, bus: Bus, node: str) -> None:
        self._bus = bus
        self.node = validate_name(node, "node")
        self.key = node_key(self.node, bus.namespace)
        self._closed = False
        self._lock = threading.Lock()
        self._link = bus._declare_token(self.key)

    def close(self) -> None:
        """Withdraw the token."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._link.close()
        self._bus._forget(self)


class LivelinessWatch(_Declared):
    """Calls ``callback(node, alive)`` when a node appears or vanishes.

    Declared by :meth:`Bus.watch_liveliness`. Nodes alive at declaration are reported first
    (``alive=True``). The callback runs on the watch's own thread.
    """

    def __init__(self, bus: Bus, callback: Callable[[str, bool], object]) -> None:
        if not callable(callback):
            raise BusConfigError(f"callback must be callable, got {type(callback).__name__}")
        self._bus = bus
        self._callback = callback
        self._prefix = f"{bus.namespace}/{NODE_SEGMENT}"
        self._events: PriorityQueue[tuple[str, bool]] = PriorityQueue(65536, "newest")
        self._closed = False
        self._lock = threading.Lock()
        self._executor = bus.executor
        self._thread: threading.Thread | None = None
        if self._executor is None:
            self._thread = threading.Thread(
                target=self._dispatch, name="anunnaki-bus-liveliness", daemon=True
            )
            self._thread.start()
        try:
            self._link = bus._declare_token_watch(self._prefix + "/**", self._on_change)
        except BaseException:
            self._events.close()  # let the thread end
            raise

    def _on_change(self, key: str, alive: bool) -> None:
        self._events.push((lenient_name(key, self._prefix + "/"), alive), 0)
        if self._executor is not None:
            self._executor.post(self._deliver_one)

    def _dispatch(self) -> None:
        while True:
            item = self._events.pop(None)
            if item is None:
                return
            self._call(item)

    def _deliver_one(self) -> None:
        if not self._closed and (item := self._events.pop(0.0)) is not None:
            self._call(item)

    def _call(self, item: tuple[str, bool]) -> None:
        try:
            self._callback(*item)
        except Exception:
            self._bus._stats.count("errors", "<liveliness>")
            self._bus._log.warning(
                ("callback", "<liveliness>"), "liveliness callback raised", exc=True
            )

    def close(self) -> None:
        """Stop watching."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._link.close()
        self._events.close()
        _join(self._thread, "liveliness watch")
        self._bus._forget(self)


# --- the bus --------------------------------------------------------------------------------


class Bus(ABC, Closing):
    """A session on the message bus: declare everything else from it.

    Open one with :func:`anunnaki.bus.open_bus`; use it as a context manager or call
    :meth:`close`. All methods are thread-safe.

    Args:
        namespace: Key prefix of this system (default ``anunnaki``).
        name: This bus's name in envelopes (``sender``); default host-pid-random.
        clock: Returns the time written into envelopes, in seconds (default ``time.time``;
            pass the simulation clock in simulations).

    """

    kind: ClassVar[str]
    #: Seconds between "a subscriber matches" and "its data route is in place".
    _settle_time: ClassVar[float] = 0.0

    def __init__(
        self,
        *,
        namespace: str,
        name: str | None = None,
        clock: Callable[[], float] | None = None,
    ) -> None:
        self._namespace = validate_namespace(namespace)
        self._prefix = self._namespace + "/"
        self._name = name or _default_name()
        self._clock = clock or time.time
        self._lock = threading.Lock()
        self._objects: dict[int, _Declared] = {}
        self._shortcuts: dict[str, Publisher] = {}
        self._request_seq = 0
        self._stats = _Stats()
        self._log = _RateLimitedLog(logger)
        self._closed = threading.Event()
        self._atexit_hook = functools.partial(_close_ref, weakref.ref(self))
        atexit.register(self._atexit_hook)

    # -- properties

    @property
    def executor(self) -> Executor | None:
        """The executor that delivers this bus's messages (``None``: its own threads).

        Only the in-process bus can have one (:mod:`anunnaki.bus._executor`).
        """
        return None

    @property
    def namespace(self) -> str:
        """The key prefix of this system."""
        return self._namespace

    @property
    def name(self) -> str:
        """Name of the bus (``sender`` in envelopes)."""
        return self._name

    @property
    def closed(self) -> bool:
        """Whether the bus is closed."""
        return self._closed.is_set()

    @property
    def endpoints(self) -> tuple[str, ...]:
        """Endpoints others can connect to (empty for the in-process bus)."""
        return ()

    def __repr__(self) -> str:
        state = "closed" if self.closed else "open"
        return f"<{type(self).__name__} {self._name!r} namespace={self._namespace!r} {state}>"

    # -- internals shared with the declared objects

    def _now(self) -> float:
        return float(self._clock())

    def _check_open(self) -> None:
        if self._closed.is_set():
            raise BusClosedError(f"bus {self._name!r} is closed")

    def _adopt(self, obj: _Declared) -> None:
        with self._lock:
            if self._closed.is_set():
                adopted = False
            else:
                self._objects[id(obj)] = obj
                adopted = True
        if not adopted:
            obj.close()
            self._check_open()

    def _forget(self, obj: _Declared) -> None:
        with self._lock:
            self._objects.pop(id(obj), None)

    def _malformed(self, topic: str, reason: str) -> None:
        self._stats.count("malformed", topic)
        self._log.warning(
            ("malformed", topic), "dropped a malformed message on %s: %s", topic, reason
        )

    # -- the interface

    def publisher(
        self, topic: str, *, priority: Priority | None = None, reliable: bool | None = None
    ) -> Publisher:
        """Declare a publisher on ``topic``.

        Args:
            topic: ROS-style name, e.g. ``/utu/oracle/output``.
            priority: ``"critical"``, ``"high"``, ``"normal"`` or ``"low"``; default from
                the QoS table (topic class and message type).
            reliable: Reliable (publisher blocks on congestion) or best effort (drops);
                default from the QoS table.

        """
        self._check_open()
        pub = Publisher(self, topic, priority=priority, reliable=reliable)
        self._adopt(pub)
        return pub

    def publish(self, topic: str, message: MessageLike) -> None:
        """Publish one message on ``topic`` (through a cached default publisher)."""
        self._check_open()
        name = validate_name(topic, "topic")
        with self._lock:
            pub = self._shortcuts.get(name)
        if pub is None or pub.closed:
            fresh = self.publisher(name)
            with self._lock:
                pub = self._shortcuts.get(name)
                if pub is None or pub.closed:
                    self._shortcuts[name] = pub = fresh
            if pub is not fresh:  # another thread cached one first
                fresh.close()
        pub.put(message)

    def subscribe(
        self,
        pattern: str,
        callback: Callable[[Sample], object] | None = None,
        *,
        queue: int = 16,
        drop: DropPolicy = "oldest",
        expect: type[Message] | tuple[type[Message], ...] | None = None,
        on_ready: Callable[[], object] | None = None,
    ) -> Subscriber:
        """Declare a subscriber on a topic or pattern (``*`` one segment, ``**`` many).

        Args:
            pattern: e.g. ``/rover/mode``, ``/utu/oracle/**``, ``/*/camera/**``.
            callback: Called with each :class:`Sample` on the subscriber's thread; without
                one, pull with ``recv``/``try_recv``/iteration.
            queue: Bound of the subscriber's queue (messages waiting for the callback).
            drop: What a full queue drops: ``"oldest"`` (latest-value) or ``"newest"``.
            expect: Message type(s) accepted; others are counted as malformed.
            on_ready: For pull subscribers: called (on the transport's thread) each time a
                message is queued, e.g. ``event.set`` to wake a loop that drains several
                subscribers. On zenoh it must return at once and never block. On the
                in-process bus it runs in the publisher's thread, which may do work there
                (Utu reacts to a violation in it, with no thread hop) but must never wait
                for a reply that needs that thread.

        """
        self._check_open()
        sub = Subscriber(
            self, pattern, callback, queue=queue, drop=drop, expect=expect, on_ready=on_ready
        )
        self._adopt(sub)
        return sub

    def service(self, name: str, handler: Handler, *, queue: int = 16) -> Service:
        """Declare a service answering requests to ``name`` with ``handler(request) -> reply``."""
        self._check_open()
        srv = Service(self, name, handler, queue=queue)
        self._adopt(srv)
        return srv

    def request(
        self,
        name: str,
        payload: MessageLike,
        timeout: float = 2.0,
        *,
        wait_for_service: bool = True,
    ) -> Message:
        """Call a service and wait for its reply.

        If no service answers yet, the request is retried until the deadline, so a client
        started before its service still gets through. With ``wait_for_service=False`` it
        is tried once: a service that is not up fails the call at once (``BusTimeout``),
        what an action of Utu wants (a dead service must not hold the loop to the deadline).

        Returns:
            The reply message.

        Raises:
            BusTimeout: No reply within ``timeout`` seconds.
            ServiceError: The service answered with an error (or a malformed reply).
            BusClosedError: The bus closed meanwhile.

        """
        service, key, data, qos = self._request_envelope(name, payload, timeout)
        deadline = time.monotonic() + timeout
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise BusTimeout(f"no reply from service {service!r} within {timeout} s")
            raw = self._query(key, data, qos, remaining)
            if raw is not None:
                break
            if not wait_for_service:
                raise _no_reply(service, timeout, deadline)
            if self._closed.wait(min(0.02, max(remaining, 0.0))):
                raise BusClosedError(f"bus {self._name!r} closed during a request")
        return self._reply_of(service, raw)

    def request_start(
        self, name: str, payload: MessageLike, timeout: float = 2.0
    ) -> Future[Message]:
        """Send a request and return at once; the returned future gets the reply.

        :meth:`request` with ``wait_for_service=False``, without holding the caller (as
        rclpy's ``call_async``): no thread waits for the reply, the transport's own delivery
        completes the future. It ends with the reply message, or with the error
        :meth:`request` would raise: :class:`ServiceError` (an error or malformed reply),
        :class:`BusTimeout` (no service up; over zenoh also no reply within ``timeout``).
        A service on the in-process bus that never answers leaves the future pending:
        bound the wait with ``future.result(timeout)`` (Utu's action runner gives such a
        request up at its timeout).

        Raises:
            BusClosedError: The bus is closed (at once, not through the future).

        """
        service, key, data, qos = self._request_envelope(name, payload, timeout)
        future: Future[Message] = Future()
        deadline = time.monotonic() + timeout

        def on_reply(raw: bytes | None) -> None:
            if future.done():
                return
            try:
                if raw is None:
                    raise _no_reply(service, timeout, deadline)
                future.set_result(self._reply_of(service, raw))
            except BusError as exc:
                future.set_exception(exc)

        self._query_start(key, data, qos, timeout, on_reply)
        return future

    def _request_envelope(
        self, name: str, payload: MessageLike, timeout: float
    ) -> tuple[str, str, bytes, QoS]:
        """A request's service name, key, encoded envelope and QoS (checked)."""
        self._check_open()
        if not timeout > 0:
            raise BusConfigError(f"timeout must be > 0 seconds, got {timeout!r}")
        service = validate_name(name, "service")
        key = service_key(service, self._namespace)
        message = as_message(payload)
        qos = qos_for(service, message.type_name())
        with self._lock:
            seq = self._request_seq
            self._request_seq += 1
        return service, key, encode_envelope(Envelope(message, self._now(), seq, self._name)), qos

    def _reply_of(self, service: str, raw: bytes) -> Message:
        """The reply message in ``raw``; an error or malformed reply raises ServiceError."""
        try:
            reply = decode_envelope(raw).message
        except MalformedMessage as exc:
            self._malformed(service, str(exc))
            raise ServiceError(service, f"malformed reply: {exc}") from None
        if isinstance(reply, ServiceReply) and not reply.ok:
            raise ServiceError(service, reply.error or "unknown error")
        return reply

    def liveliness_token(self, node: str) -> LivelinessToken:
        """Declare ``node`` alive until the token is closed (or this process dies)."""
        self._check_open()
        token = LivelinessToken(self, node)
        self._adopt(token)
        return token

    def alive_nodes(self, timeout: float = 1.0) -> set[str]:
        """Return the nodes alive now (holding a token anywhere on the bus, this one included)."""
        self._check_open()
        prefix = f"{self._namespace}/{NODE_SEGMENT}"
        keys = self._query_tokens(prefix + "/**", timeout)
        return {lenient_name(k, prefix + "/") for k in keys}

    def watch_liveliness(self, callback: Callable[[str, bool], object]) -> LivelinessWatch:
        """Call ``callback(node, alive)`` on every node that appears or vanishes."""
        self._check_open()
        watch = LivelinessWatch(self, callback)
        self._adopt(watch)
        return watch

    def stats(self) -> BusStats:
        """Return a snapshot of the counters (published, delivered, dropped, malformed, errors)."""
        return self._stats.snapshot()

    def close(self) -> None:
        """Close every declared object, then the session. Idempotent."""
        with self._lock:
            if self._closed.is_set():
                return
            self._closed.set()
            objects = list(self._objects.values())
            self._objects.clear()
            self._shortcuts.clear()
        for obj in objects:
            try:
                obj.close()
            except Exception:
                logger.exception("closing %r failed", obj)
        try:
            self._close_transport()
        except Exception:
            logger.exception("closing the %s transport failed", self.kind)
        atexit.unregister(self._atexit_hook)

    # -- transport hooks

    @abstractmethod
    def _declare_sender(self, key: str, qos: QoS) -> _Sender:
        """Declare a sender of payloads on ``key`` with ``qos``."""

    @abstractmethod
    def _declare_receiver(self, key: str, on_data: DataCallback) -> _Link:
        """Call ``on_data(key, payload, rank)`` for data on keys matching ``key``; cheaply."""

    @abstractmethod
    def _declare_queryable(self, key: str, on_query: QueryCallback) -> _Link:
        """Call ``on_query(payload, reply)`` for each query on ``key``; cheaply."""

    @abstractmethod
    def _query_start(
        self,
        key: str,
        payload: bytes,
        qos: QoS,
        timeout: float,
        on_reply: Callable[[bytes | None], None],
    ) -> None:
        """Query ``key`` once without waiting; ``on_reply`` gets the first reply's payload.

        Or ``None`` if none can come: nothing answers ``key`` (over zenoh also the timeout).
        """

    def _query(self, key: str, payload: bytes, qos: QoS, timeout: float) -> bytes | None:
        """Query ``key`` once and wait: the first reply's payload, or ``None`` if none came."""
        replied = threading.Event()
        box: list[bytes | None] = []

        def on_reply(raw: bytes | None) -> None:
            box.append(raw)
            replied.set()

        self._query_start(key, payload, qos, timeout, on_reply)
        return box[0] if replied.wait(timeout) else None

    @abstractmethod
    def _declare_token(self, key: str) -> _Link:
        """Declare a liveliness token on ``key``."""

    @abstractmethod
    def _query_tokens(self, key: str, timeout: float) -> set[str]:
        """Keys of the liveliness tokens alive under ``key``."""

    @abstractmethod
    def _declare_token_watch(self, key: str, on_change: TokenCallback) -> _Link:
        """Call ``on_change(key, alive)`` for tokens under ``key``, current ones first."""

    @abstractmethod
    def _close_transport(self) -> None:
        """Close the session."""
