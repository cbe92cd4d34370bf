"""Failing safe under faults and hostile input (issue #12): kill -9, a flood, a hostile corpus.

Everything runs on loopback with the rover example's goal model, binding and tactics
(``examples/rover``) on the wall clock, against a platform played by this process: a
:class:`~anunnaki.managed.ScriptedSystem` that replays a nominal trace live (status, camera
info, ultrasonic and the oracle's category 0, 20 Hz each; every message carries a serial
``n``) and stamps, with ``time.perf_counter``, the first fail-safe command that arrives: a
``/rover/set_mode`` request for ``manual``, a ``/rover/stop`` request or a ``/utu/run_stop``
message. Its own liveliness guard (``stop_without_utu``) is replaced by one that only stamps
when it would have stopped the platform (``guard_ms``), so that what Utu sends is measured.

Kill matrix (``kill_trials``)
    * ``processes``: ``anunnaki run LAUNCH --processes`` (a launch file without a managed
      system, its bus a zenoh peer that joins the platform's session: the platform runs
      first, as a robot would); once
      Utu reports the rover nominal, wait one of three delays (0.2, 0.9, 1.6 s) and
      ``kill -9`` one node process (``monitor``, ``analyze``, ``plan``, ``execute``,
      ``knowledge``: the pid the launch prints; ``launch_ended_ms`` says whether and when
      the launch then ended by itself);
    * ``one-process``: ``anunnaki run LAUNCH`` (the composed manager), ``kill -9`` of that
      process (victim ``manager``);
    * ``by-hand``: the five nodes started by hand (``anunnaki node NAME --config LAUNCH``,
      no launch supervising them), ``kill -9`` of one: a survivor must run-stop the
      platform;
    * ``loop``: the whole loop of ``examples/rover/sim.yaml`` taken apart so that each part
      can be killed alone: Utu (``anunnaki run``, the composed manager, goals-lm/binding-lm/
      tactics-lm, sim clock), the LEC/model manager (``LecNode``, ``/lm_manager``) and the
      ground-truth oracle node each in a process of their own (this script with
      ``--serve lec|oracle``), and the simulated rover of ``demo-scenario.yaml`` in this
      process, its ``/rover/set_mode`` and ``/rover/stop`` handlers stamped. Once Utu sees
      G3 and G18 satisfied, ``kill -9`` of the LEC (victim ``lec``) or the oracle
      (``oracle``). Inputs are not counted here (the simulator's messages carry no serial).

    Per trial: ``failsafe_ms``, kill to the fail-safe command arriving at the platform
    (``null``: none within ``--deadline`` seconds); ``lost``, inputs plus decisions lost:
    platform messages on the monitored topics published from 0.5 s after Utu was ready to
    0.3 s before the kill that the knowledge base does not hold (by ``n``), plus decisions
    the launch printed that it does not hold; ``replay_identical``, ``anunnaki.utu.replay``
    of the knowledge base after the run (``false`` also when it cannot be replayed, with
    the reason); ``platform_stops`` (kill matrix), the ``/rover/stop`` requests the platform
    received until its guard's time (nodes by hand print no decisions: their ``lost``
    counts inputs only).

Flood (``flood``)
    The composed manager spinning (20 Hz, wall clock, its knowledge base in a temporary
    file as ``anunnaki run`` keeps it) on the in-process bus with the platform nominal,
    then 50,000 messages a second (``--flood-rate``) on ``/rover/ultrasonic`` for 10 s
    (``--flood-seconds``; 3 s with ``--quick``) from another thread. ``max_cycle_gap_ms``
    is the longest time between the starts of two manager steps during the flood,
    ``period_ms`` the step period, ``max_step_ms`` the longest step and
    ``max_step_cpu_ms`` the time its thread ran in it; ``rss_mb_before`` is this
    process's resident memory before the flood, ``rss_mb_after`` 2 s after it (after a
    ``gc.collect()``).

Hostile corpus (``corpus``)
    Every message of ``tests/utu/hostile_cycle.py`` (forged, type-valid cycle messages) and
    six malformed payloads on each of Utu's internal topics (not JSON, cut short, an unknown
    type, an unknown version, an invalid body, NaN), sent one by one to a live Utu — the five
    node classes each spinning on a thread (the wiring of ``--processes``, in one process so
    that their counters can be read), then the composed manager — with the platform nominal;
    then all at once over zenoh to ``anunnaki run --processes`` (refusals not counted there).
    ``refused``: messages after which Utu's own counters moved (the bus's ``malformed``, the
    nodes' ``foreign``) within 0.2 s (the composed manager does not subscribe Utu's internal
    topics: nothing there is delivered, or counted); ``tracebacks``: log records with an exception;
    ``loop_deaths``: spin threads that ended or nodes that stopped answering readiness;
    ``steered``: decisions the corpus caused (a nominal run makes none).

Aims (issue #12): fail-safe at the platform within 250 ms of the kill in 100 % of trials;
0 lost; replay identical in 100 %; under the flood the longest cycle gap at most 2 periods
and memory back within 10 %; 0 tracebacks and 0 loop deaths for the corpus.

    .venv/bin/python benchmarks/faults.py            # full, about 10 minutes
    .venv/bin/python benchmarks/faults.py --quick    # one trial per victim, 3 s flood
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import functools
import gc
import inspect
import itertools
import json
import logging
import math
import os
import platform
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
# tests/utu/hostile_cycle.py: the forged-message corpus
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "utu"))

from anunnaki import topics
from anunnaki.bus import Bus, BusTimeout, InprocHub, LivelinessGuard, open_bus
from anunnaki.bus._zenoh import free_port
from anunnaki.managed import ScriptedSystem
from anunnaki.messages import Generic
from anunnaki.trace import Record
from anunnaki.utu import (
    NODE_NAMES,
    AutonomicManager,
    RunLogError,
    build_node,
    load_parts,
    parse_config,
    replay,
)
from anunnaki.utu.runlog import open_run

ROOT = Path(__file__).resolve().parents[1]
ROVER = ROOT / "examples" / "rover"
DEFAULT_OUTPUT = Path(__file__).parent / "results" / "faults.json"
AIMS = {
    "failsafe_ms": 250.0,
    "lost": 0,
    "replay_identical_share": 1.0,
    "max_cycle_gap_periods": 2.0,
    "rss_back_within": 0.10,
    "tracebacks": 0,
    "loop_deaths": 0,
}
RATE = 20  # Hz: the platform's messages per topic
MONITORED = ("/rover/status", "/rover/camera/info", "/rover/ultrasonic", "/utu/oracle/output")
KILL_DELAYS = (0.2, 0.9, 1.6)  # s after Utu first reports the rover nominal
WARM = 2.0  # s of platform messages taken by a running Utu before a kill
DIM_FROM = 1.5  # s: the oracle reports dim light (category 1) from then on: a hand-over
LISTENING = 0.5  # s after Utu is ready: from then on every monitored message must be stored
#: The platforms' own guard (``stop_without_utu``), as the scripted and simulated systems use it.
GUARD: float = inspect.signature(ScriptedSystem.__init__).parameters["stop_without_utu"].default
INPUT_MARGIN = 0.3  # s: inputs published this long before the kill must be in knowledge
COUNTED = 0.2  # s: how long a corpus message may take to move Utu's counters
NODE_RATES = {"monitor": 50, "analyze": 20, "plan": 20, "execute": 20, "knowledge": 10}

log = logging.getLogger("faults")

UTU_CONFIG = """\
anunnaki: utu/1
name: rover
goal_model: {rover}/goals.yaml
binding: {rover}/binding.yaml
tactics: {rover}/tactics.yaml
clock: wall
warmup: 1.0
failsafe: fail-safe
run_stop: {{service: /rover/stop}}
"""


# -- the platform ------------------------------------------------------------------------------
def nominal_trace(seconds: float, *, dim_from: float | None = None) -> list[Record]:
    """Status, camera info, ultrasonic and the oracle's category, ``RATE`` Hz, serial ``n``.

    The category is 0, or 1 (dim light: the fail-safe hands the rover over to manual mode)
    from ``dim_from`` on.
    """
    out: list[Record] = []
    n = 0
    for i in range(round(seconds * RATE) + 1):
        t = i / RATE
        category = 1 if dim_from is not None and t >= dim_from else 0
        for topic, msg in (
            ("/rover/status", {"mode": "autonomous", "buzzer": False, "bumper": False}),
            ("/rover/camera/info", {"seq": i, "width": 128, "height": 128}),
            ("/rover/ultrasonic", {"range": 3.0}),
            ("/utu/oracle/output", {"category": category, "confidence": 0.9}),
        ):
            out.append(Record(t, topic, {**msg, "n": n}))
            n += 1
    return out


class Platform(ScriptedSystem):
    """The scripted rover; stamps the first fail-safe command and when its guard would fire."""

    def __init__(self, bus: Bus, trace: list[Record]) -> None:
        super().__init__(bus, trace, stop_without_utu=None)
        self.failsafe = threading.Event()
        self.failsafe_at: float | None = None
        self.failsafe_what = ""
        self.guard_at: float | None = None
        self.commands_seen: list[tuple[str, dict[str, Any]]] = []
        self.started_at: float | None = None
        self._declared.append(bus.subscribe(topics.RUN_STOP, self._run_stop_heard, queue=16))
        self._declared.append(LivelinessGuard(bus, self._guard, timeout=GUARD))

    def arm(self) -> None:
        """Forget earlier commands: stamp the next fail-safe command from now on."""
        self.failsafe_at = None
        self.failsafe_what = ""
        self.failsafe.clear()

    def _stamp(self, what: str) -> None:
        if self.failsafe_at is None:
            self.failsafe_at = time.perf_counter()
            self.failsafe_what = what
            self.failsafe.set()

    def _set_mode(self, message: Any) -> dict[str, Any]:
        reply = super()._set_mode(message)
        body = message.to_body() if hasattr(message, "to_body") else dict(message)
        self.commands_seen.append(("set_mode", body))
        if body.get("mode") == "manual":
            self._stamp("set_mode manual")
        return reply

    def _stop(self, message: Any) -> dict[str, Any]:
        reply = super()._stop(message)
        self.commands_seen.append(("stop", {}))
        self._stamp("stop")
        return reply

    def _run_stop_heard(self, sample: Any) -> None:
        self._stamp("/utu/run_stop")

    def _guard(self, why: str) -> None:
        if self.guard_at is None:
            self.guard_at = time.perf_counter()

    def run_live(self, stop: threading.Event) -> threading.Thread:
        """Replay the trace live on a thread; :attr:`started_at` is its wall start."""
        self.started_at = time.monotonic()
        start = self.started_at
        thread = threading.Thread(
            target=self.run, args=(stop,), kwargs={"start": start}, daemon=True
        )
        thread.start()
        return thread

    def ran(self, seconds: float) -> bool:
        """Whether it has been replaying for ``seconds``."""
        return self.started_at is not None and time.monotonic() - self.started_at >= seconds

    def published_between(self, first: float, last: float) -> set[int]:
        """Serials of monitored messages due from ``first`` to ``last`` (``time.monotonic``)."""
        assert self.started_at is not None
        lo, hi = first - self.started_at, last - self.started_at
        return {r.msg["n"] for r in self.records if lo <= r.t <= hi and r.topic in MONITORED}


def _state(bus: Bus) -> dict[str, Any] | None:
    try:
        reply = bus.request(topics.QUERY, {"what": "state"}, timeout=1.0)
    except BusTimeout:
        return None
    return reply.data if isinstance(reply, Generic) else None


def nominal(state: dict[str, Any] | None) -> bool:
    """Utu sees the rover autonomous and every goal satisfied, warm-up over."""
    if not state or state.get("warming_up"):
        return False
    nodes = state.get("nodes") or {}
    return all((nodes.get(g) or [None, None])[1] == "satisfied" for g in ("G1", "G3", "G4"))


def handed_over(rover: Platform, bus: Bus) -> bool:
    """The fail-safe has put the rover in manual mode and Utu sees G3 satisfied again."""
    if rover.state().get("mode") != "manual":
        return False
    state = _state(bus)
    g3 = ((state or {}).get("nodes") or {}).get("G3") or [None, None]
    g3_status: object = g3[1]
    return g3_status == "satisfied"


def wait_until(predicate: Callable[[], Any], timeout: float, pause: float = 0.05) -> Any:
    """Poll ``predicate`` until it is truthy (returned) or ``timeout`` passes (``None``)."""
    deadline = time.monotonic() + timeout
    gate = threading.Event()
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            return None
        gate.wait(pause)


# -- the kill matrix ---------------------------------------------------------------------------
def write_launch(tmp: Path, platform: str) -> Path:
    """A launch file of the rover's Utu (no managed system) joining the platform's session."""
    (tmp / "utu.yaml").write_text(UTU_CONFIG.format(rover=ROVER))
    nodes = "".join(f"  {n}: {{rate: {r}}}\n" for n, r in NODE_RATES.items())
    text = (
        "anunnaki: launch/1\nname: rover\nutu: utu.yaml\n"
        f"bus: {{kind: zenoh, mode: peer, connect: [{platform}]}}\n"
        f"nodes:\n{nodes}ready_timeout: 60\nstop_timeout: 5\n"
    )
    path = tmp / "launch.yaml"
    path.write_text(text)
    return path


def _child(argv: list[str]) -> subprocess.Popen[str]:
    """A child process of this script, its output merged and read as text."""
    return subprocess.Popen(
        argv,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        stdin=subprocess.DEVNULL,
        text=True,
        cwd=ROOT,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
        start_new_session=True,
    )


@dataclass
class Launch:
    """``anunnaki run`` in a child process; its output read on a thread."""

    argv: list[str]
    lines: list[str] = field(default_factory=list)
    proc: subprocess.Popen[str] | None = None
    ended_at: float | None = None  # time.perf_counter() when the process ended

    def start(self) -> None:
        self.proc = _child(self.argv)
        threading.Thread(target=self._read, daemon=True).start()
        threading.Thread(target=self._wait, daemon=True).start()

    def _wait(self) -> None:
        assert self.proc is not None
        self.proc.wait()
        self.ended_at = time.perf_counter()

    def _read(self) -> None:
        assert self.proc is not None and self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))

    def pids(self) -> dict[str, int]:
        found = (re.match(r"node (\w+): pid (\d+)$", ln) for ln in self.lines)
        return {m.group(1): int(m.group(2)) for m in found if m}

    def pid(self) -> int:
        assert self.proc is not None, "start() first"
        return self.proc.pid

    def said(self, line: str) -> bool:
        """Whether the child printed exactly ``line``."""
        return line in self.lines

    def ready(self) -> bool:
        if any(ln.startswith("ready:") for ln in self.lines):
            return True
        if self.proc is not None and self.proc.poll() is not None:
            raise RuntimeError("the launch ended before it was ready:\n" + self.tail())
        return False

    def printed(self) -> list[tuple[float, str, str]]:
        """The decisions it printed: (t, kind, tactic)."""
        out = []
        for ln in self.lines:
            m = re.match(r"\s+(-?\d+\.\d{3})  (\S+)\s+(\S*)", ln)
            if m:
                out.append((float(m.group(1)), m.group(2), m.group(3)))
        return out

    def tracebacks(self) -> int:
        """How many tracebacks it (or its nodes) printed."""
        return sum(1 for ln in self.lines if "Traceback (most recent call last)" in ln)

    def tail(self, n: int = 40) -> str:
        return "\n".join(self.lines[-n:])

    def stop(self) -> None:
        if self.proc is None:
            return
        if self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(timeout=10)
        # node processes left behind by a killed launch see their stdin close and exit


class HandNodes(Launch):
    """The five nodes started by hand (``anunnaki node``, no launch), output merged.

    Shaped like :class:`Launch` for the kill trial: ``pids``, ``ready``, ``tracebacks``;
    nothing prints decisions (``printed`` is empty), and ``ended_at`` stays ``None`` (the
    survivors keep running, run-stopped).
    """

    def __init__(self, launch: Path, db: Path) -> None:
        super().__init__([])
        self.procs: dict[str, subprocess.Popen[str]] = {}
        self.launch_path, self.db = launch, db

    def start(self) -> None:
        for name in NODE_NAMES:
            argv = [sys.executable, "-m", "anunnaki.cli.main", "node", name]
            argv += ["--config", str(self.launch_path), "--knowledge", str(self.db)]
            argv += ["--rate", str(NODE_RATES[name])]
            if name == "analyze":
                argv += ["--expect", "plan,execute"]
            self.procs[name] = proc = _child(argv)
            threading.Thread(target=self._read_node, args=(proc,), daemon=True).start()

    def _read_node(self, proc: subprocess.Popen[str]) -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            self.lines.append(line.rstrip("\n"))

    def pids(self) -> dict[str, int]:
        return {n: p.pid for n, p in self.procs.items()}

    def ready(self) -> bool:
        up = {m.group(1) for ln in self.lines if (m := re.match(r"node (\w+) ready", ln))}
        if up >= set(NODE_NAMES):
            return True
        dead = [n for n, p in self.procs.items() if p.poll() is not None]
        if dead:
            raise RuntimeError(f"node {dead[0]} ended before it was ready:\n" + self.tail())
        return False

    def printed(self) -> list[tuple[float, str, str]]:
        return []

    def stop(self) -> None:
        for proc in self.procs.values():
            if proc.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    proc.send_signal(signal.SIGTERM)
        for proc in self.procs.values():
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=10)


def _printed_not_stored(printed: list[tuple[float, str, str]], db: Path, t0: float) -> int:
    with contextlib.closing(open_run(db)) as kb:
        stored = [(round(d.t - t0, 3), d.kind, d.tactic or "-") for d in kb.decisions()]
    missing = 0
    pool = list(stored)
    for entry in printed:
        match = next((s for s in pool if s[1:] == entry[1:] and abs(s[0] - entry[0]) < 2e-3), None)
        if match is None:
            missing += 1
        else:
            pool.remove(match)
    return missing


def _stored_serials(db: Path) -> set[int]:
    with contextlib.closing(open_run(db)) as kb:
        return {
            r.msg["n"] for r in kb.inputs() if r.topic in MONITORED and isinstance(r.msg, dict)
            and isinstance(r.msg.get("n"), int)
        }  # fmt: skip


def _replay(db: Path) -> tuple[bool, str]:
    try:
        report = replay(db)
    except RunLogError as exc:
        return False, f"cannot replay: {exc}"
    if report.identical:
        return True, ""
    first = report.divergence or report.verdict_divergence
    detail = first.render(limit=3) if first is not None else ""
    return False, f"{report.summary()}: {detail}"


def _utu_launch(tmp: Path, platform: str, deployment: str) -> tuple[Launch, Path]:
    db = tmp / "kb.db"
    if deployment == "by-hand":
        return HandNodes(write_launch(tmp, platform), db), db
    argv = [sys.executable, "-m", "anunnaki.cli.main", "run", str(write_launch(tmp, platform))]
    argv += ["--knowledge", str(db), "--until", "120"]
    if deployment == "processes":
        argv.append("--processes")
    return Launch(argv), db


def kill_trial(deployment: str, victim: str, delay: float, deadline: float) -> dict[str, Any]:
    """One kill -9 of ``victim`` in ``deployment`` (``processes``, ``one-process``, ``by-hand``).

    The platform runs first (as a robot would) and Utu joins its zenoh session.
    """
    trial: dict[str, Any] = {"deployment": deployment, "victim": victim, "delay_s": delay}
    stop = threading.Event()
    with (
        tempfile.TemporaryDirectory(prefix="faults-") as tmp_name,
        open_bus("zenoh", name="platform") as bus,
    ):
        rover = Platform(bus, nominal_trace(90.0, dim_from=DIM_FROM))
        launch, db = _utu_launch(Path(tmp_name), bus.endpoints[0], deployment)
        try:
            rover.run_live(stop)
            launch.start()
            if not wait_until(launch.ready, 90):
                raise RuntimeError("not ready in 90 s:\n" + launch.tail())
            listening = time.monotonic() + LISTENING
            settled = listening + WARM  # Utu has taken WARM s of the platform's messages
            if not wait_until(
                lambda: time.monotonic() >= settled and handed_over(rover, bus), 30, 0.1
            ):
                raise RuntimeError("no hand-over to manual mode:\n" + launch.tail())
            rover.arm()
            threading.Event().wait(delay)
            pid = launch.pids()[victim] if deployment != "one-process" else launch.pid()
            killed_mono = time.monotonic()
            killed = time.perf_counter()
            os.kill(pid, signal.SIGKILL)
            rover.failsafe.wait(deadline)
            wait_until(lambda: rover.guard_at is not None, 2.0)
            ended = launch.ended_at  # by itself, before this script stops it
            # Before the survivors are stopped (nodes by hand run-stop on each departure).
            stops = sum(1 for c in rover.commands if c[1] == "stop")
            stop.set()
            launch.stop()
            trial |= _trial_figures(rover, launch, db, killed, (listening, killed_mono))
            trial["launch_ended_ms"] = None if ended is None else round((ended - killed) * 1e3, 1)
            trial["platform_stops"] = stops
        finally:
            stop.set()
            launch.stop()
            rover.close()
    return trial


def _trial_figures(
    rover: Platform, launch: Launch, db: Path, killed: float, window: tuple[float, float]
) -> dict[str, Any]:
    def ms(at: float | None) -> float | None:
        return None if at is None else round((at - killed) * 1000, 1)

    out: dict[str, Any] = {
        "failsafe_ms": ms(rover.failsafe_at),
        "failsafe_command": rover.failsafe_what or None,
        "guard_ms": ms(rover.guard_at),
        "tracebacks": launch.tracebacks(),
    }
    if not db.exists():
        return out | {"lost": None, "replay_identical": False, "note": "no knowledge file"}
    published = rover.published_between(window[0], window[1] - INPUT_MARGIN)
    lost_inputs = len(published - _stored_serials(db))
    with contextlib.closing(open_run(db)) as kb:
        first = next(iter(kb.decisions()), None)
    t0 = _t0(launch, first)
    lost_decisions = _printed_not_stored(launch.printed(), db, t0)
    identical, why = _replay(db)
    out |= {
        "lost": lost_inputs + lost_decisions,
        "lost_inputs": lost_inputs,
        "lost_decisions": lost_decisions,
        "inputs_expected": len(published),
        "decisions_printed": len(launch.printed()),
        "replay_identical": identical,
    }
    if why:
        out["replay_note"] = why[:900]
    return out


def _t0(launch: Launch, first: Any) -> float:
    """The launch prints wall-clock decisions relative to its start: find that offset."""
    printed = launch.printed()
    if first is None or not printed:
        return 0.0
    return float(first.t) - printed[0][0]


# -- the whole loop: the LEC/model manager and the oracle in processes of their own ------------
SIM_LAUNCH = """\
anunnaki: launch/1
name: rover-sim
utu:
  goal_model: {rover}/goals-lm.yaml
  binding: {rover}/binding-lm.yaml
  tactics: {rover}/tactics-lm.yaml
  clock: sim
  warmup: 3.0
  failsafe: fail-safe
  run_stop: {{service: /rover/stop}}
