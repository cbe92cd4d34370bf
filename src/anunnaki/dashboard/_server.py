"""Serving the dashboard: uvicorn in a background thread, next to Utu or on its own.

:class:`Dashboard` is what the command line uses: state, bus observer and web server in one
object with ``start()`` and ``close()``. :class:`DashboardServer` runs any ASGI application
on a socket bound *before* the server starts, so a port in use is a clear error at once
(not a log line from another thread), port 0 picks a free port, and :attr:`url` is known as
soon as ``start()`` returns.
"""

from __future__ import annotations

import errno
import ipaddress
import logging
import socket
import threading
import time
from typing import Any, Literal

from anunnaki._closing import Closing
from anunnaki.bus import Bus
from anunnaki.dashboard._app_types import Operator
from anunnaki.dashboard._observer import BusObserver, ObserverConfig, OperatorError, SimTime
from anunnaki.dashboard._state import DashboardState
from anunnaki.errors import AnunnakiError, MissingExtraError
from anunnaki.goals import GoalModel
from anunnaki.tactics import TacticSet
from anunnaki.tokens import token_weakness

__all__ = [
    "Dashboard",
    "DashboardError",
    "DashboardServer",
    "create_app",
    "is_loopback",
    "loopback_names",
]

log = logging.getLogger("anunnaki.dashboard")

DEFAULT_PORT = 8765


class DashboardError(AnunnakiError):
    """The dashboard cannot start (port in use, bad address, server failure)."""


def _require() -> None:
    for module, name in (("fastapi", "fastapi"), ("uvicorn", "uvicorn")):
        try:
            __import__(module)
        except ImportError as exc:
            raise MissingExtraError(name, "dashboard") from exc


def create_app(state: DashboardState, operator: Operator | None = None, **kwargs: Any) -> Any:
    """Build the FastAPI application (see :func:`anunnaki.dashboard._app.create_app`).

    Raises:
        MissingExtraError: fastapi or uvicorn is not installed (``anunnaki[dashboard]``).

    """
    _require()
    from anunnaki.dashboard._app import create_app as build

    return build(state, operator, **kwargs)


def is_loopback(host: str) -> bool:
    """Whether ``host`` (an address or ``localhost``) is reachable from this machine only."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def loopback_names(host: str) -> list[str]:
    """The ``Host`` names a server bound to loopback ``host`` answers to (DNS rebinding)."""
    bound = host.strip("[]").lower()
    names = {"127.0.0.1", "localhost", "[::1]"}
    names.add(f"[{bound}]" if ":" in bound else bound)
    return sorted(names)


def _bind(host: str, port: int) -> socket.socket:
    try:
        family = socket.AF_INET6 if ipaddress.ip_address(host).version == 6 else socket.AF_INET
    except ValueError:
        family = socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((host, port))
        sock.listen(128)
    except OSError as exc:
        sock.close()
        if exc.errno == errno.EADDRINUSE:
            raise DashboardError(
                f"port {port} on {host} is in use; give another (anunnaki dashboard --port N, "
                "anunnaki run --dashboard-port N; 0 for any free port)"
            ) from None
        raise DashboardError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
    sock.setblocking(False)
    return sock


class DashboardServer:
    """Runs an ASGI app with uvicorn in a daemon thread.

    Bound to a loopback address, it answers only requests whose ``Host`` header names
    loopback (``127.0.0.1``, ``localhost``, ``::1`` or the bound address): others get 400,
    which defeats DNS rebinding. Bound elsewhere, it accepts any ``Host`` (the command
    line warns about such an address).

    Args:
        app: The application.
        host: Address to bind (default loopback only).
        port: TCP port; 0 for any free one.
        stopping: Set when the server stops (ends the event streams).

    """

    def __init__(
        self,
        app: Any,
        *,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        stopping: threading.Event | None = None,
    ) -> None:
        _require()
        self.app = app
        self.host = host
        self.stopping = stopping or threading.Event()
        self._sock = _bind(host, port)
        self.port: int = self._sock.getsockname()[1]
        self.loopback = is_loopback(host)
        self._server: Any = None
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None

    @property
    def url(self) -> str:
        """The page's address."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        if self.host in ("0.0.0.0", "::"):
            host = socket.gethostname()
        return f"http://{host}:{self.port}/"

    def start(self, timeout: float = 15.0) -> None:
        """Start serving; returns once the server accepts connections.

        Raises:
            DashboardError: The server did not come up within ``timeout`` seconds.

        """
        import uvicorn

        app = self.app
        if self.loopback:
            from starlette.middleware.trustedhost import TrustedHostMiddleware

            app = TrustedHostMiddleware(
                app, allowed_hosts=loopback_names(self.host), www_redirect=False
            )
        config = uvicorn.Config(
            app,
            log_level="warning",
            lifespan="off",
            access_log=False,
            timeout_graceful_shutdown=2,
            timeout_keep_alive=5,
        )
        self._server = uvicorn.Server(config)
        server = self._server

        def serve() -> None:
            try:
                server.run(sockets=[self._sock])
            except BaseException as exc:  # reported by start()/the log, never swallowed
                self._error = exc
                log.exception("dashboard server failed")

        self._thread = threading.Thread(target=serve, name="anunnaki-dashboard", daemon=True)
        self._thread.start()
        deadline = time.monotonic() + timeout
        while not server.started:
            if self._error is not None or not self._thread.is_alive():
                raise DashboardError(f"the dashboard server failed to start: {self._error!r}")
            if time.monotonic() > deadline:
                self.stop()
                raise DashboardError(f"the dashboard server did not start within {timeout} s")
            time.sleep(0.01)

    def stop(self, timeout: float = 5.0) -> None:
        """Stop serving (open event streams end first). Idempotent."""
        self.stopping.set()
        if self._server is not None:
            self._server.should_exit = True
        if self._thread is not None:
            self._thread.join(timeout)
            if self._thread.is_alive() and self._server is not None:
                self._server.force_exit = True
                self._thread.join(timeout)
        self._sock.close()


