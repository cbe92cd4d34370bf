"""What both bridge processes share on the bus's side.

``python -m anunnaki.ros1`` and ``python -m anunnaki.ros2``: the zenoh options of their
command line, and how they are told to stop.
"""

from __future__ import annotations

import argparse
import signal
import threading


def add_bus_arguments(p: argparse.ArgumentParser) -> None:
    """``--connect``, ``--listen`` and ``--exit-with-parent``, as both bridges take them."""
    p.add_argument(
        "--connect",
        action="append",
        default=[],
        metavar="ENDPOINT",
        help="zenoh endpoint to connect to (Utu's or the launch's bus)",
    )
    p.add_argument(
        "--listen",
        action="append",
        default=None,
        metavar="ENDPOINT",
        help="zenoh endpoint to listen on (default: none when connecting)",
    )
    p.add_argument(
        "--exit-with-parent",
        action="store_true",
        help="stop when standard input closes (the launch that started it is gone)",
    )


def bus_options(args: argparse.Namespace, name: str) -> dict[str, object]:
    """The bridge's zenoh session: a peer named ``name``, connecting and listening as asked.

    Connecting, it listens nowhere unless told to.
    """
    options: dict[str, object] = {"mode": "peer", "name": name}
    if args.connect:
        options["connect"] = args.connect
        options["listen"] = args.listen or []
    elif args.listen:
        options["listen"] = args.listen
    return options


def stop_event(args: argparse.Namespace) -> threading.Event:
    """An event set by SIGINT or SIGTERM, and (``--exit-with-parent``) when stdin closes."""
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    if args.exit_with_parent:
        from anunnaki._parent import stop_with_parent

        stop_with_parent(stop.set)
    return stop
