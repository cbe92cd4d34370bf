"""Launch files (``anunnaki: launch/1``): run Utu's nodes and a managed system, like ROS launch.

A launch file says which Utu configuration to run, which of its five nodes, on which bus,
at which rates, and optionally a scripted managed system to run them against::

    anunnaki: launch/1
    name: rover
    utu: utu-config.yaml          # a Utu configuration file, or the same fields inline
    knowledge: run.db             # overrides the Utu configuration's knowledge base
    bus: {kind: zenoh}            # BusConfig fields (see docs/bus.md); overrides utu's bus
    nodes:                        # a list of names, or name -> {rate: Hz}
      monitor: {rate: 50}
      analyze: {rate: 20}
      plan: {rate: 20}
      execute: {rate: 20}
      knowledge: {rate: 10}
    managed:
      scripted: {trace: trace.jsonl, prefix: /rover, speed: 1.0, loop: false,
                 publish_clock: true}

Paths are relative to the launch file. :func:`load_launch` validates everything a node
needs at bring-up (guideline B5): the launch file itself, the Utu configuration, the goal
model, binding and tactics, the trace; every error names file and line.

:func:`run_launch` starts the nodes in this process (the composed
:class:`~anunnaki.utu.AutonomicManager` when all five run) or one process per node
(``python -m anunnaki.cli.main node NAME``), waits until every node answers its readiness
service (C9), then starts the managed system, prints one line per decision, and shuts
everything down on a signal, at ``until`` or when the trace ends. See docs/running.md.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Annotated, Any, Literal, TextIO

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from anunnaki import topics
from anunnaki._safeyaml import LineMap, describe_path, load_yaml, validation_error
from anunnaki.bus import Bus, BusConfig, BusError, Clock, ServiceError, open_bus
from anunnaki.clock import SimClock
from anunnaki.errors import AnunnakiError, ModelFileError
from anunnaki.trace import Record, read_trace
from anunnaki.utu._config import UtuConfig, load_config
from anunnaki.utu._knowledge import Decision, Knowledge
from anunnaki.utu._nodes import (
    NODE_NAMES,
    ComposedUtu,
    DecisionTail,
    MonitorNode,
    NodeName,
    UtuNode,
    UtuParts,
    build_node,
    load_parts,
    open_knowledge,
    ready_service,
)

__all__ = [
    "Launch",
    "LaunchConfig",
    "LaunchError",
    "ManagedConfig",
    "NodeSettings",
    "RunResult",
    "ScriptedConfig",
    "child_bus_config",
    "format_decision",
    "load_launch",
    "parse_launch",
    "run_launch",
    "signals_to",
]

log = logging.getLogger("anunnaki.utu.launch")


class LaunchError(AnunnakiError):
    """A launch could not be brought up (a node failed to start or to become ready)."""


class _StoppedDuringBringUp(LaunchError):
    """A signal arrived before every node was ready."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ScriptedConfig(_Strict):
    """A scripted managed system (:class:`~anunnaki.managed.scripted.ScriptedSystem`).

    Attributes:
        trace: The trace to replay (JSONL, ``anunnaki: trace/1``).
        prefix: The platform's name prefix: services ``<prefix>/set_mode``, ``<prefix>/stop``.
        status_topic: The topic whose ``mode``/``buzzer`` fields follow commands.
        modes: The modes ``set_mode`` accepts.
        speed: Replay speed: 1.0 real time, 10 ten times faster.
        loop: Start over at the end (trace time keeps increasing), until stopped.
        publish_clock: Publish the trace time on ``/clock`` (for ``clock: sim``).
        sync: Lockstep with Utu: after each instant, wait (at most ``sync_timeout`` s)
            until Utu has taken that instant's messages before moving time on, as a
            simulator waits for its controller. With ``clock: sim`` every input is then
            stamped with exactly its instant, at any ``speed``.
        sync_timeout: The longest wait per instant, in wall seconds.

    """

    trace: str
    prefix: str = "/rover"
    status_topic: str | None = None
    modes: list[str] = Field(default_factory=lambda: ["autonomous", "manual"], min_length=1)
    speed: Annotated[float, Field(gt=0, le=10_000)] = 1.0
    loop: bool = False
    publish_clock: bool = False
    sync: bool = False
    sync_timeout: Annotated[float, Field(gt=0)] = 1.0


