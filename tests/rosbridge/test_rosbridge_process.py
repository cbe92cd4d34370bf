"""The bus side both bridge processes share: their zenoh options and their stop event."""

from __future__ import annotations

import argparse
import os
import signal

from anunnaki.rosbridge import add_bus_arguments, bus_options, stop_event


def _args(*argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    add_bus_arguments(p)
    return p.parse_args(list(argv))


def test_connecting_listens_nowhere_unless_told() -> None:
    assert bus_options(_args(), "b") == {"mode": "peer", "name": "b"}
    got = bus_options(_args("--connect", "tcp/127.0.0.1:7447"), "b")
    assert got == {"mode": "peer", "name": "b", "connect": ["tcp/127.0.0.1:7447"], "listen": []}
    both = bus_options(_args("--connect", "tcp/a:1", "--listen", "tcp/b:2"), "b")
    assert both["connect"] == ["tcp/a:1"] and both["listen"] == ["tcp/b:2"]
    assert bus_options(_args("--listen", "tcp/b:2"), "b")["listen"] == ["tcp/b:2"]


def test_sigterm_sets_the_stop_event() -> None:
    before = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        stop = stop_event(_args())
        assert not stop.is_set()
        os.kill(os.getpid(), signal.SIGTERM)
        assert stop.wait(5.0)
    finally:
        for sig, handler in before.items():
            signal.signal(sig, handler)
