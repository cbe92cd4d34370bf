"""The runner: a launch's nodes (here or one process each), then its managed system.

One :class:`_Runner` per run: it opens the launch's bus, starts the nodes (the composed
:class:`~anunnaki.utu.AutonomicManager` when all five run in this process), waits until all
are ready, starts the managed system (a plugin of :data:`anunnaki.managed.MANAGED`), prints one
line per decision and stops everything on a signal, at ``until`` or when the system ends.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import shutil
import signal
import sqlite3
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from anunnaki._closing import Closing
from anunnaki.bus import Bus, BusConfig, Executor, open_bus
from anunnaki.launch._schema import Launch, LaunchError, _StoppedDuringBringUp
from anunnaki.launch._supervisor import (
    Children,
    child_bus_config,
    remove_db,
    signals_to,
    wait_ready,
)
from anunnaki.managed import ManagedContext, ManagedRun
from anunnaki.utu import (
    ACT_ORDER,
    MANAGERS,
    NODE_NAMES,
    AutonomicManager,
    Decision,
    DecisionTail,
    Knowledge,
    PeerWatch,
    UtuNode,
    UtuParts,
    build_node,
    open_knowledge,
    stop_platform,
)

__all__ = ["RunResult", "format_decision", "run_launch"]

log = logging.getLogger("anunnaki.launch")

#: ``--speed 0``: as fast as the work allows (rendering, inference and Utu's steps).
_AS_FAST_AS_POSSIBLE = 10_000.0


# -- printing ----------------------------------------------------------------------------------
def _short(value: Any, width: int = 40) -> str:
    if isinstance(value, float):  # a time or a utility: to the millisecond, as 'log' shows it
        value = round(value, 3)
    text = value if isinstance(value, str) else json.dumps(value, separators=(",", ":"))
    return text if len(text) <= width else text[: width - 1] + "…"


def format_decision(d: Decision, *, t0: float = 0.0) -> str:
    """One line for a decision: time, kind, tactic, detail (times ``t0`` on: the log's base)."""
    d = d.shifted(t0)
    detail = " ".join(f"{k}={_short(v)}" for k, v in d.data.items() if v is not None)
    return f"{d.t:9.3f}  {d.kind:<20} {d.tactic or '-':<18} {detail}".rstrip()


#: What a baseline manager is, said at the start of its run (``--manager``).
_BASELINES = {
    "none": "manager: none, the baseline without adaptation: Utu monitors and analyses, "
    "no tactic starts",
    "random": "manager: random (seed {seed}), the baseline that draws one startable tactic "
    "whenever Utu would start any; each draw is a random_draw line",
}


def _baseline_outcome(manager: str, decisions: Iterable[Decision], *, t0: float = 0.0) -> str:
    """What a baseline manager did, in one line: the tactics it started, or nothing adapted."""
    started = [d.shifted(t0) for d in decisions if d.kind == "started"]
    if not started:
        return f"manager {manager}: nothing adapted (no tactic started)"
    return f"manager {manager}: started " + ", ".join(f"{d.tactic} at {d.t:.3f} s" for d in started)


class _Printer:
    def __init__(self, out: TextIO, tail: DecisionTail) -> None:
        self.out = out
        self.tail = tail
        self.t0: float | None = None  # the log's time origin, once it has a record
        self.decisions: list[Decision] = []

    def say(self, text: str) -> None:
        with contextlib.suppress(ValueError, OSError):  # a closed or broken pipe
            self.out.write(text + "\n")
            self.out.flush()

    def poll(self) -> None:
        rows = self.tail.read()
        if rows and self.t0 is None:  # the times 'anunnaki log' and 'explain' show
            self.t0 = self.tail.knowledge.time_origin()
        self.decisions += rows
        for d in rows:
            self.say(format_decision(d, t0=self.t0 or 0.0))


@dataclass
class RunResult:
    """What a run did.

    Attributes:
        exit_code: 0 after a clean stop (signal, trace end, ``until``); 1 if a node died.
        reason: Why the run stopped.
        decisions: Every decision written during the run, in order.
        ready_after: Seconds from the start until every node answered its readiness service.
        ran: Seconds from the managed system's start to the stop.
        pids: Node -> process id (one process: all the same).

    """

    exit_code: int
    reason: str
    decisions: list[Decision]
    ready_after: float
    ran: float
    pids: dict[str, int]


def run_launch(
    launch: Launch,
    *,
    processes: bool = False,
    speed: float | None = None,
    until: float | None = None,
    knowledge: str | None = None,
    fresh: bool = False,
    stop: threading.Event | None = None,
    out: TextIO | None = None,
    err: TextIO | None = None,
    handle_signals: bool = True,
    on_bus: Callable[[Bus], object] | None = None,
    manager: str | None = None,
    manager_seed: int | None = None,
    on_knowledge: Callable[[Bus, Knowledge], object] | None = None,
    on_running: Callable[[], object] | None = None,
) -> RunResult:
    """Run a launch: nodes (in this process or one process each), then the managed system.

    Args:
        launch: The loaded launch.
        processes: One process per node (``python -m anunnaki.cli.main node NAME``).
        speed: Override the managed system's speed (0: as fast as possible).
        until: Stop when the managed system's clock reaches this time (its seconds), or,
            without a managed system, after this many seconds.
        knowledge: Override the knowledge base file.
        fresh: Delete the knowledge base file first (otherwise an existing one is resumed).
        stop: Set it to stop the run (signals set it too).
        out: Where to print (default stdout).
        err: Where the nodes' error output goes (default stderr).
        handle_signals: Turn SIGINT/SIGTERM into a clean stop (main thread only).
        on_bus: Called with the launch's bus once it is open, before any node starts (e.g.
            to attach a dashboard); what it declares on the bus closes with the bus. What it
            returns, when that is a :class:`~anunnaki._closing.Closing` (a dashboard's
            observer, a subscriber), is closed when the run ends, before Utu's nodes stop and
            the bus closes: a dashboard fetches the run's last decisions then, and nothing of
            it asks the bus after the bus has closed.
        manager: Who chooses the tactics: ``utu``, or a baseline, ``none`` or ``random``
            (overrides the Utu configuration's ``manager``; docs/whole-loop.md).
        manager_seed: The random manager's seed (overrides ``manager_seed``).
        on_knowledge: Called with the bus and the run's knowledge base once it is open,
            before any node starts (e.g. a live assurance case that records in the decision
            log: :class:`anunnaki.assurance.CaseMonitor`). With ``processes`` the knowledge
            base is this process's connection to the nodes' file (what is recorded on it is
            committed by its ``flush``). What it returns is closed as ``on_bus``'s is.
        on_running: Called once everything is up and the managed system has started, before
            the run is watched (``anunnaki run`` resumes the garbage collector it paused
            for the bring-up, freezing what the bring-up made: ``anunnaki.cli._heap``).

    Raises:
        LaunchError: A node failed at bring-up or did not become ready in time.
        ModelFileError, BusError: Configuration problems found while starting.

    """
    out = out or sys.stdout
    err = err or sys.stderr
    stop = stop or threading.Event()
    runner = _Runner(
        launch,
        processes=processes,
        speed=speed,
        until=until,
        knowledge=knowledge,
        fresh=fresh,
        stop=stop,
        out=out,
        err=err,
        on_bus=on_bus,
        manager=manager,
        manager_seed=manager_seed,
        on_knowledge=on_knowledge,
        on_running=on_running,
    )
    if not handle_signals:
        return runner.run()
    with signals_to(stop):
        return runner.run()


def _manager_fields(utu: Any) -> list[tuple[str, Any]]:
    return [("manager", utu.manager), ("manager_seed", utu.manager_seed)]


class _Runner:
    def __init__(
        self,
        launch: Launch,
        *,
        processes: bool,
        speed: float | None,
        until: float | None,
        knowledge: str | None,
        fresh: bool,
        stop: threading.Event,
        out: TextIO,
        err: TextIO,
        on_bus: Callable[[Bus], object] | None = None,
        manager: str | None = None,
        manager_seed: int | None = None,
        on_knowledge: Callable[[Bus, Knowledge], object] | None = None,
        on_running: Callable[[], object] | None = None,
    ) -> None:
        self.launch = launch
        self.on_bus = on_bus
        self.on_knowledge = on_knowledge
        self.on_running = on_running
        self.attached: list[object] = []  # what on_bus and on_knowledge returned: see _detach
        self.processes = processes
        self.managed = launch.managed
        default_speed = self.managed.speed if self.managed is not None else 1.0
        self.speed = speed if speed is not None else default_speed
        if self.speed == 0:
            self.speed = _AS_FAST_AS_POSSIBLE
        self.running: ManagedRun | None = None
        if not self.speed > 0:
            raise LaunchError(f"speed must be >= 0 (0: as fast as possible), got {self.speed!r}")
        self.until = until
        self.stop = stop
        self.out = out
        self.err = err
        self.tmpdir: str | None = None
        kb = knowledge if knowledge is not None else launch.utu.knowledge
        if kb != ":memory:":
            kb = str(Path(kb).resolve())
        elif processes:  # the nodes must share one file: a temporary one
            self.tmpdir = tempfile.mkdtemp(prefix="anunnaki-run-")
            kb = str(Path(self.tmpdir) / "knowledge.db")
        self.kb_path = kb
        if fresh and kb != ":memory:":
            remove_db(kb)
        update: dict[str, Any] = {"knowledge": kb}
        if manager is not None:
            if manager not in MANAGERS:
                raise LaunchError(f"unknown manager {manager!r}; managers: {', '.join(MANAGERS)}")
            update["manager"] = manager
        if manager_seed is not None:
            update["manager_seed"] = manager_seed
        if processes and any(update.get(k, v) != v for k, v in _manager_fields(launch.utu)):
            raise LaunchError(
                "--manager and --manager-seed apply in one process; with --processes the plan "
                "node reads them from the launch file (utu: manager, manager_seed)"
            )
        self.utu = launch.utu.model_copy(update=update)
        self.parts = UtuParts(
            self.utu,
            launch.parts.sources,
            launch.parts.model,
            launch.parts.tactics,
            launch.parts.warnings,
        )
        self.t_start = time.monotonic()

    def say(self, text: str) -> None:
        with contextlib.suppress(ValueError, OSError):
            self.out.write(text + "\n")
            self.out.flush()

    def run(self) -> RunResult:
        try:
            if self.processes:
                return self._run_processes()
            return self._run_here()
        except _StoppedDuringBringUp as exc:
            self.say(f"stopped ({exc})")
            return RunResult(0, str(exc), [], time.monotonic() - self.t_start, 0.0, {})
        finally:
            if self.tmpdir is not None:
                shutil.rmtree(self.tmpdir, ignore_errors=True)

    # -- what both modes share
    def _header(self, mode: str, bus: Bus) -> None:
        launch, utu = self.launch, self.utu
        where = f"{bus.kind}" + (f" {', '.join(bus.endpoints)}" if bus.endpoints else "")
        self.say(
            f"anunnaki run: {launch.name} — {mode}; bus {where}; clock {utu.clock}; "
            f"nodes {', '.join(f'{n} {r:g} Hz' for n, r in launch.nodes.items())}"
        )
        if self.tmpdir is not None:
            self.say(
                f"knowledge: {self.kb_path} (temporary, removed at the end; "
                "--knowledge FILE keeps it)"
            )
        else:
            self.say(f"knowledge: {self.kb_path}")
        if utu.manager != "utu":
            self.say(_BASELINES[utu.manager].format(seed=utu.manager_seed))
        for w in launch.parts.warnings:
            self.say(f"warning: {w.render()}")
        if self.managed is not None:
            for note in self.managed.notes(utu, self.speed):
                self.say(note)

    def _resuming(self, kb: Knowledge) -> None:
        last = kb.decisions(limit=1)
        if last:
            self.say(
                f"knowledge: resuming a run with {kb.counts()['decisions']} decisions, the last "
                f"at t={last[-1].t:g} (tactic state and time go on from there; --fresh starts "
                "over)"
            )

    def _start_managed(
        self,
        bus: Bus,
        executor: Executor | None = None,
    ) -> ManagedRun | None:
        """Start the managed system (a plugin) in its own thread.

        ``executor``: the run's one thread of delivery, if it has one (the system drains it).
        """
        if self.managed is None:
            self._running()
            return None
        ctx = ManagedContext(
            bus=bus,
            stop=self.stop,
            speed=self.speed,
            until=self.until,
            say=self.say,
            executor=executor,
        )
        self.running = self.managed.start(ctx)
        self._running()
        return self.running

    def _running(self) -> None:
        if self.on_running is not None:
            self.on_running()

    def _watch(
        self,
        printer: _Printer,
        driver: threading.Thread | None,
        failed: Any,
    ) -> tuple[int, str]:
        """Print decisions until a reason to stop; return (exit code, reason)."""
        started = time.monotonic()
        end_at: float | None = None
        while True:
            printer.poll()
            if self.stop.is_set():
                return 0, "stopped by a signal"
            problem = failed()
            if problem:
                return 1, problem
            now = time.monotonic()
            if driver is not None and not driver.is_alive():
                if end_at is None:
                    end_at = now + self.launch.config.linger
                elif now >= end_at:
                    ended = self.running.ended if self.running is not None else "ended"
                    why = ended if self.until is None else f"reached t={self.until:g}"
                    return 0, why
            if driver is None and self.until is not None and now - started >= self.until:
                return 0, f"ran {self.until:g} s"
            self.stop.wait(0.05)

    def _fail_safe(self, bus: Bus, kb: Knowledge | None, problem: str) -> None:
        """A Utu node died: run-stop the platform now, tell everyone, record it.

        The surviving nodes may be unable to (the execute node may be the one that died),
        so the launch asks the configured run-stop service itself (guideline S4), publishes
        ``/utu/run_stop`` for the survivors and any dashboard, and records a ``node_died``
        decision with the outcome. A launch never just exits when part of Utu is gone.
        """
        service = self.utu.run_stop.service
        ok, error = stop_platform(
            bus,
            self.utu,
            reason=f"{problem}: Utu is incomplete",
            caller=f"launch:{self.launch.name}",
        )
        where = f"run-stop sent to {service}" if service else "no run_stop service configured"
        status = "" if ok is None else (" (ok)" if ok else f" (FAILED: {error})")
        self.say(f"{problem}: {where}{status}")
        if kb is not None:
            with contextlib.suppress(sqlite3.Error):
                kb.record_decision(
                    kb.last_t(),
                    "node_died",
                    None,
                    problem=problem,
                    service=service,
                    ok=ok,
                    error=error or None,
                )
                kb.flush()

    def _finish(self, printer: _Printer, code: int, reason: str, ran: float) -> None:
        printer.poll()
        self.say(f"stopped ({reason}): {len(printer.decisions)} decisions in {ran:.2f} s")
        if self.utu.manager != "utu":
            self.say(_baseline_outcome(self.utu.manager, printer.decisions, t0=printer.t0 or 0.0))
        if self.running is not None:
            self.running.finish(printer.decisions, ran)

    # -- one process
    def _deterministic(self) -> bool:
        """Whether this run is one deterministic program on an executor (issue #30).

        So it is when everything it runs is simulated and in this process: an in-process
        bus, Utu composed on sim time, and a managed system that drains the executor at
        each instant (``deterministic`` on its kind: ``sim``). Anything live keeps the
        bus's threads.
        """
        launch = self.launch
        return (
            launch.bus.kind == "inproc"
            and set(launch.nodes) == set(NODE_NAMES)
            and self.utu.clock == "sim"
            and bool(getattr(self.managed, "deterministic", False))
        )

    def _run_here(self) -> RunResult:
        launch = self.launch
        executor = Executor() if self._deterministic() else None
        bus = open_bus(launch.bus, name=f"{launch.name}-launch", executor=executor)
        if self.on_bus is not None:
            self.attached.append(self.on_bus(bus))
        nodes: list[UtuNode | AutonomicManager] = []
        threads: list[threading.Thread] = []
        halt = threading.Event()
        crashed: list[str] = []
        managed = None
        peers: PeerWatch | None = None
        kb: Knowledge | None = None
        try:
            all_five = set(launch.nodes) == set(NODE_NAMES)
            mode = (
                "5 nodes in one process (the composed manager)"
                if all_five
                else f"{len(launch.nodes)} nodes in one process"
            )
            self._header(mode, bus)
            kb = self._open_knowledge(bus)
            tail = DecisionTail(kb)
            # On sim time each node takes its time from /clock, as across processes.
            nodes.extend(self._build_nodes(bus, kb, composed=all_five))
            detach = _drive(nodes, executor, halt, crashed, threads)
            wait_ready(bus, list(launch.nodes), timeout=launch.config.ready_timeout, stop=self.stop)
            peers = self._watch_peers(bus)
            ready_after = time.monotonic() - self.t_start
            self.say(f"ready: {', '.join(launch.nodes)} after {ready_after:.2f} s")
            printer = _Printer(self.out, tail)
            t_run = time.monotonic()
            managed = self._start_managed(bus, executor)
            code, reason = self._watch(
                printer, managed.thread if managed else None, lambda: crashed[0] if crashed else ""
            )
            if crashed:
                self._fail_safe(bus, kb, crashed[0])
            self.stop.set()
            if managed is not None:
                managed.thread.join(timeout=5.0)
            detach()
            _halt(halt, nodes, threads)
            self._detach()  # the nodes are quiet; knowledge still answers
            ran = time.monotonic() - t_run
            self._finish(printer, code, reason, ran)
            pid = os.getpid()
            return RunResult(
                code, reason, printer.decisions, ready_after, ran, dict.fromkeys(launch.nodes, pid)
            )
        finally:
            self.stop.set()
            self._detach()
            if peers is not None:
                peers.close()
            _halt(halt, nodes, threads)
            if managed is not None:
                managed.close()
            for node in reversed(nodes):
                node.close()
            if kb is not None:
                with contextlib.suppress(sqlite3.Error):  # the manager may have closed it
                    kb.close()
            bus.close()

    def _open_knowledge(self, bus: Bus) -> Knowledge:
        """The run's knowledge base, opened (resumed, said so) and given to ``on_knowledge``."""
        kb = open_knowledge(self.kb_path)
        self._resuming(kb)
        if self.on_knowledge is not None:
            self.attached.append(self.on_knowledge(bus, kb))
        return kb

    def _detach(self) -> None:
        """Close what ``on_bus`` and ``on_knowledge`` returned (once), while Utu still answers."""
        attached, self.attached = self.attached, []
        for item in reversed(attached):
            if isinstance(item, Closing):
                item.close()

    def _watch_peers(self, bus: Bus) -> PeerWatch | None:
        """Watch the Utu nodes this launch does not run (started by hand elsewhere).

        The launch run-stops the platform when one of its own nodes dies; when one of the
        others does, the launch's first node in :data:`~anunnaki.utu.ACT_ORDER` acts, as the
        survivors started by hand do for one another (:class:`~anunnaki.utu.PeerWatch`).
        ``None`` when the launch runs all five.
        """
        ours = [n for n in ACT_ORDER if n in self.launch.nodes]
        if len(ours) == len(NODE_NAMES):
            return None
        return PeerWatch(ours[0], bus, self.utu, say=self.say, hosts=ours)

    def _build_nodes(
        self, bus: Bus, kb: Knowledge, *, composed: bool
    ) -> list[UtuNode | AutonomicManager]:
        """The launch's Utu nodes on ``bus``: the composed manager when all five are here."""
        launch = self.launch
        if composed:
            return [
                AutonomicManager.from_config(self.parts, bus=bus, knowledge=kb, nodes=launch.nodes)
            ]
        return [
            build_node(name, self.parts, bus=bus, knowledge=kb, rate=rate)
            for name, rate in launch.nodes.items()
        ]

    # -- one process per node
    def _node_argv(self, name: str, bus_config: BusConfig) -> list[str]:
        if self.launch.path is None:
            raise LaunchError("--processes needs a launch file (the nodes read it)")
        return [
            sys.executable,
            "-m",
            "anunnaki.cli.main",
            "node",
            name,
            "--config",
            str(self.launch.path),
            "--knowledge",
            self.kb_path,
            "--rate",
            repr(self.launch.nodes[name]),
            "--bus-json",
            bus_config.model_dump_json(exclude_none=True),
            "--exit-with-parent",
            "--supervised",  # the launch run-stops the platform when a node dies
            *self._expect_args(name),
        ]

    def _expect_args(self, name: str) -> list[str]:
        """The analyze node waits for the launch's plan and execute nodes before cycling."""
        peers = [n for n in ("plan", "execute") if n in self.launch.nodes]
        return ["--expect", ",".join(peers)] if name == "analyze" and peers else []

    def _run_processes(self) -> RunResult:
        launch = self.launch
        parent_config = launch.bus
        if parent_config.kind == "inproc":
            parent_config = BusConfig(kind="zenoh", namespace=parent_config.namespace)
        bus = open_bus(parent_config, name=f"{launch.name}-launch")
        if self.on_bus is not None:
            self.attached.append(self.on_bus(bus))
        children = Children(self.out, self.err)
        managed = None
        peers: PeerWatch | None = None
        kb: Knowledge | None = None
        try:
            self._header(f"{len(launch.nodes)} nodes, one process each", bus)
            if launch.bus.kind == "inproc":
                self.say("note: bus kind inproc cannot cross processes; using zenoh on loopback")
            # Create the knowledge base before the nodes open it together.
            kb = self._open_knowledge(bus)
            tail = DecisionTail(kb)
            for name in launch.nodes:
                config = child_bus_config(parent_config, bus.endpoints, f"{launch.name}-{name}")
                proc = children.start(name, self._node_argv(name, config))
                self.say(f"node {name}: pid {proc.pid}")
            wait_ready(
                bus,
                list(launch.nodes),
                timeout=launch.config.ready_timeout,
                stop=self.stop,
                procs=children.procs,
            )
            peers = self._watch_peers(bus)
            ready_after = time.monotonic() - self.t_start
            self.say(f"ready: {', '.join(launch.nodes)} after {ready_after:.2f} s")
            printer = _Printer(self.out, tail)
            t_run = time.monotonic()
            managed = self._start_managed(bus)

            def failed() -> str:
                dead = children.died()
                return (
                    ", ".join(f"node {n} exited with code {rc}" for n, rc in dead) if dead else ""
                )

            code, reason = self._watch(printer, managed.thread if managed else None, failed)
            if code != 0:
                self._fail_safe(bus, kb, reason)  # before anything else stops
            self.stop.set()
            if managed is not None:
                managed.thread.join(timeout=5.0)
                # Down with the platform's liveliness guard before the nodes exit: their
                # tokens going now is the end of the run, not a death (a real death was
                # caught above, by ``failed`` or the guard, and the fail-safe sent).
                managed.close()
            self._detach()  # before the knowledge node stops
            children.stop(launch.config.stop_timeout)
            ran = time.monotonic() - t_run
            bad = [(n, rc) for n, rc in children.died() if rc not in (0, -signal.SIGTERM)]
            if bad and code == 0:
                code = 1
                reason += "; " + ", ".join(f"node {n} exited with code {rc}" for n, rc in bad)
            self._finish(printer, code, reason, ran)
            pids = {n: p.pid for n, p in children.procs.items()}
            return RunResult(code, reason, printer.decisions, ready_after, ran, pids)
        finally:
            self.stop.set()
            self._detach()
            if peers is not None:
                peers.close()
            children.stop(launch.config.stop_timeout)
            if managed is not None:
                managed.close()
            if kb is not None:
                kb.close()
            bus.close()


def _drive(
    nodes: list[UtuNode | AutonomicManager],
    executor: Executor | None,
    halt: threading.Event,
    crashed: list[str],
    threads: list[threading.Thread],
) -> Callable[[], None]:
    """Set the nodes going: on the run's executor, else each on a thread (:func:`_spin`).

    Returns what ends them on the executor once the simulation is over: the manager's last
    step, delivered from the calling thread (nothing for spinning nodes: ``_halt``).
    """
    if executor is None:
        threads.extend(_spin(nodes, halt, crashed))
        return lambda: None
    ends = [n.run_on(executor) for n in nodes if isinstance(n, AutonomicManager)]

    def detach() -> None:
        for end in ends:
            end()
        try:
            executor.spin_until_idle()
        except RuntimeError:  # the simulation's thread has not ended (it was told to)
            log.warning("the simulation did not end in time; its last messages stay undelivered")
            return
        executor.release()

    return detach


def _spin(
    nodes: list[UtuNode | AutonomicManager], halt: threading.Event, crashed: list[str]
) -> list[threading.Thread]:
    """Spin each node on a thread of its own until ``halt``; failures go to ``crashed``."""
    threads = []
    for node in nodes:

        def spin(node: UtuNode | AutonomicManager = node) -> None:
            try:
                node.spin(halt)
            except Exception as exc:
                log.exception("a node failed")
                crashed.append(f"a node failed: {type(exc).__name__}: {exc}")

        t = threading.Thread(target=spin, name="anunnaki-node", daemon=True)
        t.start()
        threads.append(t)
    return threads


def _halt(
    halt: threading.Event, nodes: list[UtuNode | AutonomicManager], threads: list[threading.Thread]
) -> None:
    """Stop the nodes' spinning and wait (5 s each) for their threads."""
    halt.set()
    for node in nodes:
        node.wake()
    for t in threads:
        t.join(timeout=5.0)