class SimConfig(_Strict):
    """A simulated platform with its detector and oracle (:class:`~anunnaki.sim.SimulatedSystem`).

    Attributes:
        scenario: The scenario file (``anunnaki: scenario/1``); its ``platform`` says rover or
            UAV.
        models: The detector's model registry (``anunnaki: models/1``); without it no
            detector runs.
        oracle: The oracle node's options: ``name`` (default ``ground_truth``) and the
            oracle's own (e.g. ``window``); ``null`` runs none.
        speed: Simulated seconds per wall second (the detector can hold it back: lockstep).
        lockstep: A frame is not followed by the next before its detections are out.
        report: Print the per-phase table (detector F1, categories, models, tactics) at the end.
        report_file: Also write the run as data (``sim-report/1`` JSON: every scored frame,
            assessment and tactic); relative to the launch file.
        plot_file: Also draw the run (windowed F1 per model, the oracle's category, the
            tactics; PNG, or any format matplotlib knows by the suffix); relative to the
            launch file.

    """

    scenario: str
    models: str | None = None
    oracle: dict[str, Any] | None = Field(default_factory=lambda: {"name": "ground_truth"})
    speed: Annotated[float, Field(gt=0, le=10_000)] = 1.0
    lockstep: bool = True
    report: bool = True
    report_file: str | None = None
    plot_file: str | None = None


class ManagedConfig(_Strict):
    """The managed system a launch runs against (none: the robot is real)."""

    scripted: ScriptedConfig | None = None
    sim: SimConfig | None = None

    @model_validator(mode="after")
    def _one(self) -> ManagedConfig:
        if self.scripted is not None and self.sim is not None:
            raise ValueError("give one managed system: 'scripted' or 'sim', not both")
        return self


class NodeSettings(_Strict):
    """Settings of one node.

    Attributes:
        rate: At most this many cycles per second (C5, B2); default the Utu ``rate``.

    """

    rate: Annotated[float, Field(gt=0, le=10_000)] | None = None


class LaunchConfig(_Strict):
    """A launch file (``anunnaki: launch/1``); see the module docstring."""

    anunnaki: Literal["launch/1"]
    name: str | None = None
    utu: str | dict[str, Any]
    knowledge: str | None = None
    bus: BusConfig | None = None
    nodes: dict[NodeName, NodeSettings | None] = Field(
        default_factory=lambda: dict.fromkeys(NODE_NAMES)
    )
    managed: ManagedConfig = Field(default_factory=ManagedConfig)
    ready_timeout: Annotated[float, Field(gt=0)] = 30.0
    stop_timeout: Annotated[float, Field(gt=0)] = 10.0
    linger: Annotated[float, Field(ge=0)] = 0.5

    @field_validator("nodes", mode="before")
    @classmethod
    def _node_list(cls, nodes: Any) -> Any:
        """Take ``[monitor, analyze]`` as ``{monitor: null, analyze: null}``."""
        if isinstance(nodes, list):
            names = [n for n in nodes if isinstance(n, str)]
            repeated = sorted({n for n in names if names.count(n) > 1})
            if repeated:
                raise ValueError(f"nodes named twice: {', '.join(repeated)}")
            if len(names) != len(nodes):
                raise ValueError(f"give node names ({', '.join(NODE_NAMES)})")
            return dict.fromkeys(names)
        return nodes

    @field_validator("nodes")
    @classmethod
    def _some_nodes(
        cls, nodes: dict[NodeName, NodeSettings | None]
    ) -> dict[NodeName, NodeSettings | None]:
        if not nodes:
            raise ValueError(f"name at least one node ({', '.join(NODE_NAMES)})")
        return nodes


@dataclass(frozen=True)
class Launch:
    """A launch file loaded, resolved and checked.

    Attributes:
        config: The file's content.
        path: The launch file (``None`` for text given in memory).
        utu: The Utu configuration (paths absolute, knowledge override applied).
        parts: Its goal model, binding and tactics, loaded and checked.
        bus: The bus configuration.
        nodes: The nodes to run -> rate (Hz).
        scripted: The scripted managed system (trace path absolute), if any.
        records: The trace's records (empty when not read).
        lines: Where each element of the launch file starts.
        sim: The simulated managed system (paths absolute), if any.

    """

    config: LaunchConfig
    path: Path | None
    utu: UtuConfig
    parts: UtuParts
    bus: BusConfig
    nodes: dict[str, float]
    scripted: ScriptedConfig | None = None
    records: list[Record] = field(default_factory=list)
    lines: LineMap | None = None
    sim: SimConfig | None = None

    @property
    def name(self) -> str:
        """The launch's name (default: the Utu configuration's)."""
        return self.config.name or self.utu.name

    def line_of(self, *path: str | int) -> int | None:
        """The line where the element at ``path`` starts in the launch file."""
        return self.lines.line(path) if self.lines is not None else None

    def error(self, message: str, *path: str | int, hint: str | None = None) -> ModelFileError:
        """A :class:`ModelFileError` located at an element of the launch file."""
        return ModelFileError(
            message,
            path=self.path,
            line=self.line_of(*path),
            element=".".join(str(p) for p in path) or None,
            hint=hint,
        )


