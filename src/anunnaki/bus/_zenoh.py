"""The zenoh bus (extra ``anunnaki[bus]``): the same interface over an eclipse-zenoh session.

zenoh is imported here only, when a zenoh bus is opened, so ``import anunnaki.bus`` works
without it.

Two zenoh habits shape this module:

* A Python callback given to zenoh as a plain function runs on a *non-daemon* Python thread
  that zenoh starts; an interpreter then cannot exit until the session is closed (and
  ``atexit`` runs only after non-daemon threads end). So every callback is declared with
  ``handlers.Callback(..., indirect=False)``: it runs on zenoh's own thread and only pushes
  bytes into a bounded queue; our daemon dispatcher threads do the rest.
* Queries finalise immediately when no queryable matches; :meth:`Bus.request` retries them
  until its deadline.
"""

from __future__ import annotations

import json
import socket
from collections.abc import Callable
from pathlib import Path
from typing import Any

from anunnaki.bus._api import Bus, DataCallback, QueryCallback, TokenCallback, logger
from anunnaki.bus._config import BusConfig
from anunnaki.bus._diagnose import diagnose_connect
from anunnaki.bus._errors import BusClosedError, BusConfigError, BusConnectError, BusError
from anunnaki.bus._inproc import InprocHub
from anunnaki.bus._qos import QoS
from anunnaki.errors import MissingExtraError

__all__ = ["ZenohBus", "free_port", "open_zenoh"]

# zenoh Priority as an int (REAL_TIME=1 … BACKGROUND=7) -> our rank (0 critical … 3 low).
_RANK_OF_ZPRIORITY = {1: 0, 2: 1, 3: 1, 4: 2, 5: 2, 6: 3, 7: 3}


def _import_zenoh() -> Any:
    try:
        import zenoh
    except ImportError as exc:
        raise MissingExtraError("eclipse-zenoh", "bus") from exc
    return zenoh


