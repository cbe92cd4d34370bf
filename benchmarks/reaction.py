"""Utu's reaction latency, and how many messages a second its Monitor sustains.

Reaction latency
    From publishing a violating assessment (``/utu/oracle/output`` with ``category: 1``
    while the rover is autonomous and every other input nominal) to the fail-safe tactic's
    first action (the ``/rover/set_mode`` request) arriving at the managed system's service
    handler. Both ends are stamped with ``time.perf_counter_ns`` in the one process that
    plays the managed system and the oracle, so they share a clock. The path is
    event-driven: ``dwell: 0``, ``warmup: 0`` and a copy of the rover tactics with every
    ``cooldown="0"``; ``spin`` wakes on the message itself (the pull subscribers' doorbell),
    its ``rate`` only paces the time-driven checks. Knowledge is a SQLite file (WAL).

    A small fake rover stands in for the managed system (it is simpler to drive than
    ``ScriptedSystem``, which replays a trace): it publishes ``/rover/ultrasonic`` (20 Hz),
    ``/rover/status``, ``/rover/camera/info`` and the oracle's current assessment (10 Hz
    each), obeys ``/rover/set_mode`` (answering at once and publishing its new status) and
    acknowledges ``/rover/stop``. After each trial it waits (on the manager's
    ``/utu/analyze/state``, with deadlines) until the fail-safe has verified its
    postcondition, publishes ``category: 0``, switches back to autonomous and waits until the
    manager sees the rover nominal again. Each wait looks for a state the previous state
    cannot satisfy, so no wait passes on an analysis published before its stimulus.

    (a) everything in one process on the in-process bus, the manager spinning in a thread;
    (b) the managed system here and the whole manager in a child process (this script with
        ``--serve-manager``) over zenoh (peers on ``tcp/127.0.0.1``, scouting off);
    (c) one process per Utu node (``anunnaki node NAME``, clients of this process's zenoh
        session, one shared knowledge file) at the node rates of ``examples/rover/utu.yaml``,
        when that mode exists; then, alone, the same with every node at 1000 Hz.

    Every round runs (a) and (b), and (c) every ``--c-every``-th round, in a shuffled order,
    then one sample of each bus round trip of ``benchmarks/bus_pingpong.py`` (ping-pong and
    request/reply, zenoh over the same two sessions as (b), and in-process), in a shuffled
    order, so that load from other processes on this shared machine spreads over all of
    them. Afterwards ``bus_pingpong.measure`` itself runs back to back on the same sessions.

    Where the time goes: (a) again with stamps at the start of the step and where the step
    hands the action to the actuator; the violation step alone in one thread; cProfile.

Monitor throughput
    50,000 messages of the rover's sensor topics with changing values, with analysis and
    persistence included (knowledge in a temporary SQLite file in WAL mode):

    * ``feed``: ``manager.feed`` + ``manager.step(now)`` in batches of 10, 100 and 1000
      (simulated time advances 1 ms per message), in one thread;
    * ``inproc bus``: published on the in-process bus as fast as one thread can, taken by a
      spinning manager (queues large enough to drop nothing);
    * a cProfile of each path (own time per message).

Writes ``benchmarks/results/reaction.json`` and prints a summary table; takes about two
minutes. Needs the bus extra (``pip install 'anunnaki[bus]'``, part of the README setup)::

    .venv/bin/python benchmarks/reaction.py
    .venv/bin/python benchmarks/reaction.py --trials 50 --messages 10000 --output /tmp/r.json
"""

from __future__ import annotations

import argparse
import contextlib
import cProfile
import datetime
import importlib.util
import io
import json
import logging
import math
import os
import platform
import pstats
import random
import re
import shutil
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib.metadata import version
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

import bus_pingpong  # benchmarks/bus_pingpong.py: the bus's own round trips
import yaml

from anunnaki.bus import Bus, BusConfig, BusError, BusTimeout, InprocHub, Sample, open_bus
from anunnaki.clock import Clock, WallClock
from anunnaki.utu import (
    AutonomicManager,
    BusActuator,
    Knowledge,
    RecordingActuator,
    UtuConfig,
    load_config,
)

ROOT = Path(__file__).resolve().parents[1]
ROVER = ROOT / "examples" / "rover"
DEFAULT_OUTPUT = Path(__file__).parent / "results" / "reaction.json"

AIMS = {"a_p99_ms": 1.0, "b_p99_ms": 3.0, "c_p99_ms": 10.0, "monitor_msgs_per_s": 20_000}
#: Background traffic of the fake rover (Hz), the "everything else nominal" of a live run.
RATES = {
    "/rover/ultrasonic": 20.0,
    "/rover/status": 10.0,
    "/rover/camera/info": 10.0,
    "/utu/oracle/output": 10.0,
}
VIOLATION = {"category": 1, "confidence": 0.97}
CLEAR = {"category": 0, "confidence": 0.97}
WAIT = 3.0  # s: deadline of every wait on the other side
BACK_TO_BACK = 1000  # round trips of bus_pingpong.measure after the interleaved trials


# -- statistics ----------------------------------------------------------------------------
def percentile(sorted_values: list[float], q: float) -> float:
    """The ``q``-th percentile (0-100) of sorted values, linearly interpolated."""
    if not sorted_values:
        return math.nan
    pos = (len(sorted_values) - 1) * q / 100.0
    lo = math.floor(pos)
    hi = min(lo + 1, len(sorted_values) - 1)
    return sorted_values[lo] + (sorted_values[hi] - sorted_values[lo]) * (pos - lo)


def summary_ms(ns: list[int]) -> dict[str, Any]:
    """p50, p90, p99, max, mean (ms) and n of nanosecond samples."""
    v = sorted(x / 1e6 for x in ns)
    out: dict[str, Any] = {f"p{q}": round(percentile(v, q), 4) for q in (50, 90, 99)}
    out["max"] = round(v[-1], 4) if v else math.nan
    out["min"] = round(v[0], 4) if v else math.nan
    out["mean"] = round(sum(v) / len(v), 4) if v else math.nan
    out["n"] = len(v)
    return out


# -- the files of a run ----------------------------------------------------------------------
def write_files(tmp: Path) -> Path:
    """Copy the rover tactics with every cooldown 0; return the copy's path."""
    text = (ROVER / "tactics.xml").read_text(encoding="utf-8")
    text, n = re.subn(r'cooldown="[^"]*"', 'cooldown="0"', text)
    if n == 0:
        raise RuntimeError("examples/rover/tactics.xml has no cooldown to zero")
    path = tmp / "tactics.xml"
    path.write_text(text, encoding="utf-8")
    return path


def write_config(
    tmp: Path, name: str, tactics: Path, *, bus: Mapping[str, Any], queue: int = 1024
) -> Path:
    """Write a Utu configuration: event-driven (no dwell, warm-up or cooldown), knowledge in a
    fresh SQLite file (WAL), no escalation to run-stop (a slow trial must not halt the run)."""
    config = {
        "anunnaki": "utu/1",
        "name": name,
        "goal_model": str(ROVER / "goals.yaml"),
        "binding": str(ROVER / "binding.yaml"),
        "tactics": str(tactics),
        "knowledge": str(tmp / f"{name}.db"),
        "bus": dict(bus),
        "rate": 20,
        "dwell": 0,
        "warmup": 0,
        "failsafe": "fail-safe",
        "escalate_to_run_stop": False,
        "queue": queue,
    }
    path = tmp / f"{name}.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False), encoding="utf-8")
    return path