class _Prefixed:
    """A pydantic ValidationError seen from an enclosing document (``loc`` prefixed)."""

    def __init__(self, exc: ValidationError, prefix: tuple[str | int, ...]) -> None:
        self._exc = exc
        self._prefix = prefix

    def errors(self, include_url: bool = False) -> list[Any]:
        return [
            {**e, "loc": (*self._prefix, *(p for p in e["loc"] if p != "[key]"))}
            for e in self._exc.errors(include_url=include_url)
        ]


def load_launch(path: str | Path, *, read_records: bool = True) -> Launch:
    """Load a launch file (or a plain Utu configuration, run with every node).

    Args:
        path: The file (``anunnaki: launch/1`` or ``anunnaki: utu/1``).
        read_records: Read and check the scripted system's trace too.

    Raises:
        ModelFileError: Any file is unreadable or invalid; names file and line.

    """
    data, lines = load_yaml(path)
    return _resolve(data, lines, Path(path), read_records=read_records)


def parse_launch(
    text: str, *, source: str = "<launch>", base: Path | None = None, read_records: bool = True
) -> Launch:
    """Parse a launch file from text; paths resolve against ``base`` (default: cwd)."""
    data, lines = load_yaml(source, text=text)
    launch = _resolve(data, lines, (base or Path.cwd()) / "<launch>", read_records=read_records)
    return dataclasses.replace(launch, path=None)


def _resolve(data: Any, lines: LineMap, path: Path, *, read_records: bool) -> Launch:
    where = str(path)
    tag = data.get("anunnaki") if isinstance(data, dict) else None
    if tag == "utu/1":
        data = {"anunnaki": "launch/1", "utu": str(path.resolve())}
        lines = LineMap()
    elif tag != "launch/1":
        raise ModelFileError(
            "not a launch file",
            path=where,
            line=1,
            hint="start it with 'anunnaki: launch/1' (or give a Utu configuration, utu/1)",
        )
    try:
        config = LaunchConfig.model_validate(data)
    except ValidationError as exc:
        raise validation_error(_Prefixed(exc, ()), data, lines, where) from None
    base = path.resolve().parent

    def here(p: str) -> Path:
        q = Path(p).expanduser()
        return q if q.is_absolute() else base / q

    # The Utu configuration: a file, or inline.
    utu_data: Any
    utu_lines: LineMap | None
    utu_where: str
    utu_prefix: tuple[str | int, ...]
    if isinstance(config.utu, str):
        utu_path = here(config.utu)
        utu = load_config(utu_path)
        utu_data, utu_lines = load_yaml(utu_path)
        utu_where, utu_prefix = str(utu_path), ()
    else:
        inline = {**config.utu, "anunnaki": "utu/1"}
        try:
            utu = UtuConfig.model_validate(inline).resolve(base)
        except ValidationError as exc:
            raise validation_error(_Prefixed(exc, ("utu",)), data, lines, where) from None
        utu_data, utu_lines, utu_where, utu_prefix = data, lines, where, ("utu",)
    if config.knowledge is not None:
        kb = config.knowledge
        utu = utu.model_copy(update={"knowledge": kb if kb == ":memory:" else str(here(kb))})

    # The bus: the launch file's, else the Utu configuration's.
    if config.bus is not None:
        bus = config.bus
    else:
        try:
            bus = BusConfig.model_validate(utu.bus)
        except ValidationError as exc:
            raise validation_error(
                _Prefixed(exc, (*utu_prefix, "bus")), utu_data, utu_lines, utu_where
            ) from None

    # Nodes and rates.
    rates: dict[str, float] = {
        n: (s.rate if s is not None and s.rate is not None else utu.rate)
        for n, s in config.nodes.items()
    }
    nodes: dict[str, float] = {n: rates[n] for n in NODE_NAMES if n in rates}  # cycle order

    # The goal model, binding and tactics (B5: fail here, with file and line).
    try:
        parts = load_parts(utu)
    except ModelFileError as exc:
        if exc.element != "failsafe":
            raise
        real, element = describe_path(utu_data, (*utu_prefix, "failsafe"))
        raise ModelFileError(
            exc.message,
            path=utu_where,
            line=utu_lines.line(real) if utu_lines is not None else None,
            element=element,
            hint=exc.hint,
        ) from None

    scripted = config.managed.scripted
    records: list[Record] = []
    if scripted is not None:
        scripted = scripted.model_copy(update={"trace": str(here(scripted.trace))})
        if read_records:
            records = read_trace(scripted.trace).records
            if not records:
                raise ModelFileError(
                    "the trace has no records",
                    path=scripted.trace,
                    hint="record or write some messages",
                )
    sim = config.managed.sim
    if sim is not None:
        sim = sim.model_copy(
            update={
                "scenario": str(here(sim.scenario)),
                "models": str(here(sim.models)) if sim.models is not None else None,
                "report_file": None if sim.report_file is None else str(here(sim.report_file)),
                "plot_file": None if sim.plot_file is None else str(here(sim.plot_file)),
            }
        )
        _check_sim(sim, lines, where)
    return Launch(config, path, utu, parts, bus, nodes, scripted, records, lines, sim)


