"""``anunnaki dashboard CONFIG`` and ``anunnaki run CONFIG --dashboard``: the Utu GUI.

``dashboard`` joins the bus a launch file (or Utu configuration) names — which must reach
other processes (zenoh) — and serves the live page until Ctrl-C/SIGTERM. ``run
--dashboard`` serves the same page from the launching process, on the launch's own bus, so
it works with the in-process bus too; the URL is printed before the nodes start. Read-only
unless a token is given (``--token``/``--dashboard-token`` or ``$ANUNNAKI_DASHBOARD_TOKEN``).
See docs/dashboard.md.
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from anunnaki.bus import BusConfig, BusConfigError, on_loopback, open_bus
from anunnaki.errors import validation_message
from anunnaki.launch import Launch, load_launch, signals_to

__all__ = [
    "TOKEN_ENV",
    "add_parser",
    "add_run_options",
    "announce",
    "case_folder",
    "dashboard_for_launch",
    "joining_bus",
    "linger",
    "run",
    "token_from",
    "wait_for_signal",
    "warn_exposed",
]

#: The environment variable read when no token is given on the command line.
TOKEN_ENV = "ANUNNAKI_DASHBOARD_TOKEN"
DEFAULT_PORT = 8765


def add_parser(sub: Any) -> None:
    """Register the ``dashboard`` sub-command."""
    p: argparse.ArgumentParser = sub.add_parser(
        "dashboard",
        help="serve the live dashboard (Utu's GUI) for a running system",
        description=(
            "Join the bus of a launch file (anunnaki: launch/1) or Utu configuration "
            "(anunnaki: utu/1) and serve a live web page of Utu's knowledge, monitor, "
            "analysis, plan, execution, oracle, goal model, camera feed, timeline and "
            "decision log, until Ctrl-C/SIGTERM. The bus must reach other processes (zenoh); "
            "with the in-process bus use 'anunnaki run CONFIG --dashboard'. Read-only unless "
            f"a token is given (--token or ${TOKEN_ENV})."
        ),
    )
    p.add_argument("config", help="launch file (launch/1) or Utu configuration (utu/1)")
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to serve on (default 127.0.0.1: this machine only)",
    )
    p.add_argument(
        "--port", type=int, default=DEFAULT_PORT, help=f"TCP port (default {DEFAULT_PORT}; 0: any)"
    )
    p.add_argument(
        "--token",
        help=f"enable operator actions for requests carrying this token (or ${TOKEN_ENV})",
    )
    p.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help="zenoh endpoint to connect to (default: the launch's listen endpoints, on "
        "loopback; a client launch's connect endpoints)",
    )
    p.add_argument(
        "--listen",
        action="append",
        metavar="ENDPOINT",
        help="zenoh endpoint to listen on (default: a free loopback port; a client: none)",
    )
    p.add_argument(
        "--mode",
        choices=("peer", "client", "router"),
        help="zenoh mode (default: the launch's, peer if it is a router)",
    )
    p.add_argument(
        "--camera", default="/*/camera/image", help="camera topic pattern (Image messages)"
    )
    p.add_argument("--detections", default="/lec/*/detections", help="detections topic pattern")
    p.add_argument("--oracle", default="/utu/oracle/**", help="assessment topic pattern")
    p.add_argument(
        "--case",
        metavar="DIR",
        help="the assurance case to draw (default: built from the launch when an "
        "assurance.yaml lies beside it); its statuses come from the running launch",
    )
    p.set_defaults(run=run)


def add_run_options(p: argparse.ArgumentParser) -> None:
    """Add ``--dashboard`` and its options to the ``run`` sub-command."""
    p.add_argument(
        "--dashboard",
        action="store_true",
        help="serve the live dashboard from this process (URL printed); after the run ends it "
        "keeps showing the last state until Ctrl-C",
    )
    p.add_argument(
        "--dashboard-port",
        type=int,
        default=DEFAULT_PORT,
        metavar="N",
        help=f"the dashboard's TCP port (default {DEFAULT_PORT}; 0: any free port)",
    )
    p.add_argument(
        "--dashboard-host",
        default="127.0.0.1",
        metavar="ADDR",
        help="the dashboard's address (default 127.0.0.1: this machine only)",
    )
    p.add_argument(
        "--dashboard-token",
        metavar="T",
        help=f"enable operator actions with this token (or ${TOKEN_ENV})",
    )
    p.add_argument(
        "--dashboard-linger",
        type=float,
        metavar="S",
        help="after the run ends, keep the page up S seconds, then exit, saying every 10 s "
        "how long is left (default: until Ctrl-C)",
    )


def token_from(given: str | None) -> str | None:
    """The token given on the command line, else the environment's, else ``None``."""
    token = given if given is not None else os.environ.get(TOKEN_ENV)
    return token or None