class Dashboard(Closing):
    """State, bus observer and web server of one dashboard.

    The socket is bound in the constructor (a port in use fails here, before anything
    else starts); the bus can be given now or attached later with :meth:`attach` (``anunnaki
    run --dashboard`` attaches it to the launch's bus once that is open).

    Args:
        model: The goal model with its binding.
        tactics: The tactics.
        bus: The bus to observe (shared with Utu, or a session of its own), or ``None`` to
            :meth:`attach` one later.
        name: Shown in the page's title.
        clock: ``"sim"`` (time from ``/clock``) or ``"wall"``, as Utu's configuration says.
        host: Address to bind; loopback unless told otherwise.
        port: TCP port (0: any free one).
        token: Enables operator actions (``None``: read-only).
        topics: Where the observer listens.
        max_rate: Most updates per second sent to a page.
        seed: Ask Utu for its decisions so far when attached.
        idle: Seconds without any message after which the page's *live* badge says the
            run has ended (see :meth:`DashboardState.run`).
        operator_timeout: Seconds an operator action waits for Utu's answer before the
            page is told it failed (502).

    """

    def __init__(
        self,
        model: GoalModel,
        tactics: TacticSet,
        *,
        bus: Bus | None = None,
        name: str | None = None,
        clock: Literal["sim", "wall"] = "wall",
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        token: str | None = None,
        topics: ObserverConfig | None = None,
        max_rate: float = 15.0,
        seed: bool = True,
        idle: float = 5.0,
        operator_timeout: float = 3.0,
    ) -> None:
        _require()
        if token is not None and (weak := token_weakness(token)) is not None:
            raise DashboardError(
                f"the operator token is too weak: {weak} (make one with: python -c "
                "'import secrets; print(secrets.token_urlsafe(16))')"
            )
        self._sim = SimTime() if clock == "sim" else None
        self.state = DashboardState(
            model,
            tactics,
            name=name,
            clock=self._sim.now if self._sim is not None else None,
            clock_kind=clock,
            operator=token is not None,
            idle=idle,
        )
        self.token = token
        self.operator_timeout = operator_timeout
        self.topics = topics
        self.seed = seed
        self.observer: BusObserver | None = None
        self.stopping = threading.Event()
        self.server = DashboardServer(None, host=host, port=port, stopping=self.stopping)
        self.server.app = create_app(
            self.state, self, token=token, max_rate=max_rate, stopping=self.stopping
        )
        if bus is not None:
            self.attach(bus)

    def attach(self, bus: Bus) -> BusObserver:
        """Observe ``bus`` (replacing the bus observed so far); returns the observer."""
        if self.observer is not None:
            self.observer.close()
        self.observer = BusObserver(bus, self.state, self.topics, sim=self._sim, seed=self.seed)
        return self.observer

    def operate(
        self,
        op: str,
        *,
        caller: str,
        tactic: str | None = None,
        reason: str | None = None,
        timeout: float | None = None,
    ) -> dict[str, Any]:
        """An operator action through the observer (see :meth:`BusObserver.operate`).

        Raises:
            OperatorError: No bus attached yet, or Utu refused or did not answer.

        """
        observer = self.observer
        if observer is None:
            raise OperatorError("the dashboard is not connected to a bus yet")
        if timeout is None:
            timeout = self.operator_timeout
        return observer.operate(op, caller=caller, tactic=tactic, reason=reason, timeout=timeout)

    @property
    def url(self) -> str:
        """The page's address (without the token)."""
        return self.server.url

    def start(self) -> Dashboard:
        """Start serving; returns self."""
        self.server.start()
        return self

    def close(self) -> None:
        """Stop the server and withdraw the subscriptions. Idempotent."""
        self.server.stop()
        if self.observer is not None:
            self.observer.close()

    def __enter__(self) -> Dashboard:
        return self.start()