def _check_sim(sim: SimConfig, lines: LineMap, where: str) -> None:
    """Load the scenario and the registry now, so that errors come before bring-up (B5)."""
    from anunnaki.sim import load_scenario, require_plot_extra

    load_scenario(sim.scenario)
    if sim.plot_file is not None:
        require_plot_extra()
    if sim.models is not None:
        from anunnaki.lec import load_registry

        load_registry(sim.models)
    if sim.oracle is not None:
        from anunnaki.oracles import available_oracles

        name = sim.oracle.get("name", "ground_truth")
        if name not in available_oracles():
            raise ModelFileError(
                f"unknown oracle {name!r}",
                path=where,
                line=lines.line(("managed", "sim", "oracle")),
                element="managed.sim.oracle.name",
                hint=f"known oracles: {', '.join(available_oracles())}",
            )


# -- printing ----------------------------------------------------------------------------------
def _short(value: Any, width: int = 40) -> str:
    text = value if isinstance(value, str) else json.dumps(value, separators=(",", ":"))
    return text if len(text) <= width else text[: width - 1] + "…"


def format_decision(d: Decision, *, t0: float = 0.0) -> str:
    """One line for a decision: time, kind, tactic, detail."""
    detail = " ".join(f"{k}={_short(v)}" for k, v in d.data.items() if v is not None)
    return f"{d.t - t0:9.3f}  {d.kind:<20} {d.tactic or '-':<18} {detail}".rstrip()


class _Printer:
    def __init__(self, out: TextIO, tail: DecisionTail, t0: float) -> None:
        self.out = out
        self.tail = tail
        self.t0 = t0
        self.decisions: list[Decision] = []

    def say(self, text: str) -> None:
        with contextlib.suppress(ValueError, OSError):  # a closed or broken pipe
            self.out.write(text + "\n")
            self.out.flush()

    def poll(self) -> None:
        rows = self.tail.read()
        self.decisions += rows
        for d in rows:
            self.say(format_decision(d, t0=self.t0))


# -- the managed system ------------------------------------------------------------------------
def _drive(
    system: Any,
    stop: threading.Event,
    *,
    speed: float,
    loop: bool,
    until: float | None,
    on_instant: Callable[[float], None] | None = None,
    after_instant: Callable[[int], None] | None = None,
    watched: frozenset[str] = frozenset(),
) -> None:
    """Publish the scripted system's trace live: record time / ``speed`` after the start.

    ``on_instant(t)`` is called before the records of instant ``t`` go out (it moves an
    in-process simulation clock, so no record is taken before its time has come), and
    ``after_instant(n)`` after them, with ``n`` the number of records on ``watched``
    topics (it waits until Utu has taken them: lockstep).
    """
    base = list(system.records)
    instants = system.instants()
    if not instants:
        return
    first = instants[0]
    gap = instants[1] - instants[0] if len(instants) > 1 else 1.0
    span = instants[-1] - first + gap
    wall0 = time.monotonic()
    offset = 0.0
    cursor = 0  # the first record not yet counted for after_instant
    while True:
        for instant in instants:
            t = instant + offset
            if until is not None and t > until:
                return
            delay = wall0 + (t - first) / speed - time.monotonic()
            if (delay > 0 and stop.wait(delay)) or stop.is_set():
                return
            if on_instant is not None:
                on_instant(t)
            system.step(t)
            if after_instant is not None:
                n = 0
                records = system.records
                while cursor < len(records) and records[cursor].t <= t:
                    n += records[cursor].topic in watched
                    cursor += 1
                after_instant(n)
        if not loop:
            return
        offset += span
        system.records.extend(Record(r.t + offset, r.topic, r.msg) for r in base)