def dashboard_for_launch(
    launch: Launch,
    *,
    host: str = "127.0.0.1",
    port: int = DEFAULT_PORT,
    token: str | None = None,
    topics: Any = None,
) -> Any:
    """Build (and bind, not yet start) the dashboard of a launch; attach a bus later.

    A host other than loopback is served as asked, with a warning on stderr.

    Raises:
        MissingExtraError: fastapi/uvicorn are not installed.
        DashboardError: The port is in use or the address is bad.

    """
    from anunnaki.dashboard import Dashboard, ObserverConfig

    if topics is None:
        topics = ObserverConfig(clock=launch.utu.clock_topic)
    dashboard = Dashboard(
        launch.parts.model,
        launch.parts.tactics,
        name=launch.name,
        clock=launch.utu.clock,
        host=host,
        port=port,
        token=token,
        topics=topics,
    )
    if not dashboard.server.loopback:
        warn_exposed(host, dashboard.server.port, token)
    return dashboard


def warn_exposed(host: str, port: int, token: str | None) -> None:
    """Warn on stderr that the dashboard is served beyond this machine."""
    act = "" if token is None else ", and anyone with the token can act on it"
    advice = "put it behind TLS (a reverse proxy)" + (" and give it a --token" if not token else "")
    print(
        f"dashboard: warning: serving on {host}, not only on this machine: anyone who can "
        f"reach port {port} can watch the run{act}; {advice}",
        file=sys.stderr,
        flush=True,
    )


def announce(dashboard: Any, token: str | None) -> None:
    """Print where the dashboard is, and whether operator actions are on."""
    print(f"dashboard: {dashboard.url}", flush=True)
    if token is not None:
        print(
            "dashboard: operator actions enabled — enter the token on the page "
            f"(or open {dashboard.url}#token=<token>)",
            flush=True,
        )


def wait_for_signal(stop: threading.Event | None = None, timeout: float | None = None) -> None:
    """Block until Ctrl-C or SIGTERM (or ``stop`` is set, or ``timeout`` seconds pass)."""
    stop = stop or threading.Event()
    deadline = None if timeout is None else time.monotonic() + timeout
    with signals_to(stop):
        while True:
            left = 0.5 if deadline is None else min(0.5, deadline - time.monotonic())
            if left <= 0 or stop.wait(left):
                return


def linger(
    url: str,
    seconds: float | None,
    *,
    say: Callable[[str], None],
    every: float = 10.0,
    stop: threading.Event | None = None,
    wait: Callable[[threading.Event, float | None], None] | None = None,
) -> None:
    """After the run: keep the page up ``seconds`` (``None``: until Ctrl-C), saying so.

    The first line says where the page is and for how long; every ``every`` seconds a
    line says it is still up and for how long more, so a terminal that seems idle says what
    it waits for. Ctrl-C or SIGTERM (or ``stop``) ends it at once. ``wait(stop, timeout)``
    is :func:`wait_for_signal` (a test gives its own).
    """
    stop = stop or threading.Event()
    wait = wait or (lambda event, timeout: wait_for_signal(event, timeout=timeout))
    with signals_to(stop):  # also between two waits
        if seconds is None:
            say(f"dashboard: the run has ended; {url} keeps showing its last state until Ctrl-C")
            wait(stop, None)
            return
        say(
            f"dashboard: the run has ended; {url} keeps showing its last state for {seconds:g} s "
            "(Ctrl-C to leave now)"
        )
        left = seconds
        while left > 0 and not stop.is_set():
            step = min(every, left)
            wait(stop, step)
            left -= step
            if left > 0 and not stop.is_set():
                say(f"dashboard: still up at {url} for {left:g} s more; Ctrl-C to leave")