bus: {{kind: zenoh, mode: peer, listen: [tcp/127.0.0.1:{port}]}}
ready_timeout: 60
"""
MODELS = ROOT / "examples" / "models" / "rover.yaml"
SCENARIO = ROVER / "demo-scenario.yaml"
CAMERA = "/rover/camera/image"


class _StampingBus:
    """A bus whose ``/set_mode`` and ``/stop`` service handlers tell ``on_command`` first."""

    def __init__(self, bus: Bus, on_command: Callable[[str, Any], None]) -> None:
        self._bus = bus
        self._on_command = on_command

    def service(self, name: str, handler: Callable[[Any], Any], **kw: Any) -> Any:
        if name.endswith(("/set_mode", "/stop")):

            def stamped(message: Any) -> Any:
                self._on_command(name, message)
                return handler(message)

            return self._bus.service(name, stamped, **kw)
        return self._bus.service(name, handler, **kw)

    def __getattr__(self, attr: str) -> Any:
        return getattr(self._bus, attr)


class _Commands:
    """The fail-safe commands that reach the simulated platform, stamped once armed."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self.at: float | None = None
        self.what = ""
        self.armed = False

    def __call__(self, service: str, message: Any) -> None:
        body = message.to_body() if hasattr(message, "to_body") else dict(message or {})
        manual = service.endswith("/set_mode") and body.get("mode") == "manual"
        if self.armed and self.at is None and (manual or service.endswith("/stop")):
            self.at = time.perf_counter()
            self.what = "set_mode manual" if manual else "stop"
            self.event.set()