# -- lockstep ----------------------------------------------------------------------------------
def _taken_here(nodes: Sequence[UtuNode | ComposedUtu]) -> Callable[[int], bool] | None:
    """In one process: Utu has taken its inputs when its input queues are empty."""
    subs: list[Any] = []
    for node in nodes:
        if isinstance(node, ComposedUtu | MonitorNode):
            subs += node.input_queues()
    if not subs:
        return None
    return lambda n: all(s.pending == 0 for s in subs)


class _InputCounter:
    """Across processes: count the inputs the monitor node has republished."""

    def __init__(self, bus: Bus) -> None:
        self.seen = 0
        self._lock = threading.Lock()
        self.sub = bus.subscribe(topics.MONITOR_INPUT, self._on_batch, queue=1024)

    def _on_batch(self, sample: Any) -> None:
        inputs = sample.message.to_body().get("inputs", [])
        with self._lock:
            self.seen += len(inputs) if isinstance(inputs, list) else 0

    def __call__(self, n: int) -> bool:
        with self._lock:
            return self.seen >= n


class _CycleCounter:
    """Across processes: whether Utu has taken ``n`` inputs and acted on them.

    The analyze node reports the inputs taken so far (``taken`` in its state); with an
    execute node, the cycle that took them must be done too (its actions are out).
    """

    def __init__(self, bus: Bus, *, wait_done: bool) -> None:
        self._lock = threading.Lock()
        self._cycles: list[tuple[int, int]] = []  # (seq, taken) of recent cycles
        self._done = -1
        self._wait_done = wait_done
        self._declared = [bus.subscribe(topics.ANALYSIS, self._on_state, queue=1024)]
        if wait_done:
            self._declared.append(bus.subscribe(topics.CYCLE_DONE, self._on_done, queue=1024))

    def _on_state(self, sample: Any) -> None:
        body = sample.message.to_body()
        seq, taken = body.get("seq"), body.get("taken")
        if isinstance(seq, int) and isinstance(taken, int):
            with self._lock:
                self._cycles.append((seq, taken))
                del self._cycles[:-256]

    def _on_done(self, sample: Any) -> None:
        seq = sample.message.to_body().get("seq")
        if isinstance(seq, int):
            with self._lock:
                self._done = max(self._done, seq)

    def __call__(self, n: int) -> bool:
        with self._lock:
            seq = next((s for s, taken in self._cycles if taken >= n), None)
            return seq is not None and (not self._wait_done or self._done >= seq)


# -- running -----------------------------------------------------------------------------------
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


def child_bus_config(parent: BusConfig, endpoints: Sequence[str], node: str) -> BusConfig:
    """The bus configuration of a node process started by a launch.

    A node joins the launch's session as a zenoh client (the launch's peer or router
    routes between its clients), or, when the launch itself is a client of a router, the
    same router. Endpoints listening on every interface are reached on loopback.
    """
    if parent.mode == "client":
        connect = list(parent.connect)
    else:
        connect = [
            ep.replace("/0.0.0.0:", "/127.0.0.1:").replace("/[::]:", "/[::1]:") for ep in endpoints
        ]
    return BusConfig(
        kind="zenoh",
        mode="client",
        connect=connect,
        tls=parent.tls,
        namespace=parent.namespace,
        name=node,
        zenoh=dict(parent.zenoh),
    )


def _remove_db(path: str) -> None:
    for suffix in ("", "-wal", "-shm"):
        with contextlib.suppress(FileNotFoundError):
            Path(path + suffix).unlink()


