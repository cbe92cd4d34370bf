"""Surviving Utu nodes run-stop the platform when a peer dies (issue #12, nodes by hand).

A launch (``anunnaki run --processes``) supervises its nodes: when one exits, the launch
run-stops the platform and records ``node_died`` (:mod:`anunnaki.launch`). Nodes started by
hand (``anunnaki node NAME``) have no supervisor, so the survivors do it: every node watches
the other nodes' liveliness tokens ``/utu_<node>`` and, when one it has seen vanishes, exactly
one survivor acts — the first alive in :data:`ACT_ORDER`. Every survivor sees the same tokens,
so they agree on who that is without talking to each other.

How it acts depends on whether the loop can still act itself:

* **monitor, analyze and execute all survive** (plan or knowledge died): it publishes a
  run-stop on ``/utu/run_stop``; the monitor turns it into an operator call, and execute
  performs it in the loop — one request to the run-stop service, recorded as a ``run_stop``
  decision that a replay repeats.
* **otherwise** the loop cannot: it asks the run-stop service itself and announces it
  (:func:`~anunnaki.utu.host.stop_platform`, as the launch and the watchdog do).

Either way it records a ``node_died`` decision (``by``: the node that acted) in the
knowledge base, which ``anunnaki log`` and ``explain`` show; a replay neither makes nor
compares it (:data:`~anunnaki.utu.ASYNC_KINDS`). A node that a supervisor started is told so
(``anunnaki node --supervised``) and does not watch: the supervisor's run-stop is the one.
"""

from __future__ import annotations

import contextlib
import logging
import sqlite3
import threading
from collections.abc import Callable, Iterable

from anunnaki import topics
from anunnaki.bus import Bus
from anunnaki.errors import AnunnakiError
from anunnaki.messages import RunStop
from anunnaki.topics import UTU_NODES
from anunnaki.utu._config import UtuConfig
from anunnaki.utu.cycle._parts import open_knowledge
from anunnaki.utu.host._actuators import stop_platform

__all__ = ["ACT_ORDER", "PeerWatch"]

log = logging.getLogger("anunnaki.utu.peers")

ACT_ORDER: tuple[str, ...] = ("execute", "analyze", "plan", "knowledge", "monitor")
"""Which survivor acts on a peer's death: the first alive in this order (execute performs
run-stops anyway; the monitor, which keeps no knowledge base, last)."""

LOOP: tuple[str, ...] = ("monitor", "analyze", "execute")
"""The nodes a run-stop passes through when the loop performs it."""


class PeerWatch:
    """Run-stop the platform (once per death) when another Utu node's token vanishes.

    Args:
        name: This node's name (``monitor``, ``analyze``, …).
        bus: The node's bus.
        config: The Utu configuration (its run-stop service and knowledge base file).
        say: Where to tell the operator what happened (default: the log).
        hosts: The other nodes this process runs under a supervisor of its own (a launch
            running some of the nodes while others were started by hand): their deaths are
            the supervisor's to handle, and they count as survivors of the others'.

    Attributes:
        acted: The problems this node acted on, in order.

    """

    def __init__(
        self,
        name: str,
        bus: Bus,
        config: UtuConfig,
        *,
        say: Callable[[str], object] | None = None,
        hosts: Iterable[str] = (),
    ) -> None:
        self.hosts = frozenset({name, *hosts})
        unknown = sorted(self.hosts - set(UTU_NODES))
        if unknown:
            raise ValueError(f"unknown Utu node(s) {unknown}; nodes: {', '.join(UTU_NODES)}")
        self.name = name
        self.bus = bus
        self.config = config
        self.acted: list[str] = []
        self._say = say or log.error
        self._alive: set[str] = set()
        self._lock = threading.Lock()
        self._watch = bus.watch_liveliness(self._changed)

    def _changed(self, token: str, alive: bool) -> None:
        """From the watch's thread: a token appeared or vanished."""
        node = token.lstrip("/").removeprefix("utu_")
        if node not in UTU_NODES or node in self.hosts or token.lstrip("/") == node:
            return
        with self._lock:
            if alive:
                self._alive.add(node)
                return
            if node not in self._alive:
                return  # never seen up, or already gone
            self._alive.discard(node)
            survivors = self._alive | self.hosts
        actor = next(n for n in ACT_ORDER if n in survivors)
        if actor in self.hosts:
            self._act(node, loop=all(n in survivors for n in LOOP))

    def _act(self, dead: str, *, loop: bool) -> None:
        problem = f"node {dead} is gone (its token /utu_{dead} vanished)"
        reason = f"{problem}: Utu is incomplete"
        caller = f"peer:{self.name}"
        service = self.config.run_stop.service
        ok: bool | None = None
        error = ""
        if loop:  # execute performs it in the loop, recorded and replayed
            try:
                self.bus.publish(topics.RUN_STOP, RunStop(reason=reason, caller=caller))
            except AnunnakiError as exc:
                error = f"could not announce the run-stop: {exc}"
            what = "run-stop handed to the execute node"
        else:
            ok, error = stop_platform(self.bus, self.config, reason=reason, caller=caller)
            what = f"run-stop sent to {service}" if service else "no run_stop service configured"
            what += "" if ok is None else (" (ok)" if ok else f" (FAILED: {error})")
        self.acted.append(problem)
        self._say(f"{self.name}: {problem}: {what}")
        self._record(problem, service, ok, error, via="execute" if loop else self.name)

    def _record(
        self, problem: str, service: str | None, ok: bool | None, error: str, *, via: str
    ) -> None:
        """Record ``node_died`` on a connection of its own (the node's may be mid-step)."""
        if self.config.knowledge == ":memory:":
            return  # nothing shared to record it in (a node alone, for a look)
        try:
            kb = open_knowledge(self.config.knowledge)
        except AnunnakiError as exc:
            log.error("utu: could not record the node's death: %s", exc)
            return
        with contextlib.closing(kb), contextlib.suppress(sqlite3.Error):
            kb.record_decision(
                kb.last_t(),
                "node_died",
                None,
                problem=problem,
                by=self.name,
                via=via,
                service=service,
                ok=ok,
                error=error or None,
            )
            kb.flush()

    def close(self) -> None:
        """Stop watching (idempotent)."""
        self._watch.close()