def serve(kind: str, endpoint: str) -> int:
    """A child process: the LEC node (``/lm_manager``) or the ground-truth oracle node."""
    from anunnaki.lec import LecNode, load_registry
    from anunnaki.oracles import OracleNode
    from anunnaki.sim import load_scenario

    registry = load_registry(MODELS)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    with open_bus("zenoh", connect=[endpoint], name=f"faults-{kind}") as bus:
        if kind == "lec":
            node: Any = LecNode(bus, registry, camera=CAMERA)
        else:
            from anunnaki.sim import RoverSim  # noqa: F401  (the scene's classes below)

            classes = _classes(load_scenario(SCENARIO))
            node = OracleNode(
                bus, "ground_truth", camera=CAMERA, detections=topics.DETECTIONS,
                classes=classes, clean_f1=registry.clean_f1, window=30, min_frames=20,
                min_objects=20,
            )  # fmt: skip
        print("ready", flush=True)
        stop.wait()
        node.close()
    return 0


def _classes(scenario: Any) -> list[str]:
    return sorted({o.kind for o in scenario.objects})


def loop_trial(victim: str, delay: float, deadline: float) -> dict[str, Any]:
    """kill -9 of the LEC/model manager or the oracle while Utu watches the simulated rover."""
    from anunnaki.managed import SimulatedSystem

    trial: dict[str, Any] = {"deployment": "loop", "victim": victim, "delay_s": delay}
    with tempfile.TemporaryDirectory(prefix="faults-loop-") as tmp_name:
        tmp = Path(tmp_name)
        port = free_port()
        endpoint = f"tcp/127.0.0.1:{port}"
        db = tmp / "kb.db"
        path = tmp / "sim.yaml"
        path.write_text(SIM_LAUNCH.format(rover=ROVER, port=port))
        launch = Launch([sys.executable, "-m", "anunnaki.cli.main", "run", str(path),
                         "--knowledge", str(db), "--until", "120"])  # fmt: skip
        children = {
            kind: Launch([sys.executable, __file__, "--serve", kind, "--connect", endpoint])
            for kind in ("lec", "oracle")
        }
        stop = threading.Event()
        commands = _Commands()
        launch.start()
        try:
            if not wait_until(launch.ready, 90):
                raise RuntimeError("Utu not ready in 90 s:\n" + launch.tail())
            for child in children.values():
                child.start()
            for kind, child in children.items():
                if not wait_until(functools.partial(child.said, "ready"), 90):
                    raise RuntimeError(f"{kind} not ready:\n" + child.tail())
            with open_bus("zenoh", connect=[endpoint], name="platform") as bus:
                system = SimulatedSystem(
                    _StampingBus(bus, commands), SCENARIO, models=None, oracle=None,
                    stop_without_utu=None,
                )  # fmt: skip
                runner = threading.Thread(
                    target=system.run, args=(stop,), kwargs={"until": 120.0}, daemon=True
                )
                try:
                    runner.start()
                    if not wait_until(lambda: _loop_nominal(_state(bus)), 60, 0.1):
                        raise RuntimeError("Utu never saw the loop nominal:\n" + launch.tail())
                    commands.armed = True
                    threading.Event().wait(delay)
                    killed = time.perf_counter()
                    proc = children[victim].proc
                    assert proc is not None
                    os.kill(proc.pid, signal.SIGKILL)
                    commands.event.wait(deadline)
                finally:
                    stop.set()
                    runner.join(timeout=20)
                    system.close()
            launch.stop()
            trial |= _loop_figures(commands, killed, launch, db)
        finally:
            stop.set()
            launch.stop()
            for child in children.values():
                child.stop()
    return trial