def _wait_ready(
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


class _Children:
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
) -> RunResult:
    """Run a launch: nodes (in this process or one process each), then the managed system.

    Args:
        launch: The loaded launch.
        processes: One process per node (``python -m anunnaki.cli.main node NAME``).
        speed: Override the scripted system's speed.
        until: Stop when the scripted trace reaches this time (trace seconds), or, without
            a scripted system, after this many seconds.
        knowledge: Override the knowledge base file.
        fresh: Delete the knowledge base file first (otherwise an existing one is resumed).
        stop: Set it to stop the run (signals set it too).
        out: Where to print (default stdout).
        err: Where the nodes' error output goes (default stderr).
        handle_signals: Turn SIGINT/SIGTERM into a clean stop (main thread only).
        on_bus: Called with the launch's bus once it is open, before any node starts (e.g.
            to attach a dashboard); what it declares on the bus closes with the bus.

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
    )
    if not handle_signals:
        return runner.run()
    with signals_to(stop):
        return runner.run()


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
    ) -> None:
        self.launch = launch
        self.on_bus = on_bus
        self.processes = processes
        self.scripted = launch.scripted
        self.sim = launch.sim
        default_speed = (
            self.scripted.speed if self.scripted else self.sim.speed if self.sim else 1.0
        )
        self.speed = speed if speed is not None else default_speed
        self.simulated: Any = None  # the SimulatedSystem, while it runs
        if not self.speed > 0:
            raise LaunchError(f"speed must be > 0, got {self.speed!r}")
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
            _remove_db(kb)
        self.utu = launch.utu.model_copy(update={"knowledge": kb})
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
        for w in launch.parts.warnings:
            self.say(f"warning: {w.render()}")
        if self.scripted is not None:
            if utu.clock == "wall" and self.speed != 1:
                self.say(
                    f"note: speed {self.speed:g}× on the wall clock: rates and staleness are "
                    "measured in real time; use clock: sim and publish_clock: true"
                )
            if utu.clock == "sim" and not self.scripted.publish_clock:
                self.say(
                    "note: clock: sim but the scripted system does not publish /clock "
                    "(publish_clock: true); Utu's time will not advance unless a simulator "
                    "publishes it"
                )

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
        on_instant: Callable[[float], None] | None = None,
        taken: Callable[[int], bool] | None = None,
    ) -> tuple[Any, threading.Thread] | None:
        """Start the scripted system in a thread.

        ``on_instant(t)`` runs before an instant's records go out; ``taken(n)`` tells
        whether Utu has taken ``n`` inputs so far (lockstep).
        """
        if self.sim is not None:
            return self._start_sim(bus, on_instant)
        sc = self.scripted
        if sc is None:
            return None
        from anunnaki.managed import ScriptedSystem

        system = ScriptedSystem(
            bus,
            list(self.launch.records),
            prefix=sc.prefix,
            status_topic=sc.status_topic,
            modes=tuple(sc.modes),
            publish_clock=sc.publish_clock,
        )
        recs = self.launch.records
        self.say(
            f"managed: scripted {sc.prefix} from {sc.trace} ({len(recs)} records, "
            f"t {recs[0].t:g}–{recs[-1].t:g} s) at {self.speed:g}× "
            + ("looping" if sc.loop else "once")
            + (", in lockstep with Utu" if sc.sync else "")
        )

        total = 0
        late = 0

        def after(n: int) -> None:
            nonlocal total, late
            total += n
            if taken is None or not n:
                return
            deadline = time.monotonic() + sc.sync_timeout
            while not taken(total) and not self.stop.is_set():
                if time.monotonic() > deadline:
                    late += 1
                    if late == 1:
                        log.warning(
                            "sync: Utu did not take the messages of an instant within "
                            "%.1f s; the replay goes on without waiting for it",
                            sc.sync_timeout,
                        )
                    return
                self.stop.wait(0.0005)

        watched = frozenset(
            tb.topic for agent in self.parts.model.agents.values() for tb in agent.topics
        )

        def drive() -> None:
            try:
                _drive(
                    system,
                    self.stop,
                    speed=self.speed,
                    loop=sc.loop,
                    until=self.until,
                    on_instant=on_instant,
                    after_instant=after if sc.sync else None,
                    watched=watched,
                )
            except AnunnakiError as exc:
                if not self.stop.is_set():
                    log.warning("scripted system stopped: %s", exc)
            except Exception:  # a bug: say so; the run then ends as after the trace
                log.exception("the scripted system failed")

        thread = threading.Thread(target=drive, name="anunnaki-scripted", daemon=True)
        thread.start()
        return system, thread

    def _start_sim(
        self, bus: Bus, on_time: Callable[[float], None] | None
    ) -> tuple[Any, threading.Thread]:
        """Start the simulated platform, its detector and its oracle; run it in a thread."""
        from anunnaki.managed import SimulatedSystem

        cfg = self.sim
        assert cfg is not None
        system = SimulatedSystem(
            bus,
            cfg.scenario,
            models=cfg.models,
            oracle=cfg.oracle,
            lockstep=cfg.lockstep,
            on_time=on_time,
        )
        self.simulated = system
        sc = system.scenario
        end = sc.duration if self.until is None else self.until
        active = system.lec.active.id if system.lec is not None else "no detector"
        oracle = system.oracle.oracle.name if system.oracle is not None else "no oracle"
        self.say(
            f"managed: simulated {sc.platform} '{sc.name}' from {cfg.scenario} "
            f"(t 0–{end:g} s) at {self.speed:g}×"
            + (", in lockstep with the detector" if cfg.lockstep and system.lec else "")
            + f"; detector {active}; oracle {oracle}"
        )

        def drive() -> None:
            try:
                system.run(self.stop, speed=self.speed, until=end)
            except Exception:  # a bug: say so; the run then ends as after the scenario
                log.exception("the simulation failed")

        thread = threading.Thread(target=drive, name="anunnaki-sim", daemon=True)
        thread.start()
        return system, thread

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
                    why = (
                        ("scenario ended" if self.sim is not None else "trace ended")
                        if self.until is None
                        else f"reached t={self.until:g}"
                    )
                    return 0, why
            if driver is None and self.until is not None and now - started >= self.until:
                return 0, f"ran {self.until:g} s"
            self.stop.wait(0.05)

    def _clock_publisher(self, bus: Bus) -> Callable[[float], None] | None:
        """Publish the simulation time before each instant, ahead of the instant's records.

        The scripted system publishes ``/clock`` at normal priority; assessments travel at
        high priority and could overtake it. Published here at high priority first, the
        time of an instant always reaches a node before the instant's messages.
        """
        if self.scripted is None or not self.scripted.publish_clock:
            return None
        pub = bus.publisher(self.utu.clock_topic, priority="high")

        def publish(t: float) -> None:
            pub.put(Clock(time=max(t, 0.0)))

        return publish

    def _finish(self, printer: _Printer, code: int, reason: str, ran: float) -> None:
        printer.poll()
        self.say(f"stopped ({reason}): {len(printer.decisions)} decisions in {ran:.2f} s")
        system = self.simulated
        if system is not None and self.sim is not None and self.sim.report:
            from anunnaki.managed import format_phases

            platform = system.platform
            self.say(
                f"\nsimulated {platform.t:.1f} s in {ran:.1f} s wall "
                f"({platform.frames} frames, {platform.frames / max(ran, 1e-9):.1f} frames/s); "
                "per phase:"
            )
            self.say(format_phases(system.phases(printer.decisions)))
        if (
            system is not None
            and self.sim is not None
            and (self.sim.report_file or self.sim.plot_file)
        ):
            from anunnaki.sim import save_run

            try:  # a file that cannot be written is said, never fatal: the run is over
                save_run(
                    system.report(printer.decisions),
                    report=self.sim.report_file,
                    plot=self.sim.plot_file,
                    say=self.say,
                )
            except (OSError, AnunnakiError) as exc:
                self.say(f"report: not written: {exc}")

    # -- one process
    def _run_here(self) -> RunResult:
        launch = self.launch
        clock_t0 = 0.0
        bus = open_bus(launch.bus, name=f"{launch.name}-launch")
        if self.on_bus is not None:
            self.on_bus(bus)
        nodes: list[UtuNode | ComposedUtu] = []
        threads: list[threading.Thread] = []
        halt = threading.Event()
        crashed: list[str] = []
        managed = None
        kb: Knowledge | None = None
        try:
            all_five = set(launch.nodes) == set(NODE_NAMES)
            mode = (
                "5 nodes in one process (the composed manager)"
                if all_five
                else f"{len(launch.nodes)} nodes in one process"
            )
            self._header(mode, bus)
            kb = open_knowledge(self.kb_path)
            self._resuming(kb)
            tail = DecisionTail(kb)
            # On sim time the scripted system moves the clock itself, in order with its
            # records (a clock fed from the bus arrives on another thread: racy).
            sim = SimClock() if self.utu.clock == "sim" else None
            if all_five:
                nodes.append(
                    ComposedUtu(self.parts, bus=bus, knowledge=kb, clock=sim, rates=launch.nodes)
                )
            else:
                for name, rate in launch.nodes.items():
                    nodes.append(
                        build_node(name, self.parts, bus=bus, knowledge=kb, clock=sim, rate=rate)
                    )
            for node in nodes:

                def spin(node: UtuNode | ComposedUtu = node) -> None:
                    try:
                        node.spin(halt)
                    except Exception as exc:
                        log.exception("a node failed")
                        crashed.append(f"a node failed: {type(exc).__name__}: {exc}")

                t = threading.Thread(target=spin, name="anunnaki-node", daemon=True)
                t.start()
                threads.append(t)
            _wait_ready(
                bus, list(launch.nodes), timeout=launch.config.ready_timeout, stop=self.stop
            )
            ready_after = time.monotonic() - self.t_start
            self.say(f"ready: {', '.join(launch.nodes)} after {ready_after:.2f} s")
            if self.utu.clock == "wall":
                clock_t0 = time.time()
            printer = _Printer(self.out, tail, clock_t0)
            t_run = time.monotonic()
            managed = self._start_managed(
                bus, sim.update if sim is not None else None, _taken_here(nodes)
            )
            code, reason = self._watch(
                printer, managed[1] if managed else None, lambda: crashed[0] if crashed else ""
            )
            self.stop.set()
            if managed is not None:
                managed[1].join(timeout=5.0)
            halt.set()
            for node in nodes:
                node.wake()
            for t in threads:
                t.join(timeout=5.0)
            ran = time.monotonic() - t_run
            self._finish(printer, code, reason, ran)
            pid = os.getpid()
            return RunResult(
                code, reason, printer.decisions, ready_after, ran, dict.fromkeys(launch.nodes, pid)
            )
        finally:
            self.stop.set()
            halt.set()
            for node in nodes:
                node.wake()
            for t in threads:
                t.join(timeout=5.0)
            if managed is not None:
                managed[0].close()
            for node in reversed(nodes):
                node.close()
            if kb is not None:
                with contextlib.suppress(sqlite3.Error):  # the manager may have closed it
                    kb.close()
            bus.close()

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
        ]

    def _run_processes(self) -> RunResult:
        launch = self.launch
        parent_config = launch.bus
        if parent_config.kind == "inproc":
            parent_config = BusConfig(kind="zenoh", namespace=parent_config.namespace)
        bus = open_bus(parent_config, name=f"{launch.name}-launch")
        if self.on_bus is not None:
            self.on_bus(bus)
        children = _Children(self.out, self.err)
        managed = None
        kb: Knowledge | None = None
        try:
            self._header(f"{len(launch.nodes)} nodes, one process each", bus)
            if launch.bus.kind == "inproc":
                self.say("note: bus kind inproc cannot cross processes; using zenoh on loopback")
            # Create the knowledge base before the nodes open it together.
            kb = open_knowledge(self.kb_path)
            self._resuming(kb)
            tail = DecisionTail(kb)
            taken: Callable[[int], bool] | None = None
            if "analyze" in launch.nodes:
                taken = _CycleCounter(bus, wait_done="execute" in launch.nodes)
            elif "monitor" in launch.nodes:
                taken = _InputCounter(bus)
            for name in launch.nodes:
                config = child_bus_config(parent_config, bus.endpoints, f"{launch.name}-{name}")
                proc = children.start(name, self._node_argv(name, config))
                self.say(f"node {name}: pid {proc.pid}")
            _wait_ready(
                bus,
                list(launch.nodes),
                timeout=launch.config.ready_timeout,
                stop=self.stop,
                procs=children.procs,
            )
            ready_after = time.monotonic() - self.t_start
            self.say(f"ready: {', '.join(launch.nodes)} after {ready_after:.2f} s")
            clock_t0 = time.time() if self.utu.clock == "wall" else 0.0
            printer = _Printer(self.out, tail, clock_t0)
            t_run = time.monotonic()
            managed = self._start_managed(bus, self._clock_publisher(bus), taken)

            def failed() -> str:
                dead = children.died()
                return (
                    ", ".join(f"node {n} exited with code {rc}" for n, rc in dead) if dead else ""
                )

            code, reason = self._watch(printer, managed[1] if managed else None, failed)
            self.stop.set()
            if managed is not None:
                managed[1].join(timeout=5.0)
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
            children.stop(launch.config.stop_timeout)
            if managed is not None:
                managed[0].close()
            if kb is not None:
                kb.close()
            bus.close()