# -- the managed system ----------------------------------------------------------------------
def _status(state: Mapping[str, Any] | None, node: str) -> str | None:
    if state is None:
        return None
    entry = state.get("nodes", {}).get(node)
    return entry[1] if entry else None


#: Key under which the rover keeps the fail-safe's state (idle, running, awaiting, ...) in its
#: copy of the analysis: from the composed manager's queue, or the execute node's status.
FAILSAFE = "_failsafe"


# The waits below each look for a state that the state before it cannot satisfy, so that a
# wait never passes on an analysis published before the stimulus it waits for.
def _nominal(state: Mapping[str, Any] | None) -> bool:
    """Autonomous, no obstacle, no tactic in flight: ready for a trial."""
    return (
        state is not None
        and all(_status(state, g) == "satisfied" for g in ("G1", "G3", "G4", "G7"))
        and _status(state, "O1") == "unsatisfied"
        and state.get(FAILSAFE) == "idle"
        and "fail-safe" not in state.get("tactics", ())
    )


def _handed_over(state: Mapping[str, Any] | None) -> bool:
    """The violation is seen, the rover is manual and the fail-safe verified its
    postcondition."""
    return (
        state is not None
        and _status(state, "O1") == "satisfied"
        and _status(state, "G11") == "satisfied"
        and _status(state, "G3") == "satisfied"
        and state.get(FAILSAFE) == "idle"
    )


def _cleared(state: Mapping[str, Any] | None) -> bool:
    """The obstacle is gone, the rover still manual, nothing in flight."""
    return (
        state is not None
        and _status(state, "O1") == "unsatisfied"
        and _status(state, "G11") == "satisfied"
        and all(_status(state, g) == "satisfied" for g in ("G3", "G6", "G8"))
        and state.get(FAILSAFE) == "idle"
    )


class FakeRover:
    """The managed system and the oracle of one setup, on one bus.

    Publishes the rover's sensors in the background, obeys ``/rover/set_mode`` (stamping each
    request's arrival with ``perf_counter_ns`` before anything else), and follows the
    manager's analysis on ``/utu/analyze/state`` and the fail-safe's state (the composed
    manager's queue in that analysis; the execute node's ``/utu/execute/status`` when Utu
    runs as nodes).
    """

    def __init__(self, bus: Bus, label: str) -> None:
        self.bus = bus
        self.label = label
        self.mode = "autonomous"
        self.set_mode_ns: list[int] = []
        self.stops = 0
        self.state: dict[str, Any] | None = None
        self.failsafe = "idle"
        self._cond = threading.Condition()
        # Held from reading a value to putting it, so that the background thread never
        # publishes a stale mode or assessment after a fresh one.
        self._status_lock = threading.Lock()
        self._oracle_lock = threading.Lock()
        self._stop = threading.Event()
        self._pubs = {topic: bus.publisher(topic) for topic in RATES}
        self.oracle = self._pubs["/utu/oracle/output"]
        self.assessment = CLEAR
        self._declared: list[Any] = [
            *self._pubs.values(),
            bus.service("/rover/set_mode", self._set_mode),
            bus.service("/rover/stop", self._on_stop),
            bus.subscribe("/utu/analyze/state", self._on_state, queue=64),
            bus.subscribe("/utu/execute/status", self._on_exec_status, queue=64),
        ]
        self._thread = threading.Thread(target=self._run, name=f"rover-{label}", daemon=True)
        self._thread.start()

    # handlers
    def _set_mode(self, request: Any) -> dict[str, Any]:
        t = time.perf_counter_ns()
        mode = str(request.to_body().get("mode"))
        with self._cond:
            self.set_mode_ns.append(t)
            self.mode = mode
            self._cond.notify_all()
        self.publish_status()
        return {"ok": True, "mode": mode}

    def _on_stop(self, request: Any) -> dict[str, Any]:
        with self._cond:
            self.stops += 1  # acknowledged, not obeyed: only start-up with no inputs asks
        return {"ok": True, "stopped": False}

    def _on_state(self, sample: Sample) -> None:
        state = sample.message.to_body()
        with self._cond:
            if "queue" in state:  # the composed manager: its queue says what is in flight
                self.failsafe = next(
                    (str(q["state"]) for q in state["queue"] if q.get("tactic") == "fail-safe"),
                    "idle",
                )
            self.state = {**state, FAILSAFE: self.failsafe}
            self._cond.notify_all()

    def _on_exec_status(self, sample: Sample) -> None:
        runtime = sample.message.to_body().get("runtimes", {}).get("fail-safe", {})
        with self._cond:
            self.failsafe = str(runtime.get("state", "idle"))
            if self.state is not None:
                self.state = {**self.state, FAILSAFE: self.failsafe}
            self._cond.notify_all()

    # publishing
    def publish_status(self) -> None:
        """Publish the rover's status with its current mode."""
        with self._status_lock:
            with self._cond:
                mode = self.mode
            self._pubs["/rover/status"].put(
                {"mode": mode, "buzzer": False, "bumper": False, "lights": True}
            )

    def _run(self) -> None:
        period = 1.0 / max(RATES.values())
        tick = 0
        while not self._stop.wait(period):
            tick += 1
            self._pubs["/rover/ultrasonic"].put({"range": 2.0 + 0.5 * math.sin(tick / 7)})
            if tick % 2 == 0:
                self.publish_status()
                self._pubs["/rover/camera/info"].put({"seq": tick, "width": 640, "height": 480})
                self.assess()

    def assess(self, assessment: Mapping[str, Any] | None = None) -> None:
        """Publish the oracle's assessment (a new one, or the current one again)."""
        with self._oracle_lock:
            if assessment is not None:
                self.assessment = dict(assessment)
            self.oracle.put(self.assessment)

    # waiting
    def wait(self, predicate: Callable[[], bool], timeout: float = WAIT) -> bool:
        """Wait (on the condition, with a deadline) until ``predicate`` holds."""
        with self._cond:
            return self._cond.wait_for(predicate, timeout)

    def wait_set_mode(self, before: int) -> bool:
        """Wait until ``/rover/set_mode`` requests number more than ``before``."""
        return self.wait(lambda: len(self.set_mode_ns) > before)

    def wait_state(self, predicate: Callable[[dict[str, Any] | None], bool]) -> bool:
        """Wait until the manager's latest analysis satisfies ``predicate``."""
        return self.wait(lambda: predicate(self.state))

    # one trial
    def set_mode_locally(self, mode: str) -> None:
        """Change mode as an operator at the rover would, and report it."""
        with self._cond:
            self.mode = mode
        self.publish_status()

    def reset(self) -> bool:
        """After a trial: clear the violation, go back to autonomous, and wait for the
        manager to see the rover nominal."""
        self.assess(CLEAR)
        if not self.wait_state(_cleared):
            return False
        self.set_mode_locally("autonomous")
        return self.wait_state(_nominal)

    def settle(self, gate: threading.Event) -> None:
        """From any state (start-up, a failed reset) to nominal, stable for 0.3 s."""
        for _ in range(5):
            self.set_mode_locally("manual")
            self.assess(CLEAR)
            if not self.wait_state(_cleared):
                continue
            self.set_mode_locally("autonomous")
            if not self.wait_state(_nominal):
                continue
            with self._cond:
                n = len(self.set_mode_ns)
            gate.wait(0.3)
            with self._cond:
                if _nominal(self.state) and len(self.set_mode_ns) == n:
                    return
        raise RuntimeError(f"setup ({self.label}) never settled in the nominal state")

    def violate(self) -> tuple[int, int]:
        """Publish the violation; return (its perf_counter_ns, set_mode requests before)."""
        with self._cond:
            n0 = len(self.set_mode_ns)
            if not _nominal(self.state) or self.mode != "autonomous":
                raise RuntimeError(f"({self.label}) trial started off-nominal: {self.state}")
        with self._oracle_lock:
            self.assessment = VIOLATION
            t0 = time.perf_counter_ns()
            self.oracle.put(VIOLATION)
        return t0, n0

    def trial(self) -> tuple[int | None, bool]:
        """One trial: (ns until ``/rover/set_mode`` arrived or None on timeout, whether the
        fail-safe then completed and the rover is back to nominal)."""
        t0, n0 = self.violate()
        if not self.wait_set_mode(n0):
            return None, False
        latency = self.set_mode_ns[n0] - t0
        return latency, self.wait_state(_handed_over) and self.reset()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        for d in reversed(self._declared):
            d.close()