def joining_bus(
    launch: Launch, args: argparse.Namespace, *, role: str = "the dashboard"
) -> BusConfig:
    """The bus of a session joining a running launch (the dashboard, a node run by hand).

    It joins the launch's session, never takes its place.

    The launch file describes the session of the running launch; the dashboard is one more
    session on that bus. So it never listens where the launch listens (which is taken): it
    listens only where ``--listen`` says (by default a peer listens on a free loopback port,
    a client nowhere), and connects where ``--connect`` says, by default to the launch's
    ``listen`` endpoints (an endpoint on every interface is reached on loopback) or, when
    the launch is a client, to the launch's router. ``--mode`` defaults to the launch's
    (peer when the launch is a router). TLS, namespace, scouting and raw zenoh entries are the
    launch's.

    Raises:
        ModelFileError: the bus is in-process and nothing on the command line says where to
            join, or there is no endpoint to connect to.
        BusConfigError: the options do not make a valid bus (e.g. a client with ``--listen``).

    """
    bus = launch.bus
    if bus.kind == "inproc" and not (args.connect or args.listen or args.mode):
        raise launch.error(
            f"{role} on its own needs a bus other processes can reach, but the bus is inproc",
            "bus",
            hint="run it with the nodes: anunnaki run CONFIG --dashboard; or set bus: "
            "{kind: zenoh, ...} or give --connect ENDPOINT",
        )
    mode = args.mode or ("peer" if bus.mode == "router" else bus.mode)
    if args.connect:
        connect = list(args.connect)
    elif bus.kind == "inproc" or bus.mode == "client":
        connect = list(bus.connect)
    else:
        launch_listens = bus.listen or (bus.effective_listen() if bus.mode == "router" else [])
        connect = [on_loopback(ep) for ep in launch_listens] or list(bus.connect)
    if not connect and not bus.multicast_scouting:
        raise launch.error(
            f"{role} cannot find the launch's session: the bus names no listen or connect endpoint",
            "bus",
            hint="give --connect ENDPOINT (where the launch listens, e.g. tcp/127.0.0.1:7447)",
        )
    data = bus.model_dump(exclude_unset=True, exclude={"listen", "connect", "mode", "name"})
    data.update(kind="zenoh", mode=mode, connect=connect, listen=list(args.listen or []))
    try:
        return BusConfig.model_validate(data)
    except ValidationError as exc:
        first = exc.errors(include_url=False)[0]
        where = ".".join(str(p) for p in first["loc"]) or "bus"
        raise BusConfigError(f"bus option {where}: {validation_message(first)}") from None


def case_folder(launch: Launch, given: str | None) -> str | bool | None:
    """The live case's folder: ``--case``, else the launch file's ``assurance:``.

    A folder in the launch file is relative to it; ``False`` when the launch file says
    ``assurance: false``; ``None``: built if it can be (docs/assurance.md).
    """
    if given is not None:
        return given
    key = launch.config.assurance
    if isinstance(key, str) and launch.path is not None:
        return str(Path(launch.path).parent / key)
    return False if key is False else None


def run(args: argparse.Namespace) -> int:
    """Serve the dashboard of a launch's bus until a signal; returns the exit code."""
    from anunnaki.dashboard import ObserverConfig

    launch = load_launch(args.config, read_records=False)
    bus_config = joining_bus(launch, args)
    token = token_from(args.token)
    topics = ObserverConfig(
        camera=args.camera,
        detections=args.detections,
        oracle=args.oracle,
        clock=launch.utu.clock_topic,
    )
    dashboard = dashboard_for_launch(
        launch, host=args.host, port=args.port, token=token, topics=topics
    )
    from anunnaki.assurance import load_live_case, render_svg

    folder = case_folder(launch, args.case)
    case = (
        None
        if folder is False
        else load_live_case(
            launch.path,
            folder if isinstance(folder, str) else None,
            warn=lambda line: print(line, file=sys.stderr, flush=True),
        )
    )
    if case is not None:
        dashboard.state.set_case_drawing(render_svg(case))
    try:
        with open_bus(bus_config, name=f"{launch.name}-dashboard") as bus:
            dashboard.attach(bus)
            dashboard.start()
            announce(dashboard, token)
            where = ", ".join(bus_config.connect) or ", ".join(bus.endpoints) or bus.kind
            print(f"dashboard: observing {launch.name} on bus {where}; Ctrl-C to stop", flush=True)
            wait_for_signal()
    finally:
        dashboard.close()
    print("dashboard: stopped", file=sys.stderr)
    return 0