def free_port(host: str = "127.0.0.1") -> int:
    """Return a TCP port free on ``host`` now (bind to port 0, read it, release it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        port: int = s.getsockname()[1]
        return port


def _without_source_location(exc: Exception | None) -> str:
    """The text of a zenoh error without the Rust source location it appends (`` at /…``)."""
    return str(exc).split("  at /", 1)[0].rstrip("!. ")


class _Link:
    def __init__(self, undeclare: Callable[[], object]) -> None:
        self._undeclare: Callable[[], object] | None = undeclare

    def close(self) -> None:
        undeclare, self._undeclare = self._undeclare, None
        if undeclare is not None:
            try:
                undeclare()
            except Exception as exc:  # the session may be closed already
                logger.debug("undeclare failed: %s", exc)


class _ZSender:
    def __init__(self, z: Any, publisher: Any) -> None:
        self._z = z
        self._pub = publisher
        self._json = z.Encoding.APPLICATION_JSON
        self._binary = z.Encoding.APPLICATION_OCTET_STREAM

    def send(self, payload: bytes) -> None:
        encoding = self._json if payload[:1] == b"{" else self._binary
        try:
            self._pub.put(payload, encoding=encoding)
        except self._z.ZError as exc:
            raise BusError(f"zenoh put on {self._pub.key_expr} failed: {exc}") from exc

    def matching(self) -> bool:
        try:
            return bool(self._pub.matching_status)
        except self._z.ZError:
            return False

    def close(self) -> None:
        try:
            self._pub.undeclare()
        except Exception as exc:
            logger.debug("undeclare failed: %s", exc)


class ZenohBus(Bus):
    """A bus over an eclipse-zenoh session (see the module docstring).

    Args:
        config: The validated bus configuration (``kind`` is ignored).
        clock: The clock written into envelopes.

    Raises:
        MissingExtraError: eclipse-zenoh is not installed.
        BusConfigError: A TLS file does not exist, or zenoh refuses the configuration.
        BusConnectError: The session could not be opened (e.g. a client found no router,
            or TLS was refused).

    """

    kind = "zenoh"
    _settle_time = 0.02  # measured: losses stop ~1 ms after the match on loopback

    def __init__(self, config: BusConfig, *, clock: Callable[[], float] | None = None) -> None:
        z = _import_zenoh()
        self._z = z
        self._config = config
        if config.tls is not None:
            for field, path in config.tls.files().items():
                if not Path(path).is_file():
                    raise BusConfigError(f"tls.{field}: file not found: {path}")
        auto_port = not config.listen and config.mode == "peer"
        attempts = 3 if auto_port else 1
        last: Exception | None = None
        for _ in range(attempts):
            listen = config.effective_listen(free_port() if auto_port else None)
            try:
                self._session = z.open(self._zenoh_config(listen))
                break
            except z.ZError as exc:
                last = exc
        else:
            where = ", ".join(config.connect) or "(no connect endpoints)"
            found = diagnose_connect(config)
            if found:
                check = "; ".join(found)
            elif config.connect:
                check = (
                    "check that the router runs at that address, that its certificate "
                    "names the host connected to (subjectAltName) and that both sides' "
                    "certificates come from the CA the other trusts"
                )
            else:
                check = "check that the listen endpoints are free and valid here"
            raise BusConnectError(
                f"cannot open a zenoh {config.mode} session (listen {listen}, connect {where}): "
                f"{_without_source_location(last)}. What to check: {check}"
            ) from last
        self._endpoints = tuple(listen)
        super().__init__(namespace=config.namespace, name=config.name, clock=clock)

    def _zenoh_config(self, listen: list[str]) -> Any:
        z = self._z
        try:
            conf = z.Config.from_json5(json.dumps(self._config.to_zenoh(listen)))
            for path, value in self._config.zenoh.items():
                conf.insert_json5(path, json.dumps(value))
        except (z.ZError, ValueError, TypeError) as exc:
            raise BusConfigError(f"zenoh refused the configuration: {exc}") from exc
        return conf

    @property
    def endpoints(self) -> tuple[str, ...]:
        """The endpoints this session listens on (connect other sessions to these)."""
        return self._endpoints

    @property
    def config(self) -> BusConfig:
        """The configuration the session was opened with."""
        return self._config

    def _callback(self, fn: Callable[[Any], None]) -> Any:
        return self._z.handlers.Callback(_guarded(fn), indirect=False)

    def _declare_sender(self, key: str, qos: QoS) -> _ZSender:
        z = self._z
        priority = (
            z.Priority.REAL_TIME,
            z.Priority.INTERACTIVE_HIGH,
            z.Priority.DATA,
            z.Priority.DATA_LOW,
        )[qos.rank]
        try:
            pub = self._session.declare_publisher(
                key,
                priority=priority,
                congestion_control=(
                    z.CongestionControl.BLOCK if qos.reliable else z.CongestionControl.DROP
                ),
                reliability=z.Reliability.RELIABLE if qos.reliable else z.Reliability.BEST_EFFORT,
                express=qos.express,
            )
        except z.ZError as exc:
            raise self._error("declare a publisher", exc) from exc
        return _ZSender(z, pub)

    def _error(self, what: str, exc: Exception) -> BusError:
        if self._session.is_closed():
            return BusClosedError(f"cannot {what}: the zenoh session is closed")
        return BusError(f"cannot {what}: {exc}")

    def _declare_receiver(self, key: str, on_data: DataCallback) -> _Link:
        z = self._z
        put = z.SampleKind.PUT

        def on_sample(sample: Any) -> None:
            payload = sample.payload.to_bytes() if sample.kind == put else b""
            rank = _RANK_OF_ZPRIORITY.get(int(sample.priority), 2)
            on_data(str(sample.key_expr), payload, rank)

        try:
            sub = self._session.declare_subscriber(key, self._callback(on_sample))
        except z.ZError as exc:
            raise self._error("declare a subscriber", exc) from exc
        return _Link(sub.undeclare)

    def _declare_queryable(self, key: str, on_query: QueryCallback) -> _Link:
        z = self._z

        def on_zquery(query: Any) -> None:
            payload = query.payload.to_bytes() if query.payload is not None else b""

            def reply(data: bytes) -> None:
                try:
                    query.reply(query.key_expr, data)
                finally:
                    query.drop()

            on_query(payload, reply)

        try:
            queryable = self._session.declare_queryable(
                key, self._callback(on_zquery), complete=True
            )
        except z.ZError as exc:
            raise self._error("declare a service", exc) from exc
        return _Link(queryable.undeclare)

    def _query_start(
        self,
        key: str,
        payload: bytes,
        qos: QoS,
        timeout: float,
        on_reply: Callable[[bytes | None], None],
    ) -> None:
        z = self._z
        answered = False

        def on_answer(reply: Any) -> None:
            nonlocal answered
            ok = reply.ok
            if ok is not None and not answered:
                answered = True
                on_reply(ok.payload.to_bytes())

        def on_end() -> None:  # zenoh's last call for this query: replies are all in
            if not answered:
                on_reply(None)

        try:
            self._session.get(
                key,
                payload=payload,
                timeout=timeout,
                consolidation=z.ConsolidationMode.NONE,
                congestion_control=z.CongestionControl.BLOCK,
                priority=z.Priority.REAL_TIME if qos.rank == 0 else z.Priority.INTERACTIVE_HIGH,
                express=True,
                handler=z.handlers.Callback(_guarded(on_answer), _guarded(on_end), indirect=False),
            )
        except z.ZError as exc:
            if self._session.is_closed():
                raise BusClosedError("the zenoh session closed during a request") from exc
            logger.debug("query on %s ended: %s", key, exc)
            on_reply(None)

    def _declare_token(self, key: str) -> _Link:
        try:
            token = self._session.liveliness().declare_token(key)
        except self._z.ZError as exc:
            raise self._error("declare a liveliness token", exc) from exc
        return _Link(token.undeclare)

    def _query_tokens(self, key: str, timeout: float) -> set[str]:
        keys: set[str] = set()
        try:
            for reply in self._session.liveliness().get(key, timeout=timeout):
                if reply.ok is not None:
                    keys.add(str(reply.ok.key_expr))
        except self._z.ZError as exc:
            raise self._error("query liveliness", exc) from exc
        return keys

    def _declare_token_watch(self, key: str, on_change: TokenCallback) -> _Link:
        put = self._z.SampleKind.PUT

        def on_sample(sample: Any) -> None:
            on_change(str(sample.key_expr), sample.kind == put)

        try:
            sub = self._session.liveliness().declare_subscriber(
                key, self._callback(on_sample), history=True
            )
        except self._z.ZError as exc:
            raise self._error("watch liveliness", exc) from exc
        return _Link(sub.undeclare)

    def _close_transport(self) -> None:
        self._session.close()


def open_zenoh(
    config: BusConfig, *, clock: Callable[[], float] | None = None, hub: InprocHub | None = None
) -> Bus:
    """The ``"zenoh"`` kind: a zenoh session (eclipse-zenoh is imported when one is opened)."""
    if hub is not None:
        raise BusConfigError("hub only applies to the inproc bus")
    return ZenohBus(config, clock=clock)


def _guarded(fn: Callable[..., None]) -> Callable[..., None]:
    """``fn``, never letting an exception reach zenoh's thread."""

    def guarded(*args: Any) -> None:
        try:
            fn(*args)
        except Exception:
            logger.exception("zenoh callback failed")

    return guarded
