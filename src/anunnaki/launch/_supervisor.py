"""The launch's supervisor: node processes started, watched, stopped; readiness; signals.

Every node process is started in its own session (the launch, not the terminal, stops them,
in order), its output forwarded line by line with a ``[name]`` prefix; the launch waits until
every node answers its readiness service (guideline C9) and never leaves one behind.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import subprocess
import threading
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import IO, Any, TextIO

from anunnaki.bus import Bus, BusConfig, BusError, ServiceError, on_loopback
from anunnaki.launch._schema import LaunchError, _StoppedDuringBringUp
from anunnaki.topics import ready_service

__all__ = ["Children", "child_bus_config", "signals_to", "wait_ready"]

log = logging.getLogger("anunnaki.launch")


def child_bus_config(parent: BusConfig, endpoints: Sequence[str], node: str) -> BusConfig:
    """The bus configuration of a node process started by a launch.

    A node joins the launch's session as a zenoh client (the launch's peer or router
    routes between its clients), or, when the launch itself is a client of a router, the
    same router. Endpoints listening on every interface are reached on loopback.
    """
    if parent.mode == "client":
        connect = list(parent.connect)
    else:
        connect = [on_loopback(ep) for ep in endpoints]
    return BusConfig(
        kind="zenoh",
        mode="client",
        connect=connect,
        tls=parent.tls,
        namespace=parent.namespace,
        name=node,
        zenoh=dict(parent.zenoh),
    )


def remove_db(path: str) -> None:
    for suffix in ("", "-wal", "-shm"):
        with contextlib.suppress(FileNotFoundError):
            Path(path + suffix).unlink()


def wait_ready(
    bus: Bus,
    names: Sequence[str],
    *,
    timeout: float,
    stop: threading.Event,
    procs: dict[str, subprocess.Popen[bytes]] | None = None,
) -> None:
    """Ask each node's readiness service until all answer (C9); fail on an early exit."""
    deadline = time.monotonic() + timeout
    pending = list(names)
    while pending:
        for name in list(pending):
            proc = (procs or {}).get(name)
            if proc is not None and proc.poll() is not None:
                raise LaunchError(
                    f"node {name} exited with code {proc.returncode} during bring-up "
                    "(its error is printed above)"
                )
            try:
                reply = bus.request(ready_service(name), {}, timeout=0.25)
            except ServiceError as exc:
                raise LaunchError(f"node {name}: readiness service failed: {exc}") from exc
            except BusError:
                continue
            body = reply.to_body() if hasattr(reply, "to_body") else {}
            if body.get("ready"):
                pending.remove(name)
        if stop.is_set():
            raise _StoppedDuringBringUp("stopped during bring-up")
        if pending and time.monotonic() > deadline:
            raise LaunchError(
                f"not ready within {timeout:g} s: {', '.join(pending)} "
                "(raise ready_timeout in the launch file if the machine is slow)"
            )


def _forward(stream: IO[bytes], out: TextIO, prefix: str) -> None:
    for raw in iter(stream.readline, b""):
        line = raw.decode("utf-8", "replace").rstrip("\n")
        with contextlib.suppress(ValueError, OSError):
            out.write(f"{prefix}{line}\n")
            out.flush()
    stream.close()


class Children:
    """The node processes of a launch: started, watched, stopped; never left behind."""

    def __init__(self, out: TextIO, err: TextIO) -> None:
        self.out = out
        self.err = err
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self.threads: list[threading.Thread] = []

    def start(self, name: str, argv: list[str]) -> subprocess.Popen[bytes]:
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        proc = subprocess.Popen(
            argv,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env=env,
            start_new_session=True,  # the launch, not the terminal, stops them (in order)
        )
        self.procs[name] = proc
        for stream, sink in ((proc.stdout, self.out), (proc.stderr, self.err)):
            assert stream is not None
            t = threading.Thread(target=_forward, args=(stream, sink, f"[{name}] "), daemon=True)
            t.start()
            self.threads.append(t)
        return proc

    def died(self) -> list[tuple[str, int]]:
        return [(n, p.returncode) for n, p in self.procs.items() if p.poll() is not None]

    def stop(self, timeout: float) -> None:
        for proc in self.procs.values():
            if proc.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    proc.send_signal(signal.SIGTERM)
            if proc.stdin is not None:
                with contextlib.suppress(OSError):
                    proc.stdin.close()
        deadline = time.monotonic() + timeout
        for name, proc in self.procs.items():
            try:
                proc.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                log.warning("node %s did not stop within %.1f s; killing it", name, timeout)
                proc.kill()
                proc.wait()
        for t in self.threads:
            t.join(timeout=2.0)


@contextlib.contextmanager
def signals_to(stop: threading.Event) -> Iterator[None]:
    """Turn SIGINT/SIGTERM into ``stop`` (main thread only; restored afterwards)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {}

    def handler(signum: int, frame: Any) -> None:
        stop.set()

    for sig in (signal.SIGINT, signal.SIGTERM):
        previous[sig] = signal.signal(sig, handler)
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)