def _loop_nominal(state: dict[str, Any] | None) -> bool:
    """Warm-up over, the detector up with a known model (G18) and obstacles detected (G3)."""
    if not state or state.get("warming_up"):
        return False
    nodes = state.get("nodes") or {}
    return all((nodes.get(g) or [None, None])[1] == "satisfied" for g in ("G3", "G18"))


def _loop_figures(commands: _Commands, killed: float, launch: Launch, db: Path) -> dict[str, Any]:
    out: dict[str, Any] = {
        "failsafe_ms": None if commands.at is None else round((commands.at - killed) * 1000, 1),
        "failsafe_command": commands.what or None,
        "guard_ms": None,
        "tracebacks": launch.tracebacks(),
    }
    if not db.exists():
        return out | {"lost": None, "replay_identical": False, "note": "no knowledge file"}
    printed = launch.printed()
    lost_decisions = _printed_not_stored(printed, db, 0.0)  # sim time: printed as stored
    identical, why = _replay(db)
    out |= {
        "lost": lost_decisions,
        "lost_inputs": None,  # the simulator's messages carry no serial: not counted
        "lost_decisions": lost_decisions,
        "decisions_printed": len(printed),
        "replay_identical": identical,
    }
    if why:
        out["replay_note"] = why[:900]
    return out