# -- setups --------------------------------------------------------------------------------
class InprocSetup:
    """(a): rover, oracle and manager in this process, on one in-process bus."""

    label = "a"

    def __init__(
        self,
        config_path: Path,
        *,
        clock: Clock | None = None,
        actuator: Callable[[Bus], Any] | None = None,
    ) -> None:
        self.config = load_config(config_path)
        self.bus = open_bus("inproc", name="bench-a")
        self.rover = FakeRover(self.bus, "a")
        self.manager = AutonomicManager.from_config(
            self.config,
            bus=self.bus,
            clock=clock,
            actuator=None if actuator is None else actuator(self.bus),
        )
        self._stop = threading.Event()
        self._thread = threading.Thread(
            target=self.manager.spin,
            args=(self._stop,),
            kwargs={"rate": self.config.rate},
            name="utu-a",
            daemon=True,
        )
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self.manager.wake()  # end spin's wait now
        self._thread.join(timeout=5.0)
        self.rover.close()
        self.manager.close()
        self.bus.close()


class ZenohSetup:
    """(b): rover and oracle here; the manager in a child process, over zenoh."""

    label = "b"

    def __init__(self, tmp: Path, tactics: Path) -> None:
        self.bus = open_bus("zenoh", name="bench-b")
        self.endpoint = self.bus.endpoints[0]
        config = write_config(
            tmp, "utu-b", tactics, bus={"kind": "zenoh", "connect": [self.endpoint]}
        )
        self.rover = FakeRover(self.bus, "b")
        self.log_path = tmp / "utu-b.log"
        self._log = self.log_path.open("w")
        self.child = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve()), "--serve-manager", str(config)],
            stdin=subprocess.PIPE,
            stdout=self._log,
            stderr=subprocess.STDOUT,
        )
        try:
            self.bus.request("/utu/ready", {}, timeout=30.0)
            self.probe = EchoProbe(self.bus)
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.rover.close()
        if self.child.poll() is None:
            with contextlib.suppress(Exception):
                assert self.child.stdin is not None
                self.child.stdin.close()  # the child stops on EOF
            try:
                self.child.wait(timeout=10.0)
            except subprocess.TimeoutExpired:
                self.child.kill()
                self.child.wait(timeout=5.0)
        self.bus.close()
        self._log.close()
        _report_log(self.log_path, "the manager process of (b)")


def example_node_rates() -> dict[str, float]:
    """The node rates of the rover's launch file (``examples/rover/utu.yaml``)."""
    launch = yaml.safe_load((ROVER / "utu.yaml").read_text(encoding="utf-8"))
    return {name: float(v["rate"]) for name, v in launch["nodes"].items()}


class NodesSetup:
    """(c): rover and oracle here; each Utu node in its own process (``anunnaki node``),
    joining this process's zenoh session as a client, all sharing one knowledge file."""

    label = "c"

    def __init__(self, tmp: Path, tactics: Path, rates: Mapping[str, float]) -> None:
        self.bus = open_bus("zenoh", name="bench-c")
        endpoint = self.bus.endpoints[0]
        config = write_config(tmp, "utu-c", tactics, bus={"kind": "zenoh"})
        Knowledge(tmp / "utu-c.db").close()  # created before the nodes open it together
        self.rover = FakeRover(self.bus, "c")
        self.log_path = tmp / "utu-c.log"
        self._poll = threading.Event()  # never set: paces the readiness polls
        self._log = self.log_path.open("w")
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(
            p for p in (str(ROOT / "src"), env.get("PYTHONPATH")) if p
        )
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        try:
            for name, rate in rates.items():
                self.procs[name] = subprocess.Popen(
                    [
                        sys.executable,
                        "-m",
                        "anunnaki.cli.main",
                        "node",
                        name,
                        "--config",
                        str(config),
                        "--rate",
                        repr(rate),
                        "--connect",
                        endpoint,
                        "--mode",
                        "client",
                        "--exit-with-parent",
                    ],
                    stdin=subprocess.PIPE,
                    stdout=self._log,
                    stderr=subprocess.STDOUT,
                    env=env,
                )
            for name in rates:
                self._wait_ready(name)
        except BaseException:
            self.close()
            raise

    def _wait_ready(self, name: str) -> None:
        deadline = time.monotonic() + 60.0
        while True:
            if self.procs[name].poll() is not None:
                raise RuntimeError(
                    f"node {name} exited: {self.log_path.read_text(errors='replace')[-2000:]}"
                )
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise RuntimeError(f"node {name} was not ready within 60 s")
            with contextlib.suppress(BusError):
                reply = self.bus.request(f"/utu/{name}/ready", {}, timeout=min(remaining, 5.0))
                if reply.to_body().get("ready"):
                    return
            self._poll.wait(0.05)

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.rover.close()
        for proc in self.procs.values():
            if proc.poll() is None and proc.stdin is not None:
                with contextlib.suppress(OSError):
                    proc.stdin.close()  # --exit-with-parent: the node stops on EOF
        for proc in self.procs.values():
            try:
                proc.wait(timeout=10.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5.0)
        self.bus.close()
        self._log.close()
        _report_log(self.log_path, "the per-node processes of (c)")