# -- the flood ---------------------------------------------------------------------------------
def rss_mb() -> float:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return math.nan


class _TimedManager(AutonomicManager):
    """The composed manager, stamping each step: its start (``time.perf_counter``), how long
    it took and how much of that its thread ran (``time.thread_time``: the rest it waited
    for the processor or the interpreter lock)."""

    stamps: list[float]
    spans: list[tuple[float, float, float]]  # (start, wall s, thread cpu s)

    def step(self, now: float | None = None, *, execute: bool = True) -> Any:
        start, cpu = time.perf_counter(), time.thread_time()
        self.stamps.append(start)
        try:
            return super().step(now, execute=execute)
        finally:
            wall = time.perf_counter() - start
            self.spans.append((start, wall, time.thread_time() - cpu))


def flood(seconds: float, rate: float) -> dict[str, Any]:
    """The composed manager under ``rate`` messages a second for ``seconds`` (in-process bus)."""
    hub = InprocHub()
    # A knowledge file, as ``anunnaki run`` keeps one (a temporary one unless told): an
    # in-memory knowledge base holds every input the flood gave in this process's memory.
    tmp = tempfile.TemporaryDirectory(prefix="faults-flood-")
    knowledge = f"knowledge: {Path(tmp.name) / 'flood.db'}\n"
    cfg = parse_config(UTU_CONFIG.format(rover=ROVER) + knowledge)
    period = 1.0 / NODE_RATES["analyze"]
    stop, halt = threading.Event(), threading.Event()
    with (
        tmp,
        open_bus("inproc", hub=hub, name="utu") as utu_bus,
        open_bus("inproc", hub=hub, name="platform") as rover_bus,
        open_bus("inproc", hub=hub, name="flood") as flood_bus,
    ):
        manager = _TimedManager.from_config(cfg, bus=utu_bus)
        assert isinstance(manager, _TimedManager)  # from_config builds its own class
        manager.stamps, manager.spans = [], []
        spinner = threading.Thread(
            target=manager.spin, args=(halt,), kwargs={"rate": 1 / period}, daemon=True
        )
        rover = Platform(rover_bus, nominal_trace(seconds + 30.0))
        try:
            spinner.start()
            rover.run_live(stop)
            wait_until(lambda: not manager.analyzer.warming_up, 20)
            gc.collect()
            before = rss_mb()
            sent, began, ended = _flood(flood_bus, seconds, rate)
            threading.Event().wait(2.0)
            gc.collect()
            after = rss_mb()
            stamps = [s for s in manager.stamps if began <= s <= ended]
            longest = max(
                (sp for sp in manager.spans if began <= sp[0] <= ended), default=None,
                key=lambda sp: sp[1],
            )  # fmt: skip
            gaps = [b - a for a, b in itertools.pairwise(stamps)]
            if stamps:
                gaps += [stamps[0] - began, ended - stamps[-1]]
            alive = spinner.is_alive()
        finally:
            stop.set()
            halt.set()
            manager.wake()
            spinner.join(timeout=10)
            rover.close()
            manager.close()
    return {
        "knowledge": "file",
        "seconds": seconds,
        "rate_asked": rate,
        "sent": sent,
        "rate_achieved": round(sent / max(ended - began, 1e-9)),
        "cycles": len(stamps),
        "max_cycle_gap_ms": round(max(gaps) * 1000, 1) if gaps else None,
        "period_ms": round(period * 1000, 1),
        "max_step_ms": None if longest is None else round(longest[1] * 1000, 1),
        "max_step_cpu_ms": None if longest is None else round(longest[2] * 1000, 1),
        "rss_mb_before": round(before, 1),
        "rss_mb_after": round(after, 1),
        "loop_alive": alive,
    }


def _flood(bus: Bus, seconds: float, rate: float) -> tuple[int, float, float]:
    pub = bus.publisher("/rover/ultrasonic")
    # Encoded once: the flood measures Utu's intake, not this thread's JSON encoder.
    payloads = [_envelope("Generic", {"range": 2.0 + k * 0.1}) for k in range(7)]
    began = time.perf_counter()
    sent = 0
    chunk = 100
    while True:
        now = time.perf_counter()
        if now - began >= seconds:
            break
        due = began + sent / rate
        if now < due:
            threading.Event().wait(min(due - now, 0.01))
            continue
        for _ in range(chunk):
            pub.put_raw(payloads[sent % 7])
            sent += 1
    return sent, began, time.perf_counter()


# -- the hostile corpus ------------------------------------------------------------------------
def _envelope(type_name: str, body: dict[str, Any], v: int = 1) -> bytes:
    """A well-formed envelope (as the bus writes it) around any type name and body."""
    env = {"v": v, "type": type_name, "t": 0.0, "seq": 0, "sender": "forger", "body": body}
    return json.dumps(env).encode()


MALFORMED = [
    b"\xff\xfe\x00\x01 not an envelope at all",
    b'{"v": 1, "type": "Generic", "t": 0',
    _envelope("NoSuchMessage", {"x": 1}),
    _envelope("Generic", {"x": 1}, v=99),
    _envelope("ModeRequest", {"mode": 7}),
    _envelope("Generic", {"x": 0}).replace(b"0}", b"NaN}"),
]
INTERNAL = (
    topics.MONITOR_INPUT,
    topics.ANALYSIS,
    topics.EXECUTE_STATUS,
    topics.PLAN_START,
    topics.CYCLE_DONE,
)


def corpus_messages(t: float) -> list[tuple[str, Any, bool]]:
    """``(topic, message or raw bytes, raw)``: the forged cycle messages, then malformed ones."""
    from hostile_cycle import hostile_cycle_messages

    out: list[tuple[str, Any, bool]] = [(tp, m, False) for tp, m in hostile_cycle_messages(t)]
    out += [(tp, raw, True) for tp in INTERNAL for raw in MALFORMED]
    return out