class EchoProbe:
    """Round trips to an echo side served by ``bus_pingpong.serve_echo``, as
    ``bus_pingpong.measure`` makes them, one at a time (so they can be interleaved).

    Ping-pong: publish ``{"i": n}`` on ``/bench/ping``, the echo side republishes it on
    ``/bench/pong``, wait for it on a pull subscriber. Request/reply: ``/bench/echo``.
    """

    def __init__(self, bus: Bus) -> None:
        self.bus = bus
        self.pongs = bus.subscribe("/bench/pong", queue=64)
        self.ping = bus.publisher("/bench/ping")
        if not self.ping.wait_for_subscribers(10.0):
            raise RuntimeError("the echo side never subscribed to /bench/ping")
        self.i = 0
        # Handshake: the route back may come up a little after ours (as bus_pingpong does).
        deadline = time.monotonic() + 10.0
        while self.pubsub_rtt() is None:
            if time.monotonic() > deadline:
                raise RuntimeError("no pong from the echo side")
        self.request_rtt()

    def pubsub_rtt(self) -> int | None:
        """One ping-pong (ns), or None when the pong did not come back within 0.5 s."""
        self.i += 1
        t0 = time.perf_counter_ns()
        self.ping.put({"i": self.i})
        try:
            while True:
                sample = self.pongs.recv(timeout=0.5)
                if sample.message.to_body().get("i") == self.i:
                    return time.perf_counter_ns() - t0
        except BusTimeout:
            return None

    def request_rtt(self) -> int:
        """One request/reply (ns)."""
        self.i += 1
        t0 = time.perf_counter_ns()
        self.bus.request("/bench/echo", {"i": self.i}, timeout=WAIT)
        return time.perf_counter_ns() - t0

    def back_to_back(self, rounds: int, warmup: int) -> dict[str, Any]:
        """``bus_pingpong.measure`` itself on this bus: rounds back to back (microseconds)."""
        self.pongs.close()  # measure declares its own pong subscriber
        self.ping.close()
        return bus_pingpong.measure(self.bus, rounds, warmup)


class InprocBaseline:
    """The in-process bus's own round trips: two buses on one hub, as in bus_pingpong."""

    def __init__(self) -> None:
        hub = InprocHub()
        self.bus = open_bus("inproc", hub=hub, name="bench-ping")
        self.echo = open_bus("inproc", hub=hub, name="bench-echo")
        bus_pingpong.serve_echo(self.echo)
        self.probe = EchoProbe(self.bus)

    def close(self) -> None:
        self.bus.close()
        self.echo.close()


def serve_manager(config_path: str) -> int:
    """The child of setup (b): the whole manager on a zenoh bus, plus the baseline's echo
    service and ping-pong on the same session; stops when its stdin closes."""
    config = load_config(config_path)
    bus = open_bus(BusConfig.model_validate(config.bus), name="bench-utu-b")
    bus_pingpong.serve_echo(bus)
    manager = AutonomicManager.from_config(config, bus=bus)
    stop = threading.Event()

    def watch_stdin() -> None:
        sys.stdin.read()
        stop.set()
        manager.wake()

    threading.Thread(target=watch_stdin, daemon=True).start()
    try:
        manager.spin(stop, rate=config.rate)
    finally:
        manager.close()
        bus.close()
    return 0


# -- the latency run -----------------------------------------------------------------------
@dataclass
class Samples:
    """Nanosecond samples per series, and the trials that timed out."""

    ns: dict[str, list[int]] = field(default_factory=dict)
    timeouts: dict[str, int] = field(default_factory=dict)
    resettles: dict[str, int] = field(default_factory=dict)

    def add(self, series: str, value: int | None) -> None:
        if value is None:
            self.timeouts[series] = self.timeouts.get(series, 0) + 1
        else:
            self.ns.setdefault(series, []).append(value)


def _pause(rng: random.Random, gate: threading.Event) -> None:
    # A random gap, so that trials do not lock in phase with the rover's 20 Hz traffic.
    gate.wait(rng.uniform(0.002, 0.012))