class _Tracebacks(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.count = 0

    def emit(self, record: logging.LogRecord) -> None:
        if record.exc_info or "Traceback" in record.getMessage():
            self.count += 1


@dataclass
class _Live:
    """A live Utu in this process: the composed manager or the five node classes."""

    bus: Bus
    nodes: list[Any]
    threads: list[threading.Thread]
    halt: threading.Event

    def counters(self) -> int:
        malformed = sum(self.bus.stats().malformed.values())
        return malformed + sum(getattr(n, "foreign", 0) for n in self.nodes)

    def counted_past(self, before: int) -> bool:
        """Whether the counters went past ``before`` (a message refused since)."""
        return self.counters() > before

    def deaths(self) -> int:
        dead = sum(1 for t in self.threads if not t.is_alive())
        for name in NODE_NAMES:
            try:
                self.bus.request(topics.ready_service(name), {}, timeout=2.0)
            except BusTimeout:
                dead += 1
        return dead

    def decisions(self) -> list[tuple[str, str | None]]:
        kb = self.nodes[0].knowledge
        return [(d.kind, d.tactic) for d in kb.decisions()]


def _bring_up(deployment: str, bus: Bus) -> _Live:
    parts = load_parts(parse_config(UTU_CONFIG.format(rover=ROVER)))
    from anunnaki.utu import AutonomicManager, Knowledge

    kb = Knowledge()
    halt = threading.Event()
    if deployment == "one-process":
        nodes: list[Any] = [
            AutonomicManager.from_config(parts, bus=bus, knowledge=kb, nodes=NODE_RATES)
        ]
    else:
        nodes = [
            build_node(name, parts, bus=bus, knowledge=kb, rate=rate)
            for name, rate in NODE_RATES.items()
        ]
    threads = []
    for node in nodes:
        t = threading.Thread(target=node.spin, args=(halt,), daemon=True)
        t.start()
        threads.append(t)
    return _Live(bus, nodes, threads, halt)


def corpus(deployment: str) -> dict[str, Any]:
    """Send the corpus, one message at a time, to a live Utu with the platform nominal."""
    handler = _Tracebacks()
    logging.getLogger().addHandler(handler)
    hub = InprocHub()
    stop = threading.Event()
    sent = refused = 0
    try:
        with (
            open_bus("inproc", hub=hub, name="utu") as utu_bus,
            open_bus("inproc", hub=hub, name="platform") as rover_bus,
            open_bus("inproc", hub=hub, name="forger") as forger,
        ):
            live = _bring_up(deployment, utu_bus)
            rover = Platform(rover_bus, nominal_trace(120.0))
            try:
                rover.run_live(stop)
                if not wait_until(lambda: nominal(_state(forger)), 30, pause=0.1):
                    raise RuntimeError(f"{deployment}: Utu never saw the rover nominal")
                before = live.decisions()
                for topic, message, raw in corpus_messages(time.time()):
                    counted = live.counters()
                    pub = forger.publisher(topic)
                    pub.put_raw(message) if raw else pub.put(message)
                    sent += 1
                    if wait_until(functools.partial(live.counted_past, counted), COUNTED, 0.01):
                        refused += 1
                threading.Event().wait(1.0)  # the platform's next messages go through
                steered = len(live.decisions()) - len(before)
                deaths = live.deaths()
            finally:
                stop.set()
                live.halt.set()
                for node in live.nodes:
                    node.wake()
                for t in live.threads:
                    t.join(timeout=10)
                rover.close()
                for node in live.nodes:
                    node.close()
    finally:
        logging.getLogger().removeHandler(handler)
    return {
        "deployment": deployment,
        "sent": sent,
        "refused": refused,
        "tracebacks": handler.count,
        "loop_deaths": deaths,
        "steered": steered,
        "platform_failsafe": rover.failsafe_what or None,
    }


def corpus_launch() -> dict[str, Any]:
    """The corpus sent over zenoh to ``anunnaki run --processes`` (five node processes).

    Refusals are not visible from outside (``refused: null``); tracebacks are those the
    nodes print, loop deaths the node processes that ended or stopped answering readiness,
    ``steered`` the decisions the knowledge base holds afterwards (a nominal run makes none).
    """
    stop = threading.Event()
    sent = 0
    with (
        tempfile.TemporaryDirectory(prefix="faults-corpus-") as tmp_name,
        open_bus("zenoh", name="platform") as bus,
        open_bus("zenoh", connect=list(bus.endpoints), name="forger") as forger,
    ):
        rover = Platform(bus, nominal_trace(120.0))
        launch, db = _utu_launch(Path(tmp_name), bus.endpoints[0], "processes")
        try:
            rover.run_live(stop)
            launch.start()
            if not wait_until(launch.ready, 90):
                raise RuntimeError("not ready in 90 s:\n" + launch.tail())
            # Settled: Utu has run WARM s on the platform's messages and decided nothing
            # for a second (its start may hand the rover over before the oracle speaks).
            settled = time.monotonic() + LISTENING + WARM
            history: list[tuple[float, int]] = []

            def quiet() -> bool:
                now, count = time.monotonic(), len(read_decisions(db))
                history.append((now, count))
                calm = [c for t, c in history if t >= now - 1.0]
                return now >= settled and history[0][0] <= now - 1.0 and len(set(calm)) == 1

            if not wait_until(quiet, 30, 0.1):
                raise RuntimeError("Utu never settled:\n" + launch.tail())
            decided = len(read_decisions(db))
            pubs = {topic: forger.publisher(topic) for topic in INTERNAL}
            for pub in pubs.values():
                pub.wait_for_subscribers(5)
            for topic, message, raw in corpus_messages(time.time()):
                pub = pubs[topic]
                pub.put_raw(message) if raw else pub.put(message)
                sent += 1
            threading.Event().wait(2.0)  # the platform's next messages go through
            deaths = _dead_nodes(launch, bus)
            stop.set()
            launch.stop()
            steered = len(read_decisions(db)) - decided
        finally:
            stop.set()
            launch.stop()
            rover.close()
    return {
        "deployment": "processes (five node processes, zenoh)",
        "sent": sent,
        "refused": None,
        "tracebacks": launch.tracebacks(),
        "loop_deaths": deaths,
        "steered": steered,
        "platform_failsafe": rover.failsafe_what or None,
    }


def read_decisions(db: Path) -> list[Any]:
    """The decisions of a knowledge file (none while it does not exist)."""
    if not db.exists():
        return []
    with contextlib.closing(open_run(db)) as kb:
        return list(kb.decisions())


def _corpus(where: str) -> dict[str, Any]:
    try:
        return corpus_launch() if where == "launch" else corpus(where)
    except Exception as exc:
        return {"deployment": where, "sent": 0, "refused": None, "tracebacks": None,
                "loop_deaths": None, "steered": None,
                "error": f"{type(exc).__name__}: {exc}"[-2500:]}  # fmt: skip


def _dead_nodes(launch: Launch, bus: Bus) -> int:
    dead = 0
    for name, pid in launch.pids().items():
        try:
            os.kill(pid, 0)
            bus.request(topics.ready_service(name), {}, timeout=2.0)
        except (ProcessLookupError, BusTimeout):
            dead += 1
    return dead


# -- the report --------------------------------------------------------------------------------
def summary(result: dict[str, Any]) -> str:
    rows = ["deployment   victim      delay  failsafe_ms  guard_ms  lost  replay"]
    for t in result["kill_trials"]:
        rows.append(
            f"{t['deployment']:<12} {t['victim']:<10} {t.get('delay_s', 0):>5}  "
            f"{t.get('failsafe_ms')!s:>11}  {t.get('guard_ms')!s:>8}  {t.get('lost')!s:>4}  "
            f"{t.get('replay_identical')}"
        )
    f = result["flood"]
    rows.append(
        f"flood: {f['sent']} msgs at {f['rate_achieved']}/s; longest cycle gap "
        f"{f['max_cycle_gap_ms']} ms (period {f['period_ms']} ms); RSS {f['rss_mb_before']} -> "
        f"{f['rss_mb_after']} MB"
    )
    c = result["corpus"]
    rows.append(
        f"corpus: sent {c['sent']}, refused {c['refused']}, tracebacks {c['tracebacks']}, "
        f"loop deaths {c['loop_deaths']}, steered {c['steered']}"
    )
    return "\n".join(rows)


def _aims(result: dict[str, Any]) -> dict[str, Any]:
    trials = result["kill_trials"]
    fs = [t.get("failsafe_ms") for t in trials]
    met_fs = sum(1 for x in fs if x is not None and x <= AIMS["failsafe_ms"])
    f = result["flood"]
    c = result["corpus"]
    gap_ok = (
        f["max_cycle_gap_ms"] is not None
        and f["max_cycle_gap_ms"] <= AIMS["max_cycle_gap_periods"] * f["period_ms"]
    )
    rss_ok = f["rss_mb_after"] <= f["rss_mb_before"] * (1 + AIMS["rss_back_within"])
    return {
        "failsafe_within_250ms": f"{met_fs}/{len(trials)}",
        "nothing_lost": f"{sum(1 for t in trials if t.get('lost') == 0)}/{len(trials)}",
        "replay_identical": f"{sum(1 for t in trials if t.get('replay_identical'))}/{len(trials)}",
        "flood_gap_met": gap_ok,
        "flood_memory_met": rss_ok,
        "corpus_met": c["tracebacks"] == 0 and c["loop_deaths"] == 0,
    }


def _trials(quick: bool, deadline: float, only: list[str] | None) -> Iterator[dict[str, Any]]:
    delays = KILL_DELAYS[:1] if quick else KILL_DELAYS
    plan = [("processes", node) for node in NODE_NAMES] + [("one-process", "manager")]
    plan += [("by-hand", node) for node in NODE_NAMES]
    for deployment, victim in plan:
        if only and victim not in only:
            continue
        for delay in delays:
            try:
                trial = kill_trial(deployment, victim, delay, deadline)
            except Exception as exc:
                trial = {"deployment": deployment, "victim": victim, "delay_s": delay,
                         "failsafe_ms": None, "lost": None, "replay_identical": False,
                         "error": f"{type(exc).__name__}: {exc}"[-2500:]}  # fmt: skip
            print(f"  {deployment} {victim} +{delay}s: {trial.get('failsafe_ms')} ms", flush=True)
            yield trial


def _loop_trials(quick: bool, deadline: float, only: list[str] | None) -> Iterator[dict[str, Any]]:
    delays = KILL_DELAYS[:1] if quick else KILL_DELAYS
    for victim in ("lec", "oracle"):
        if only and victim not in only:
            continue
        for delay in delays:
            try:
                trial = loop_trial(victim, delay, deadline)
            except Exception as exc:
                trial = {"deployment": "loop", "victim": victim, "delay_s": delay,
                         "failsafe_ms": None, "lost": None, "replay_identical": False,
                         "error": f"{type(exc).__name__}: {exc}"[-2500:]}  # fmt: skip
            print(f"  loop {victim} +{delay}s: {trial.get('failsafe_ms')} ms", flush=True)
            yield trial


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="one trial per victim, 3 s flood")
    parser.add_argument("--serve", choices=("lec", "oracle"), help=argparse.SUPPRESS)
    parser.add_argument("--connect", help=argparse.SUPPRESS)
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT)
    parser.add_argument("--deadline", type=float, default=3.0, help="s to wait for a fail-safe")
    parser.add_argument("--flood-rate", type=float, default=50_000.0)
    parser.add_argument("--flood-seconds", type=float, default=None)
    parser.add_argument("--victims", nargs="*", help="only these victims (e.g. analyze manager)")
    parser.add_argument(
        "--skip", nargs="*", default=[], choices=("kill", "loop", "flood", "corpus")
    )
    parser.add_argument(
        "--corpus",
        nargs="*",
        default=["processes", "one-process", "launch"],
        choices=("processes", "one-process", "launch"),
        help="where the corpus goes: the node classes or the composed manager in this "
        "process, or 'anunnaki run --processes' (launch)",
    )
    args = parser.parse_args(argv)
    if args.serve:
        return serve(args.serve, args.connect)
    logging.basicConfig(level=logging.ERROR, format="%(levelname)s %(name)s: %(message)s")
    started = time.monotonic()
    result: dict[str, Any] = {
        "when": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "quick": args.quick,
        "machine": {
            "python": platform.python_version(),
            "cpus": os.cpu_count(),
            "load": os.getloadavg(),
        },
        "aims": AIMS,
    }
    print("kill -9 matrix", flush=True)
    result["kill_trials"] = (
        [] if "kill" in args.skip else list(_trials(args.quick, args.deadline, args.victims))
    )
    seconds = args.flood_seconds or (3.0 if args.quick else 10.0)
    print(f"flood {args.flood_rate:g} msg/s for {seconds:g} s", flush=True)
    result["flood"] = {} if "flood" in args.skip else flood(seconds, args.flood_rate)
    print("hostile corpus", flush=True)
    if "corpus" in args.skip:
        result["corpus"] = {}
    else:
        per = [_corpus(d) for d in args.corpus]
        result["corpus"] = {
            key: sum(p[key] or 0 for p in per)
            for key in ("sent", "refused", "tracebacks", "loop_deaths", "steered")
        } | {"deployments": per}
    if "loop" not in args.skip:  # last: it brings torch and pybullet into this process
        print("kill -9 in the whole loop", flush=True)
        result["kill_trials"] += list(_loop_trials(args.quick, args.deadline, args.victims))
    result["seconds"] = round(time.monotonic() - started, 1)
    if not args.skip:
        result["aims_met"] = _aims(result)
        print(summary(result))
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.output} ({result['seconds']} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