def run_latency(
    trials: int,
    warmup: int,
    tmp: Path,
    tactics: Path,
    seed: int,
    *,
    nodes: Mapping[str, float] | None,
    c_every: int,
    back_to_back: int = BACK_TO_BACK,
) -> tuple[Samples, dict[str, Any]]:
    """Setups (a), (b) and, with ``nodes`` (rates), (c), and the bus baselines, interleaved:
    every round runs (a) and (b), every ``c_every``-th round (c) too, in a shuffled order,
    then one sample of each bus round trip in a shuffled order."""
    rng = random.Random(seed)
    gate = threading.Event()
    samples = Samples()
    a: InprocSetup | None = None
    b: ZenohSetup | None = None
    c: NodesSetup | None = None
    base: InprocBaseline | None = None
    info: dict[str, Any] = {}
    try:
        a = InprocSetup(write_config(tmp, "utu-a", tactics, bus={"kind": "inproc"}))
        b = ZenohSetup(tmp, tactics)
        base = InprocBaseline()
        if nodes is not None:
            t0 = time.monotonic()
            try:
                c = NodesSetup(tmp, tactics, nodes)
                info["c_ready_after_s"] = round(time.monotonic() - t0, 2)
            except Exception as exc:  # report it, measure the rest
                info["c_failed"] = f"{type(exc).__name__}: {exc}"[:2000]
        setups: list[InprocSetup | ZenohSetup | NodesSetup] = [a, b]
        if c is not None:
            setups.append(c)
        for s in setups:
            s.rover.settle(gate)

        def one_round(i: int, record: bool) -> None:
            chosen = [s for s in setups if s.label != "c" or i % c_every == 0]
            for s in rng.sample(chosen, len(chosen)):
                lat, finished = s.rover.trial()
                if record:
                    samples.add(s.label, lat)
                if not finished:
                    samples.resettles[s.label] = samples.resettles.get(s.label, 0) + 1
                    s.rover.settle(gate)
                _pause(rng, gate)
            for probe in rng.sample(["zr", "zp", "ir", "ip"], 4):
                p = b.probe if probe[0] == "z" else base.probe
                v = p.request_rtt() if probe[1] == "r" else p.pubsub_rtt()
                if record:
                    samples.add(probe, v)

        for i in range(warmup):
            one_round(i, record=False)
        started = time.perf_counter()
        for i in range(trials):
            one_round(i, record=True)
        seconds = time.perf_counter() - started
        # bus_pingpong's own measurement, back to back, over the same sessions.
        rounds = {
            "zenoh": b.probe.back_to_back(back_to_back, back_to_back // 10),
            "inproc": base.probe.back_to_back(back_to_back, back_to_back // 10),
        }
        info |= {
            "seconds": round(seconds, 2),
            "back_to_back_us": rounds,
            "set_mode_requests": {s.label: len(s.rover.set_mode_ns) for s in setups},
            "stop_requests": {s.label: s.rover.stops for s in setups},
            "resettled_after_trial": samples.resettles,
            "a_knowledge": a.manager.knowledge.counts(),
        }
        return samples, info
    finally:
        for done in (base, a, b, c):
            if done is not None:
                done.close()


def run_nodes_fast(trials: int, tmp: Path, tactics: Path, seed: int, rate: float) -> dict[str, Any]:
    """(c) again with every node at ``rate`` Hz, alone (its nodes then cycle continuously,
    which would load the interleaved setups): how much of (c) the rate gates are."""
    gate = threading.Event()
    samples = Samples()
    c = NodesSetup(tmp, tactics, dict.fromkeys(example_node_rates(), rate))
    try:
        c.rover.settle(gate)
        for i in range(10 + trials):
            lat, finished = c.rover.trial()
            if i >= 10:
                samples.add("c", lat)
            if not finished:
                c.rover.settle(gate)
            _pause(random.Random(seed + i), gate)
    finally:
        c.close()
    return {
        "setup": f"as (c), every node at {rate:g} Hz, run alone after the interleaved rounds",
        **summary_ms(samples.ns.get("c", [])),
        "timeouts": samples.timeouts.get("c", 0),
    }


# -- breakdown of setup (a): where the time goes -----------------------------------------------
class _StampedClock(WallClock):
    """The wall clock, stamping each reading: a step reads its clock once, at its start
    (after taking its inputs), so the last reading before an action is that step's start."""

    def __init__(self) -> None:
        self.read_ns = 0

    def now(self) -> float:
        self.read_ns = time.perf_counter_ns()
        return super().now()


class _StampedActuator(BusActuator):
    """The bus actuator, stamping (step start, request) when the fail-safe's request leaves
    the step (sent without waiting, or on a worker thread), while armed."""

    def __init__(self, bus: Bus, clock: _StampedClock) -> None:
        super().__init__(bus)
        self.clock = clock
        self.armed = False
        self.stamps: list[tuple[int, int]] = []

    def request(self, service: str, payload: Mapping[str, Any], timeout: float) -> Any:
        self._stamp(service)
        return super().request(service, payload, timeout)

    def request_start(self, service: str, payload: Mapping[str, Any], timeout: float) -> Any:
        self._stamp(service)
        return super().request_start(service, payload, timeout)

    def _stamp(self, service: str) -> None:
        if self.armed and service == "/rover/set_mode":
            self.stamps.append((self.clock.read_ns, time.perf_counter_ns()))


def run_breakdown(trials: int, tmp: Path, tactics: Path, seed: int) -> dict[str, Any]:
    """Stamp each stage of the in-process path (instrumented, so not the headline figures).

    Stages: publish -> the step that takes the message starts (its clock reading) -> the
    step hands the fail-safe's request to the actuator (``actuator.request``) -> the rover's
    handler runs. Stamped through the manager's public hooks: the clock and the actuator it
    is built with.
    """
    config = write_config(tmp, "utu-prof", tactics, bus={"kind": "inproc"})
    clock = _StampedClock()
    stamped: list[_StampedActuator] = []

    def actuator(bus: Bus) -> _StampedActuator:
        stamped.append(_StampedActuator(bus, clock))
        return stamped[0]

    setup = InprocSetup(config, clock=clock, actuator=actuator)
    act = stamped[0]
    rover = setup.rover
    rng = random.Random(seed)
    gate = threading.Event()
    rows: list[tuple[int, int, int, int]] = []
    try:
        rover.settle(gate)
        for i in range(10 + trials):
            act.stamps.clear()
            act.armed = True
            t0, k = rover.violate()
            ok = rover.wait_set_mode(k)
            act.armed = False
            if ok and i >= 10 and act.stamps:
                step_t, action_t = act.stamps[0]
                rows.append((t0, step_t, action_t, rover.set_mode_ns[k]))
            if not (ok and rover.wait_state(_handed_over) and rover.reset()):
                rover.settle(gate)
            _pause(rng, gate)
    finally:
        setup.close()
    stages = {
        "publish_to_step_start": [r[1] - r[0] for r in rows],
        "step_start_to_action": [r[2] - r[1] for r in rows],
        "action_to_handler": [r[3] - r[2] for r in rows],
        "total": [r[3] - r[0] for r in rows],
    }
    return {name: summary_ms(v) for name, v in stages.items()}


class _StampingActuator(RecordingActuator):
    """Records actions, stamping the first request of each armed step."""

    def __init__(self) -> None:
        super().__init__(replies={"/rover/set_mode": {"ok": True, "mode": "manual"}})
        self.stamp: int | None = None

    def request(self, service: str, payload: Mapping[str, Any], timeout: float) -> Any:
        if self.stamp is None:
            self.stamp = time.perf_counter_ns()
        return super().request(service, payload, timeout)


def run_step_only(trials: int, tmp: Path, tactics: Path) -> dict[str, Any]:
    """The violation step alone, in one thread, no bus: ``feed`` the violation, ``step``,
    stamp when the step hands the fail-safe's request to the actuator. Then as many more
    violation steps under cProfile: where the step's own time goes (own time per step)."""
    config = _fresh_config(tmp, "step-only", tactics, bus={"kind": "inproc"})
    actuator = _StampingActuator()
    m = AutonomicManager.from_config(
        config, knowledge=Knowledge(config.knowledge), actuator=actuator
    )
    t = 0.0
    seq = 0

    def nominal_inputs(mode: str, assessment: Mapping[str, Any]) -> None:
        nonlocal t, seq
        seq += 1
        m.feed("/rover/status", {"mode": mode, "buzzer": False, "bumper": False, "lights": True})
        m.feed("/rover/camera/info", {"seq": seq, "width": 640, "height": 480})
        m.feed("/rover/ultrasonic", {"range": 2.0 + 0.01 * (seq % 50)})
        m.feed("/utu/oracle/output", dict(assessment))
        t += 0.05
        m.step(t)

    for _ in range(12):
        nominal_inputs("autonomous", CLEAR)
    profiler = cProfile.Profile()
    ns: list[int] = []
    for i in range(2 * trials):
        nominal_inputs("autonomous", CLEAR)
        if m.analyzer.eligible():
            raise RuntimeError(f"step-only: not nominal: {m.analyzer.eligible()}")
        actuator.stamp = None
        m.feed("/utu/oracle/output", dict(VIOLATION))
        t += 0.005
        profiled = i >= trials
        t0 = time.perf_counter_ns()
        if profiled:
            profiler.enable()
        m.step(t)
        if profiled:
            profiler.disable()
        elif actuator.stamp is not None:
            ns.append(actuator.stamp - t0)
        nominal_inputs("manual", VIOLATION)  # the rover obeyed: postcondition verified
        nominal_inputs("manual", CLEAR)
    m.close()
    rows = _profile_rows(profiler)
    return {
        "violation_step_to_action": summary_ms(ns),
        "whole_violation_step_profiled_us": round(
            sum(r[0] for r in rows) / max(trials, 1) * 1e6, 1
        ),
        "profile_own_time_per_violation_step": [
            {
                "function": name,
                "own_us": round(tt / trials * 1e6, 1),
                "cumulative_us": round(ct / trials * 1e6, 1),
                "calls": round(nc / trials, 2),
            }
            for tt, ct, nc, name in rows[:15]
        ],
    }


# -- Monitor throughput ----------------------------------------------------------------------
def rover_messages(n: int, seed: int) -> list[tuple[str, dict[str, Any]]]:
    """``n`` messages of the rover's sensor topics, round-robin, every value changing."""
    rng = random.Random(seed)
    out: list[tuple[str, dict[str, Any]]] = []
    for i in range(n):
        k = i % 4
        if k == 0:
            out.append(("/rover/ultrasonic", {"range": round(1.5 + rng.random(), 4)}))
        elif k == 1:
            out.append(
                (
                    "/rover/status",
                    {"mode": "autonomous", "buzzer": False, "bumper": False, "lights": i % 8 == 1},
                )
            )
        elif k == 2:
            out.append(("/rover/camera/info", {"seq": i, "width": 640, "height": 480}))
        else:
            out.append(
                ("/utu/oracle/output", {"category": 0, "confidence": round(rng.random(), 4)})
            )
    return out


def _fresh_config(tmp: Path, name: str, tactics: Path, **kw: Any) -> UtuConfig:
    db = tmp / f"{name}.db"
    for suffix in ("", "-wal", "-shm"):
        Path(f"{db}{suffix}").unlink(missing_ok=True)
    return load_config(write_config(tmp, name, tactics, **kw))


def throughput_feed(
    messages: list[tuple[str, dict[str, Any]]], batch: int, tmp: Path, tactics: Path
) -> dict[str, Any]:
    """``feed`` + ``step`` in batches; sim time advances 1 ms per message, each message fed at
    its own arrival time (as the bus's sender stamps do live)."""
    config = _fresh_config(tmp, f"feed-{batch}", tactics, bus={"kind": "inproc"})
    knowledge = Knowledge(config.knowledge)
    with contextlib.closing(sqlite3.connect(config.knowledge)) as db:  # WAL is the file's
        mode = db.execute("PRAGMA journal_mode").fetchone()[0]
    manager = AutonomicManager.from_config(config, knowledge=knowledge)  # no bus: recorded
    t = 0.0
    # Nominal first, with rates defined (one message per topic 50 ms apart).
    for j in range(12):
        for topic, msg in messages[j * 4 : j * 4 + 4]:
            manager.feed(topic, msg)
        t += 0.05
        manager.step(t)
    decisions0 = knowledge.decisions_written
    n = len(messages)
    cpu0 = time.process_time()
    start = time.perf_counter()
    for i in range(0, n, batch):
        for topic, msg in messages[i : i + batch]:
            t += 0.001  # each message keeps its own arrival time
            manager.feed(topic, msg, t=t)
        manager.step(t)
    knowledge.flush()
    elapsed = time.perf_counter() - start
    cpu = time.process_time() - cpu0
    taken = sum(ts.count for ts in manager.monitor.topics.values()) - 48
    counts = knowledge.counts()
    manager.close()
    return {
        "batch": batch,
        "messages": n,
        "taken": taken,
        "seconds": round(elapsed, 3),
        "msgs_per_s": round(taken / elapsed),
        "cpu_us_per_msg": round(cpu / taken * 1e6, 1),
        "inputs_rows": counts["inputs"],
        "decisions_during_run": counts["decisions"] - decisions0,
        "journal_mode": mode,
    }


def throughput_bus(
    messages: list[tuple[str, dict[str, Any]]], tmp: Path, tactics: Path
) -> dict[str, Any]:
    """Publish on the in-process bus as fast as one thread can; a spinning manager takes them.

    The manager's input queues are as large as the run, so none is dropped; actions are only
    recorded (no rover here).
    """
    n = len(messages)
    config = _fresh_config(tmp, "bus-tp", tactics, bus={"kind": "inproc"}, queue=n + 100)
    bus = open_bus("inproc", name="bench-tp")
    manager = AutonomicManager.from_config(config, bus=bus, actuator=RecordingActuator())
    pubs = {topic: bus.publisher(topic) for topic in {t for t, _ in messages}}
    stop = threading.Event()
    steps = 0

    def count_steps(_m: AutonomicManager) -> None:
        nonlocal steps
        steps += 1

    thread = threading.Thread(
        target=manager.spin,
        args=(stop,),
        kwargs={"rate": config.rate, "on_step": count_steps},
        daemon=True,
    )
    gate = threading.Event()
    # Nominal first (rates defined), then wait for the manager to have taken it.
    thread.start()
    for j in range(12):
        for topic, msg in messages[j * 4 : j * 4 + 4]:
            pubs[topic].put(msg)
        gate.wait(0.05)

    def taken() -> int:
        return sum(ts.count for ts in manager.monitor.topics.values())

    deadline = time.monotonic() + WAIT
    while taken() < 48 and time.monotonic() < deadline:
        gate.wait(0.005)
    base = taken()
    decisions0 = manager.knowledge.decisions_written
    steps0 = steps
    cpu0 = time.process_time()
    start = time.perf_counter()
    for topic, msg in messages:
        pubs[topic].put(msg)
    published = time.perf_counter() - start
    deadline = time.monotonic() + 120.0
    while taken() - base < n and time.monotonic() < deadline:
        gate.wait(0.001)
    manager.knowledge.flush()
    elapsed = time.perf_counter() - start
    cpu = time.process_time() - cpu0
    got = taken() - base
    decisions = manager.knowledge.decisions_written - decisions0
    stats = bus.stats().totals()
    nsteps = steps - steps0
    stop.set()
    manager.wake()
    thread.join(timeout=5.0)
    manager.close()
    bus.close()
    return {
        "messages": n,
        "taken": got,
        "seconds": round(elapsed, 3),
        "msgs_per_s": round(got / elapsed),
        "cpu_us_per_msg": round(cpu / max(got, 1) * 1e6, 1),
        "publish_only_msgs_per_s": round(n / published),
        "steps": nsteps,
        "mean_batch": round(got / max(nsteps, 1), 1),
        "decisions_during_run": decisions,
        "dropped": stats["dropped"],
    }


def profile_feed(
    messages: list[tuple[str, dict[str, Any]]], batch: int, tmp: Path, tactics: Path
) -> list[dict[str, Any]]:
    """cProfile of the feed/step path: where a monitored message's time goes."""
    config = _fresh_config(tmp, "feed-prof", tactics, bus={"kind": "inproc"})
    manager = AutonomicManager.from_config(config, knowledge=Knowledge(config.knowledge))
    profiler = cProfile.Profile()
    t = 0.0
    profiler.enable()
    for i in range(0, len(messages), batch):
        for topic, msg in messages[i : i + batch]:
            manager.feed(topic, msg)
        t += 0.001 * batch
        manager.step(t)
    manager.knowledge.flush()
    profiler.disable()
    manager.close()
    return _own_time_rows(profiler, len(messages), "msg", 15)


def profile_bus(
    messages: list[tuple[str, dict[str, Any]]], batch: int, tmp: Path, tactics: Path
) -> list[dict[str, Any]]:
    """cProfile of the in-process bus path in one thread: publish ``batch`` messages, then
    ``step`` (drain, decode, monitor, analyze, persist); own time per message."""
    config = _fresh_config(tmp, "bus-prof", tactics, bus={"kind": "inproc"}, queue=10 * batch)
    bus = open_bus("inproc", name="bench-prof")
    manager = AutonomicManager.from_config(config, bus=bus, actuator=RecordingActuator())
    pubs = {topic: bus.publisher(topic) for topic in {t for t, _ in messages}}
    profiler = cProfile.Profile()
    t = 0.0
    profiler.enable()
    for i in range(0, len(messages), batch):
        for topic, msg in messages[i : i + batch]:
            pubs[topic].put(msg)
        t += 0.001 * batch
        manager.step(t)
    manager.knowledge.flush()
    profiler.disable()
    manager.close()
    bus.close()
    return _own_time_rows(profiler, len(messages), "msg", 18)


def _profile_rows(profiler: cProfile.Profile) -> list[tuple[float, float, int, str]]:
    """(own s, cumulative s, calls, ``file:line(function)``) per function, most own time first."""
    # typeshed's pstats.Stats leaves out ``stats``, the table pstats prints from (a dict of
    # (file, line, function) to (primitive calls, calls, own s, cumulative s, callers)).
    table: dict[tuple[str, int, str], tuple[int, int, float, float, Any]]
    table = pstats.Stats(profiler, stream=io.StringIO()).stats  # type: ignore[attr-defined]
    return sorted(
        (
            (tt, ct, nc, f"{Path(f).name}:{line}({func})")
            for (f, line, func), (_cc, nc, tt, ct, _) in table.items()
        ),
        reverse=True,
    )


def _own_time_rows(profiler: cProfile.Profile, per: int, unit: str, n: int) -> list[dict[str, Any]]:
    rows = _profile_rows(profiler)
    total = sum(r[0] for r in rows)
    out: list[dict[str, Any]] = [
        {
            "function": name,
            f"own_us_per_{unit}": round(tt / per * 1e6, 2),
            f"cumulative_us_per_{unit}": round(ct / per * 1e6, 2),
            f"calls_per_{unit}": round(nc / per, 2),
            "share_of_total": round(tt / total, 3) if total else None,
        }
        for tt, ct, nc, name in rows[:n]
    ]
    out.append(
        {"function": "(all, under cProfile)", f"own_us_per_{unit}": round(total / per * 1e6, 1)}
    )
    return out


# -- machine and (c) ---------------------------------------------------------------------------
def machine_info() -> dict[str, Any]:
    info: dict[str, Any] = {
        "python": platform.python_version(),
        "implementation": platform.python_implementation(),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "cpus": os.cpu_count(),
        "gil_switch_interval_s": sys.getswitchinterval(),
        "sqlite": __import__("sqlite3").sqlite_version,
    }
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                info["cpu"] = line.split(":", 1)[1].strip()
                break
    with contextlib.suppress(OSError):
        info["loadavg_start"] = [float(x) for x in os.getloadavg()]
    for pkg in ("eclipse-zenoh", "pydantic", "pydantic-core"):
        with contextlib.suppress(Exception):
            info[pkg] = version(pkg)
    return info


def _report_log(path: Path, what: str) -> None:
    """Print the tail of a child's log when it shows an error (the log dies with tmp)."""
    with contextlib.suppress(OSError):
        text = path.read_text(errors="replace")
        if "Traceback" in text or "ERROR" in text:
            print(f"--- {what} logged errors ({path.name}):\n{text[-3000:]}", file=sys.stderr)


def per_node_mode() -> bool:
    """Whether ``anunnaki node`` (one process per Utu node) exists in this tree."""
    return (
        all(importlib.util.find_spec(m) is not None for m in ("anunnaki.utu.host", "anunnaki.cli"))
        and (ROVER / "utu.yaml").is_file()
    )


# -- main ----------------------------------------------------------------------------------
def _aim(figure: float, aim: float, *, at_most: bool) -> dict[str, Any]:
    return {"aim": aim, "met": figure <= aim if at_most else figure >= aim}


def table(result: dict[str, Any]) -> str:
    lines = [
        f"{'series':<44}{'p50':>8}{'p90':>8}{'p99':>8}{'max':>8}{'n':>6}  (ms)",
    ]
    r = result["reaction_ms"]
    rows = [
        ("(a) reaction, one process, inproc bus", r["a"]),
        ("(b) reaction, manager in a child, zenoh", r["b"]),
    ]
    for name, key in (
        ("zenoh request/reply round trip", "request_rtt"),
        ("zenoh publish/subscribe ping-pong", "pubsub_rtt"),
    ):
        rows.append((f"    baseline: {name}", result["bus_baseline_ms"]["zenoh"][key]))
    for name, key in (
        ("inproc request/reply round trip", "request_rtt"),
        ("inproc publish/subscribe ping-pong", "pubsub_rtt"),
    ):
        rows.append((f"    baseline: {name}", result["bus_baseline_ms"]["inproc"][key]))
    if "p50" in r["c"]:
        rows.append(("(c) reaction, one process per node", r["c"]))
    if "p50" in r.get("c_fast", {}):
        rows.append(("    (c) with every node at 1000 Hz", r["c_fast"]))
    for name, s in rows:
        lines.append(
            f"{name:<44}{s['p50']:>8.3f}{s['p90']:>8.3f}{s['p99']:>8.3f}{s['max']:>8.3f}{s['n']:>6}"
        )
    if "status" in r["c"]:
        lines.append(f"{'(c) one process per node':<44}{r['c']['status']}")
    lines.append("")
    tp = result["monitor_throughput"]
    for row in tp["feed"]:
        lines.append(
            f"Monitor, feed+step (batch {row['batch']:>4}):{'':<10}{row['msgs_per_s']:>10,} msgs/s"
        )
    lines.append(
        f"Monitor, through the inproc bus:{'':<13}{tp['inproc_bus']['msgs_per_s']:>10,} msgs/s"
    )
    lines.append("")
    for name, aim in result["aims"].items():
        lines.append(f"aim {name}: {aim['aim']} -> {'met' if aim['met'] else 'MISSED'}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=500, help="recorded trials per setup")
    parser.add_argument("--warmup", type=int, default=30, help="unrecorded rounds first")
    parser.add_argument("--messages", type=int, default=50_000, help="throughput messages")
    parser.add_argument("--breakdown", type=int, default=150, help="instrumented (a) trials")
    parser.add_argument("--c-every", type=int, default=2, help="(c) runs every N-th round")
    parser.add_argument(
        "--fast-trials", type=int, default=100, help="trials of (c) at 1000 Hz (0: skip)"
    )
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument(
        "--quick",
        action="store_true",
        help="a few trials and messages of everything (the suite runs this; figures are "
        "not meaningful)",
    )
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT)
    parser.add_argument("--serve-manager", metavar="CONFIG", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve_manager:
        return serve_manager(args.serve_manager)
    if args.quick:
        args.trials, args.warmup, args.messages = 4, 1, 2000
        args.breakdown, args.c_every, args.fast_trials = 4, 4, 0
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    began = time.perf_counter()
    tmp = Path(tempfile.mkdtemp(prefix="anunnaki-reaction-"))
    try:
        tactics = write_files(tmp)
        machine = machine_info()
        print(f"reaction latency: {args.trials} trials per setup, interleaved ...", flush=True)
        nodes = example_node_rates() if per_node_mode() else None
        samples, info = run_latency(
            args.trials,
            args.warmup,
            tmp,
            tactics,
            args.seed,
            nodes=nodes,
            c_every=args.c_every,
            back_to_back=50 if args.quick else BACK_TO_BACK,
        )
        c_fast = None
        if nodes is not None and args.fast_trials > 0 and "c_failed" not in info:
            print("(c) with every node at 1000 Hz, alone ...", flush=True)
            c_fast = run_nodes_fast(args.fast_trials, tmp, tactics, args.seed + 4, 1000.0)
        print("where the time goes in (a) (instrumented trials) ...", flush=True)
        breakdown = run_breakdown(args.breakdown, tmp, tactics, args.seed + 10)
        breakdown["step_only"] = run_step_only(args.breakdown, tmp, tactics)
        print(f"Monitor throughput: {args.messages:,} messages ...", flush=True)
        messages = rover_messages(args.messages, args.seed)
        feed = [throughput_feed(messages, batch, tmp, tactics) for batch in (10, 100, 1000)]
        via_bus = throughput_bus(messages, tmp, tactics)
        feed_profile = profile_feed(messages[:20_000], 100, tmp, tactics)
        bus_profile = profile_bus(messages[:20_000], 100, tmp, tactics)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    with contextlib.suppress(OSError):
        machine["loadavg_end"] = [float(x) for x in os.getloadavg()]
    reaction = {
        "a": {
            "setup": "one process, in-process bus; the manager spins in a thread",
            **summary_ms(samples.ns.get("a", [])),
            "timeouts": samples.timeouts.get("a", 0),
        },
        "b": {
            "setup": "rover+oracle here, whole manager in a child process; zenoh peers on "
            "tcp/127.0.0.1, scouting off",
            **summary_ms(samples.ns.get("b", [])),
            "timeouts": samples.timeouts.get("b", 0),
        },
    }
    if nodes is None:
        reaction["c"] = {"status": "not measured: per-node mode not available"}
    elif "c_failed" in info:
        reaction["c"] = {"status": f"not measured: per-node mode failed: {info['c_failed']}"}
    else:
        reaction["c"] = {
            "setup": "rover+oracle here; monitor, analyze, plan, execute, knowledge each in "
            "its own process (anunnaki node NAME --connect ... --mode client), one shared "
            "knowledge file; node rates of examples/rover/utu.yaml",
            "node_rates_hz": nodes,
            **summary_ms(samples.ns.get("c", [])),
            "timeouts": samples.timeouts.get("c", 0),
            "note": "every node acts on a message as it arrives (event-driven); the node rates "
            "only pace watermarks, ticks without a monitor and decision publications",
        }
        if c_fast is not None:
            reaction["c_fast"] = c_fast
    baseline: dict[str, dict[str, Any]] = {
        "zenoh": {
            "setup": "the same two zenoh sessions as (b): this process <-> the manager's child",
            "request_rtt": summary_ms(samples.ns.get("zr", [])),
            "pubsub_rtt": summary_ms(samples.ns.get("zp", [])),
        },
        "inproc": {
            "setup": "two in-process buses on one hub, in this process (as bus_pingpong)",
            "request_rtt": summary_ms(samples.ns.get("ir", [])),
            "pubsub_rtt": summary_ms(samples.ns.get("ip", [])),
        },
        "timeouts": {k: v for k, v in samples.timeouts.items() if k not in ("a", "b", "c")},
    }
    headline_feed = next(r for r in feed if r["batch"] == 100)
    # Each reaction against the bus's own round trip in the same run: how many round trips
    # the reaction costs (the path has one request/reply at least: the action itself).
    pairs = {"a": ("inproc", "a"), "b": ("zenoh", "b"), "c": ("zenoh", "c")}
    for label, (kind, key) in pairs.items():
        rtt = baseline[kind]["request_rtt"]
        got = reaction[key]
        if "p50" in got and rtt.get("p50"):
            got["ratio_to_bus_request_rtt"] = {
                q: round(got[q] / rtt[q], 2) for q in ("p50", "p90", "p99") if rtt.get(q)
            }
            got["ratio_baseline"] = f"{kind} request/reply round trip, same run ({label})"
    aims = {
        "a_p99_ms": _aim(reaction["a"]["p99"], AIMS["a_p99_ms"], at_most=True),
        "b_p99_ms": _aim(reaction["b"]["p99"], AIMS["b_p99_ms"], at_most=True),
        **(
            {"c_p99_ms": _aim(reaction["c"]["p99"], AIMS["c_p99_ms"], at_most=True)}
            if "p99" in reaction["c"]
            else {}
        ),
        "monitor_feed_msgs_per_s": _aim(
            headline_feed["msgs_per_s"], AIMS["monitor_msgs_per_s"], at_most=False
        ),
        "monitor_inproc_bus_msgs_per_s": _aim(
            via_bus["msgs_per_s"], AIMS["monitor_msgs_per_s"], at_most=False
        ),
    }
    result = {
        "benchmark": "reaction",
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "machine": machine,
        "method": {
            "trials_per_setup": args.trials,
            "warmup_rounds": args.warmup,
            "interleaved": "each round runs (a) and (b) (and (c) once every "
            f"{args.c_every} rounds) in a shuffled order, then one sample of each bus round "
            "trip, in a shuffled order; (c) at 1000 Hz runs alone afterwards",
            "violation": {"topic": "/utu/oracle/output", "message": VIOLATION},
            "first_action": "/rover/set_mode request arriving at the rover's service handler",
            "clock": "time.perf_counter_ns in the rover/oracle process, both ends",
            "config": {"dwell": 0, "warmup": 0, "tactic_cooldown": 0, "rate_hz": 20},
            "knowledge": "SQLite file in a temporary folder, WAL, synchronous=NORMAL",
            "background_traffic_hz": RATES,
            "throughput_messages": args.messages,
        },
        "aims": aims,
        "reaction_ms": reaction,
        "bus_baseline_ms": baseline,
        "run": info,
        "breakdown_a_ms": breakdown,
        "monitor_throughput": {
            "feed": feed,
            "inproc_bus": via_bus,
            "headline": {
                "feed_batch_100_msgs_per_s": headline_feed["msgs_per_s"],
                "inproc_bus_msgs_per_s": via_bus["msgs_per_s"],
            },
            "note": "every input is nominal, so decisions_during_run must be 0 (each input keeps "
            "its own arrival time: a burst taken by one step does not make rate(A3) unknown). "
            "cpu_us_per_msg is the process's CPU time per message (less sensitive than "
            "msgs_per_s to other load on the machine). Through the in-process bus the manager "
            "reacts to each message in the publishing thread, so publish, encode, decode and "
            "the incremental analysis of every message are on that one thread.",
            "feed_profile_top": feed_profile,
            "inproc_bus_profile_top": bus_profile,
        },
        "wall_seconds": round(time.perf_counter() - began, 1),
    }
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    print()
    print(table(result))
    print(f"\nwrote {args.output} in {result['wall_seconds']} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
