"""The whole loop's throughput: simulator, phenomena, bus, detector, oracle and Utu.

Two loops, each with the learned ``enlil`` oracles as agent A4 (issue #24):

* the rover's, ``examples/rover/demo.yaml`` (what ``make demo`` runs: 128 × 128 camera at
  10 Hz, the HSL/fog/raindrop scenario, the registry of ``examples/models/rover.yaml``, the
  oracle of the active model; aim 20 Hz);
* the UAV's, ``examples/uav/sim.yaml`` (320 × 240 camera at 10 Hz, the delivery scenario
  from take-off, uav-default/uav-fog and their oracles; aim 10 Hz).

Each is run flat out — ``--speed`` far above what the machine can keep, with the simulator
in lockstep with the detector and the oracle: a frame is not followed by the next until its
detections and its assessment are out — and timed in wall seconds, in two layouts:

**one process** (the launch as ``anunnaki run`` starts it, on the in-process bus), in four
stages, each adding a part, so the ratios show what each part costs:

* ``platform``: the platform alone (physics, rendering, phenomena, JPEG, publishing);
* ``detector``: + the LEC node running the active model on every frame, in lockstep;
* ``oracle``: + the oracle node (enlil);
* ``utu``: the whole launch, + Utu's monitor, analyzer, planner, executor and knowledge.

**one process per component** (``processes``): the platform, the detector (the LEC node),
the oracle node and Utu (the composed manager with the launch's five nodes) each in a
process of its own, on zenoh over ``tcp/127.0.0.1`` (multicast scouting off): the platform's
session listens, the other three join it as clients, as ``anunnaki run --processes`` has
its nodes join the launch's session. The platform waits for each frame's detections and its
assessment (an acknowledgement the oracle's process publishes once its node has handled the
frame) before the next, as in one process. Every process reports what flowed through it
(frames rendered, detected, assessed; the oracle's verdicts Utu took in). Only the
detector's and the oracle's processes load torch (``torch_threads``: ``null`` for the
others): the platform and Utu run no network.

The figure of merit is camera frames per wall second of the whole loop (``utu`` in one
process; ``processes``). Beside it, each run gives the CPU time per frame
(``cpu_ms_per_frame``): of the one process (every thread: simulator, detector, oracle,
Utu), or of each component's process and their sum. On a machine shared with other work the
frame rate measures the load as much as the loop, the CPU time much less so; the sum is what
must fit the cores' budget (two cores at 10 Hz: 200 ms per frame).

The stages and the layouts of a repeat run one after the other, so the ratios between them
come from the same minutes of the same machine. A launch's live ground-truth scorer is
scoring, not the loop: it is left out (``"scorer": "off"``). The rover's figures stay at the
top level of the results (as before); the UAV's are under ``"uav"``. Writes
``benchmarks/results/loop.json``::

    .venv/bin/python benchmarks/loop.py
    .venv/bin/python benchmarks/loop.py --seconds 10 --repeats 1 --output /tmp/loop.json
    .venv/bin/python benchmarks/loop.py --loops uav        # the UAV's loop only
    .venv/bin/python benchmarks/loop.py --layouts one_process  # the four stages only
    .venv/bin/python benchmarks/loop.py --torch-threads 0,1    # torch's default threads vs 1
    .venv/bin/python benchmarks/loop.py --loops uav --profile runs/profile.json  # where it goes

``--profile`` runs the whole loop in one process under cProfile, every thread on its own CPU
clock, and writes the CPU time per frame of each part (:data:`PARTS`) instead.

``--cli`` times the command a user runs instead, scorer and bring-up included: ``anunnaki run
LAUNCH --speed 0 --until SECONDS --report FILE`` in a process of its own, ``--repeats`` times
per loop: simulated seconds per wall second, the process's CPU seconds (user + system, its
children's clock), the run's own wall time (the ``simulated … in … s wall`` line) and the
report's sha256. With ``--cli-against DIR`` (another checkout, e.g. ``git archive main``
unpacked) its runs alternate with this checkout's, the same launch files from each, so the
before/after pairs share the minutes of a shared machine, and the reports are compared byte
for byte (``reports_identical``)::

    .venv/bin/python benchmarks/loop.py --cli --seconds 20 --repeats 2 \
        --cli-against /tmp/main --output benchmarks/results/sim-speed.json
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import os
import platform
import queue
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import IO, Any

from anunnaki import topics
from anunnaki.bus import BusConfig, Executor, open_bus
from anunnaki.launch import Launch, load_launch, run_launch
from anunnaki.managed import SimKind, SimulatedSystem

ROOT = Path(__file__).parents[1]
LAUNCH = ROOT / "examples" / "rover" / "demo.yaml"
UAV_LAUNCH = ROOT / "examples" / "uav" / "sim.yaml"
AIM_HZ = {"rover": 20.0, "uav": 10.0}  # issue #24
RESULTS = Path(__file__).parent / "results" / "loop.json"
FAST = 1000.0  # simulated seconds per wall second asked for: far beyond the machine
STAGES = ("platform", "detector", "oracle", "utu")
LAYOUTS = ("one_process", "processes")
COMPONENTS = ("platform", "detector", "oracle", "utu")
#: Where the oracle's process acknowledges each frame its node has handled (assessed,
#: withheld or skipped): the platform's lockstep across processes. The benchmark's own.
HANDLED = "/bench/loop/oracle_handled"
#: The longest a frame waits for its detections and its assessment (wall seconds); the
#: one-process lockstep waits 2 s, but a process on a loaded machine may be descheduled.
LOCKSTEP_TIMEOUT = 10.0
#: Seconds a component process gets to come up (imports, models, bus) and to finish.
BRING_UP = 180.0
#: A line of the components' protocol on stdout starts with this (anything else is noise).
TAG = "@loop "


def _torch() -> Any:
    """torch, imported when first asked: a component's process that does not run a network
    (the platform, Utu) does not load it, as the launch's own nodes do not."""
    import torch

    return torch


def _component_threads(threads: int) -> int | None:
    """torch's threads in this component's process, set to ``threads`` (> 0) once its
    bring-up has loaded torch; ``None`` when it did not (the platform's and Utu's)."""
    if "torch" not in sys.modules:
        return None
    torch = _torch()
    if threads > 0:
        torch.set_num_threads(threads)
    return int(torch.get_num_threads())


def _launch(path: Path, oracle: Mapping[str, Any] | None = None) -> tuple[Launch, SimKind]:
    """The launch, without its live scorer (scoring, not the loop; see above).

    ``oracle``: options to set on the launch's oracle (e.g. ``{"blas_threads": None}``).
    """
    launch = load_launch(path)
    assert isinstance(launch.managed, SimKind)
    options = launch.managed.options
    update: dict[str, Any] = {"scorer": None}
    if oracle:
        update["oracle"] = {**(options.oracle or {}), **oracle}
    launch.managed.options = options.model_copy(update=update)
    return launch, launch.managed


class _FrameClock:
    """Wall and process CPU time at the first and the last camera frame of a run.

    Subscribed on the launch's bus through ``run_launch``'s ``on_bus`` hook, so the whole
    launch is timed from its first frame to its last, without its bring-up (Utu's nodes,
    the models and the scene loading), as the other stages are.
    """

    def __init__(self, camera: str) -> None:
        self.camera = camera
        self.frames = 0
        self.first = self.last = (0.0, 0.0)
        self._lock = threading.Lock()

    def attach(self, bus: Any) -> None:
        bus.subscribe(self.camera, self._on_frame, queue=256)  # closes with the bus

    def _on_frame(self, sample: Any) -> None:
        now = (time.perf_counter(), time.process_time())
        with self._lock:
            if self.frames == 0:
                self.first = now
            self.last = now
            self.frames += 1

    def per_frame(self) -> tuple[float, float]:
        """Frames per wall second and CPU ms per frame, from the first frame to the last."""
        with self._lock:
            n = max(self.frames - 1, 1)
            wall, cpu = self.last[0] - self.first[0], self.last[1] - self.first[1]
        return n / max(wall, 1e-9), 1000 * cpu / n


def _camera_topic(scenario: Any) -> str:
    from anunnaki.sim import RoverSim, UavSim

    return f"{(RoverSim if scenario.platform == 'rover' else UavSim).prefix}/camera/image"


def stage(
    name: str, seconds: float, launch_path: Path, oracle: Mapping[str, Any] | None = None
) -> dict[str, float]:
    """Run one stage in this process for ``seconds`` of simulated time; frames and wall time.

    The ``utu`` stage (the whole launch, ``run_launch``) is timed from its first camera
    frame to its last; ``run_s`` is its managed system's run with its bring-up, and
    ``fps_with_bring_up`` the frames over it (how this stage was timed before 2026-11-27).
    """
    launch, managed = _launch(launch_path, oracle)
    sim = managed.options
    if name == "utu":
        from anunnaki.sim import load_scenario

        out = io.StringIO()
        clock = _FrameClock(_camera_topic(load_scenario(sim.scenario)))
        t0 = time.perf_counter()
        result = run_launch(
            launch, speed=FAST, until=seconds, out=out, handle_signals=False, on_bus=clock.attach
        )
        wall = time.perf_counter() - t0
        line = next(x for x in out.getvalue().splitlines() if x.startswith("simulated "))
        frames = int(line.split("(")[1].split()[0])
        fps, cpu_ms = clock.per_frame()
        return {
            "frames": frames,
            "wall_s": round(wall, 3),
            "run_s": round(result.ran, 3),
            "fps": round(fps, 2),
            "fps_with_bring_up": round(frames / result.ran, 2),
            "cpu_ms_per_frame": round(cpu_ms, 1),
            "decisions": len(result.decisions),
        }
    with open_bus("inproc", executor=Executor()) as bus:
        system = SimulatedSystem(
            bus,
            sim.scenario,
            models=sim.models if name in ("detector", "oracle") else None,
            oracle=sim.oracle if name == "oracle" else None,
        )
        with system:
            t0, cpu0 = time.perf_counter(), time.process_time()
            system.run(threading.Event(), speed=FAST, until=seconds)
            wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
            frames = system.platform.frames
    return {
        "frames": frames,
        "wall_s": round(wall, 3),
        "fps": round(frames / wall, 2),
        "cpu_ms_per_frame": round(1000 * cpu / max(frames, 1), 1),
    }


# -- one process per component ------------------------------------------------------------------
class _Child:
    """One component's process: its protocol lines on a queue, its errors in a file."""

    def __init__(self, name: str, argv: list[str]) -> None:
        self.name = name
        # closed in close(), after the process has ended
        self.errors: IO[str] = tempfile.TemporaryFile("w+", encoding="utf-8")  # noqa: SIM115
        self.proc = subprocess.Popen(
            argv,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self.errors,
            text=True,
            bufsize=1,
            cwd=ROOT,
        )
        self.lines: queue.Queue[dict[str, Any] | None] = queue.Queue()
        threading.Thread(target=self._read, name=f"loop-{name}", daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            if line.startswith(TAG):
                self.lines.put(json.loads(line[len(TAG) :]))
        self.lines.put(None)  # the process closed its output: it has ended

    def expect(self, key: str, timeout: float) -> dict[str, Any]:
        """The next protocol message, which must hold ``key``."""
        try:
            message = self.lines.get(timeout=timeout)
        except queue.Empty:
            message = None
            why = f"said nothing within {timeout:g} s"
        else:
            why = "ended"
        if message is None or key not in message:
            raise RuntimeError(
                f"the {self.name} process {why} (waiting for {key!r}): "
                f"{message if message is not None else self.stderr()}"
            )
        return message

    def send(self, word: str) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(word + "\n")
        self.proc.stdin.flush()

    def stderr(self) -> str:
        self.errors.seek(0)
        return self.errors.read()[-3000:]

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        for stream in (self.proc.stdin, self.proc.stdout):
            if stream is not None:
                stream.close()
        self.errors.close()


def _child_argv(
    name: str,
    launch: Path,
    bus: BusConfig,
    seconds: float,
    threads: int,
    oracle: Mapping[str, Any] | None,
) -> list[str]:
    return [
        sys.executable,
        str(Path(__file__).resolve()),
        "--component",
        name,
        "--launch",
        str(launch),
        "--bus-json",
        bus.model_dump_json(exclude_none=True),
        "--seconds",
        repr(seconds),
        "--torch-threads",
        str(threads),
        "--oracle-json",
        json.dumps(dict(oracle or {})),
    ]


def processes_run(
    launch: Path,
    seconds: float,
    *,
    torch_threads: int = 0,
    oracle: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """One run of the loop with one process per component; rates, CPU time, what flowed.

    ``torch_threads``: torch's intra-op threads in each component's process (0: torch's
    default, one per core); ``oracle``: options set on the launch's oracle.
    """
    listen = BusConfig(kind="zenoh", mode="peer")  # on a free loopback port, no scouting
    children: dict[str, _Child] = {}
    try:
        children["platform"] = _Child(
            "platform", _child_argv("platform", launch, listen, seconds, torch_threads, oracle)
        )
        endpoints = children["platform"].expect("ready", BRING_UP)["endpoints"]
        for name in COMPONENTS[1:]:
            join = BusConfig(kind="zenoh", mode="client", connect=endpoints, name=f"loop-{name}")
            children[name] = _Child(
                name, _child_argv(name, launch, join, seconds, torch_threads, oracle)
            )
        for name in COMPONENTS[1:]:
            children[name].expect("ready", BRING_UP)
        children["platform"].send("peers")  # it waits to see the others' nodes on the bus
        children["platform"].expect("peers", BRING_UP)
        for name in (*COMPONENTS[1:], "platform"):  # the platform last: it starts the frames
            children[name].send("go")
        ran = children["platform"].expect("ran", BRING_UP + 60 * seconds)
        for child in children.values():
            child.send("stop")
        done = {name: child.expect("cpu_s", BRING_UP) for name, child in children.items()}
        for child in children.values():
            child.proc.wait(timeout=BRING_UP)
    finally:
        for child in children.values():
            child.close()
    frames = int(ran["frames"])
    cpu = {name: round(1000 * float(d["cpu_s"]) / max(frames, 1), 1) for name, d in done.items()}
    wall = float(ran["wall_s"])
    return {
        "frames": frames,
        "wall_s": round(wall, 3),
        "fps": round(frames / wall, 2),
        "cpu_ms_per_frame": round(sum(cpu.values()), 1),
        "cpu_ms_per_frame_by_process": cpu,
        # cores each process kept busy (its CPU seconds per wall second of the run)
        "cores_by_process": {n: round(float(d["cpu_s"]) / wall, 2) for n, d in done.items()},
        "lockstep_timeouts": int(ran["timeouts"]),
        "flow": {
            name: {k: v for k, v in d.items() if k not in ("cpu_s", "torch_threads")}
            for name, d in done.items()
        },
        "torch_threads": {name: d.get("torch_threads") for name, d in done.items()},
    }


class _Lockstep:
    """The platform's frame hook across processes: wait for the frame's detections and the
    oracle process's acknowledgement, both on the bus (at most ``LOCKSTEP_TIMEOUT``)."""

    def __init__(self, bus: Any, detections: str) -> None:
        self._cond = threading.Condition()
        self._seen = {"detections": -1, "handled": -1}
        self.timeouts = 0
        self._subs = [
            bus.subscribe(detections, self._on("detections"), queue=256),
            bus.subscribe(HANDLED, self._on("handled"), queue=256),
        ]

    def _on(self, key: str) -> Callable[[Any], None]:
        def callback(sample: Any) -> None:
            message = sample.message
            seq = getattr(message, "frame_seq", None)
            if seq is None:
                seq = message.to_body().get("seq")
            with self._cond:
                self._seen[key] = max(self._seen[key], int(seq))
                self._cond.notify_all()

        return callback

    def __call__(self, sim: Any, frame: Any, image: Any) -> None:
        deadline = time.monotonic() + LOCKSTEP_TIMEOUT
        with self._cond:
            while min(self._seen.values()) < frame.seq:
                left = deadline - time.monotonic()
                if left <= 0:
                    self.timeouts += 1
                    return
                self._cond.wait(left)

    def close(self) -> None:
        for sub in self._subs:
            sub.close()


def _say(**message: Any) -> None:
    print(TAG + json.dumps(message), flush=True)


def _wait_for(word: str) -> None:
    line = sys.stdin.readline()
    if line.strip() != word:
        raise SystemExit(f"loop component: expected {word!r} on stdin, got {line.strip()!r}")


def component(
    name: str,
    launch_path: Path,
    bus_json: str,
    seconds: float,
    oracle: Mapping[str, Any] | None = None,
    torch_threads: int = 0,
) -> None:
    """One component's process (``--component``): bring up, say ready, run, report.

    The protocol with :func:`processes_run`, a JSON object a line on stdout after ``TAG``:
    ``ready`` (the platform: with its endpoints) → [platform: ``peers`` in, out] → ``go``
    in → [platform: runs ``seconds``, ``ran`` out] → ``stop`` in → ``cpu_s`` and the
    component's counters out (CPU seconds of the process from ``go`` to ``stop``).
    """
    launch, managed = _launch(launch_path, oracle)
    sim = managed.options
    from anunnaki.sim import RoverSim, UavSim, load_scenario

    scenario = load_scenario(sim.scenario)
    platform_class = RoverSim if scenario.platform == "rover" else UavSim
    camera = _camera_topic(scenario)
    with open_bus(BusConfig.model_validate_json(bus_json), name=f"loop-{name}") as bus:
        report: Callable[[], dict[str, Any]]
        closing: list[Any] = []
        if name == "platform":
            from anunnaki.lec import detections_topic, load_registry

            lec = load_registry(sim.models).lec if sim.models is not None else "detector"
            lockstep = _Lockstep(bus, detections_topic(lec))
            system = platform_class(bus, scenario, frame_hook=lockstep)
            closing.extend([lockstep, system])
            _component_threads(torch_threads)
            _say(ready=True, endpoints=list(bus.endpoints))
            _wait_for("peers")
            want = {"/lm_manager", "/oracle_" + str((sim.oracle or {}).get("name"))}
            want |= {f"/utu_{n}" for n in launch.nodes}
            deadline = time.monotonic() + BRING_UP
            while not want <= bus.alive_nodes(timeout=2.0):
                if time.monotonic() > deadline:
                    raise SystemExit(f"loop platform: {sorted(want - bus.alive_nodes())} not up")
            _say(peers=True)
            _wait_for("go")
            t0, cpu0 = time.perf_counter(), time.process_time()
            system.run(threading.Event(), speed=FAST, until=seconds)
            wall = time.perf_counter() - t0
            _say(ran=True, frames=system.frames, wall_s=wall, timeouts=lockstep.timeouts)

            def report() -> dict[str, Any]:
                return {"frames": system.frames}

        elif name == "detector":
            from anunnaki.lec import LecNode, load_registry

            assert sim.models is not None, f"{launch_path}: the loop needs a detector (models)"
            node = LecNode(bus, load_registry(sim.models), camera=camera)
            closing.append(node)

            def report() -> dict[str, Any]:
                # A frame's detections leave the node before its callback counts them: the
                # platform may have seen the last frame's (and said "ran") while the count
                # is one short. Take the figures once every frame received has ended.
                deadline = time.monotonic() + LOCKSTEP_TIMEOUT
                stats = node.stats()
                while stats.frames > stats.detections + stats.failed:
                    if time.monotonic() > deadline:
                        break
                    time.sleep(0.01)
                    stats = node.stats()
                return {"frames": stats.frames, "detections": stats.detections}

        elif name == "oracle":
            node = _oracle_node(bus, sim, camera)
            closing.append(node)

            def report() -> dict[str, Any]:
                stats = node.stats()
                return {"frames": stats.frames, "assessments": stats.assessments}

        else:
            report = _utu(bus, launch, closing)
        if name != "platform":
            bus.alive_nodes(timeout=5.0)  # our declarations have left (see anunnaki node)
            _component_threads(torch_threads)
            _say(ready=True)
            _wait_for("go")
            cpu0 = time.process_time()
        _wait_for("stop")
        cpu = time.process_time() - cpu0
        _say(cpu_s=cpu, torch_threads=_component_threads(0), **report())
        for obj in reversed(closing):
            obj.close()


def _oracle_node(bus: Any, sim: Any, camera: str) -> Any:
    """The launch's oracle node alone, with what it takes from the detector's registry.

    It acknowledges each frame once its node has handled it (assessed, withheld or skipped),
    on :data:`HANDLED`, from the frame's own callback: the platform's lockstep.
    """
    from anunnaki.lec import load_registry
    from anunnaki.managed import TakesModels
    from anunnaki.oracles import ORACLES, OracleNode

    class AckingOracleNode(OracleNode):
        def _on_frame(self, sample: Any) -> None:
            super()._on_frame(sample)
            self.bus.publish(HANDLED, {"seq": sample.message.seq})

    options = dict(sim.oracle or {})
    name = str(options.pop("name", "ground_truth"))
    factory = ORACLES.factory(name)
    if sim.models is not None and isinstance(factory, TakesModels):
        options = {**factory.options_from_models(load_registry(sim.models)), **options}
    return AckingOracleNode(bus, name, camera=camera, **options)


def _utu(bus: Any, launch: Launch, closing: list[Any]) -> Callable[[], dict[str, Any]]:
    """Utu's five nodes composed in this process (the launch's ``nodes``), spinning."""
    from anunnaki.utu import AutonomicManager, open_knowledge

    kb = open_knowledge(":memory:")
    manager = AutonomicManager.from_config(launch.parts, bus=bus, knowledge=kb, nodes=launch.nodes)
    halt = threading.Event()
    thread = threading.Thread(target=manager.spin, args=(halt,), name="loop-utu", daemon=True)
    thread.start()

    class _Stop:
        def close(self) -> None:
            halt.set()
            manager.wake()
            thread.join(timeout=10.0)
            manager.close()
            kb.close()

    closing.append(_Stop())

    def report() -> dict[str, Any]:
        kb.flush()
        verdicts = sum(1 for row in kb.inputs() if row.topic == topics.ORACLE_OUTPUT)
        return {
            "inputs": kb.counts()["inputs"],
            "oracle_verdicts": verdicts,
            "decisions": len(kb.decisions()),
        }

    return report


# -- where the CPU time goes --------------------------------------------------------------------
#: What the profile's breakdown adds up, per frame: a part's CPU time is the inclusive time
#: of the calls that match (file suffix and function name; ``~`` for a C function), summed
#: over every thread, or (``*`` as the name) the functions' own time in files under that
#: folder. The parts do not nest; the rest of the Python threads' time is ``other``.
PARTS: dict[str, tuple[tuple[str, str], ...]] = {
    "physics and motion": (("anunnaki/sim/_rover.py", "_tick"), ("anunnaki/sim/_uav.py", "_tick")),
    "rendering": (("anunnaki/sim/_scene.py", "render"),),
    "phenomena": (("anunnaki/phenomena/_base.py", "apply"),),
    "jpeg encode": (("~", "<imencode>"),),
    "jpeg decode": (("anunnaki/messages/_image.py", "to_array"),),
    "detector forward": (("anunnaki/lec/_centernet.py", "detect"),),
    "oracle forward": (("anunnaki/enlil/_oracle_plugin.py", "assess"),),
    "utu": (("anunnaki/utu/host/_manager.py", "step"),),
    "bus (own time)": (("anunnaki/bus/", "*"), ("anunnaki/messages/", "*")),
    "scoring (F1; not the loop)": (("anunnaki/managed/_sim.py", "_score"),),
    "bring-up (not per frame)": (
        ("anunnaki/managed/_sim.py", "__init__"),
        ("anunnaki/launch/_schema.py", "load_launch"),
        ("anunnaki/launch/_runner.py", "_build_nodes"),
    ),
}


def profile(
    launch: Path, seconds: float, *, top: int = 30, dump: Path | None = None
) -> dict[str, Any]:
    """The whole loop in one process (the ``utu`` stage) under cProfile, every thread.

    Each thread gets a profiler of its own (``threading.setprofile`` installs it as the
    thread starts) timed by ``time.thread_time``, so the figures are CPU time, not wall
    time. Torch's own worker threads are not Python threads: their time shows only in the
    process's total (``native_threads_ms_per_frame``).
    """
    import cProfile
    import pstats

    profiles: list[cProfile.Profile] = []
    lock = threading.Lock()

    def install(*_: Any) -> None:
        prof = cProfile.Profile(time.thread_time)
        with lock:
            profiles.append(prof)
        prof.enable()

    main = cProfile.Profile(time.thread_time)
    threading.setprofile(install)
    try:
        cpu0 = time.process_time()
        main.enable()
        run = stage("utu", seconds, launch)
        main.disable()
        cpu = time.process_time() - cpu0
    finally:
        threading.setprofile(None)
    stats = pstats.Stats(main)
    for prof in profiles:
        stats.add(prof)
    if dump is not None:
        stats.dump_stats(dump)  # for a closer look: python -m pstats FILE
    table: dict[tuple[str, int, str], Any] = getattr(stats, "stats")  # noqa: B009 (untyped)
    frames = max(int(run["frames"]), 1)

    def ms(seconds: float) -> float:
        return round(1000 * seconds / frames, 2)

    parts: dict[str, float] = {}
    for part, keys in PARTS.items():
        total = 0.0
        for (file, _, func), (_, _, own, cum, _) in table.items():
            for where, name in keys:
                if name == "*" and f"/{where}" in file:
                    total += own
                elif name == func and file.endswith(where):
                    total += cum
        parts[part] = ms(total)
    threads = sum(v[2] for v in table.values())  # every Python thread's own time
    parts["other (python)"] = round(ms(threads) - sum(parts.values()), 2)
    ranked = sorted(table.items(), key=lambda kv: kv[1][3], reverse=True)[:top]
    return {
        "launch": str(launch),
        "run": run,
        "cpu_ms_per_frame": ms(cpu),
        "python_threads_ms_per_frame": ms(threads),
        "native_threads_ms_per_frame": round(ms(cpu) - ms(threads), 2),
        "torch_threads": _torch().get_num_threads(),
        "parts_ms_per_frame": parts,
        "top_inclusive_ms_per_frame": [
            {"function": f"{Path(file).name}:{line}({func})", "ms": ms(v[3]), "calls": v[1]}
            for (file, line, func), v in ranked
        ],
    }


# -- the measurement ----------------------------------------------------------------------------
def cli_run(launch: Path, seconds: float, *, src: Path | None = None) -> dict[str, Any]:
    """One ``anunnaki run LAUNCH --speed 0 --until SECONDS --report`` (``src``: whose code)."""
    env = dict(os.environ)
    if src is not None:  # another checkout's package ahead of this one's
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(src), env.get("PYTHONPATH")) if p)
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "report.json"
        argv = [sys.executable, "-m", "anunnaki", "run", str(launch), "--speed", "0"]
        argv += ["--until", f"{seconds:g}", "--report", str(report)]
        load = os.getloadavg()[0]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        done = subprocess.run(argv, capture_output=True, text=True, env=env, check=False)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if done.returncode != 0 or not report.exists():
            raise RuntimeError(f"{' '.join(argv)} failed ({done.returncode}):\n{done.stderr}")
        digest = hashlib.sha256(report.read_bytes()).hexdigest()
    found = re.search(r"simulated ([0-9.]+) s in ([0-9.]+) s wall", done.stdout)
    user, system = after.ru_utime - before.ru_utime, after.ru_stime - before.ru_stime
    return {
        "wall_s": round(wall, 2),
        "cpu_s": round(user + system, 2),
        "user_s": round(user, 2),
        "sys_s": round(system, 2),
        "sim_s_per_wall_s": round(seconds / wall, 3),
        "run_wall_s": None if found is None else float(found.group(2)),
        "load1_before": round(load, 2),
        "load1_after": round(os.getloadavg()[0], 2),
        "report_sha256": digest,
    }


def cli_measure(
    launches: Mapping[str, Path], seconds: float, repeats: int, *, against: Path | None
) -> dict[str, Any]:
    """``--cli``: each loop's command ``repeats`` times, alternating with ``against``'s."""
    out: dict[str, Any] = {}
    for name, launch in launches.items():
        codes: dict[str, tuple[Path, Path | None]] = {}
        if against is not None:
            codes["against"] = (against / launch.resolve().relative_to(ROOT), against / "src")
        codes["this"] = (launch, None)
        runs: dict[str, list[dict[str, Any]]] = {code: [] for code in codes}
        for _ in range(repeats):
            for code, (path, src) in codes.items():
                run = cli_run(path, seconds, src=src)
                runs[code].append(run)
                print(f"{name} {code}: {json.dumps(run)}", flush=True)
        doc: dict[str, Any] = {"launch": str(launch)}
        for code, done in runs.items():
            doc[code] = {
                "sim_s_per_wall_s_median": round(_median(done, "sim_s_per_wall_s"), 3),
                "cpu_s_median": round(_median(done, "cpu_s"), 2),
                "runs": done,
            }
        digests = {run["report_sha256"] for done in runs.values() for run in done}
        doc["reports_identical"] = len(digests) == 1
        out[name] = doc
    return out


def _median(runs: list[dict[str, Any]], key: str) -> float:
    return round(statistics.median(float(r[key]) for r in runs), 2)


def _summary(runs: list[dict[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {
        "fps_median": _median(runs, "fps"),
        "cpu_ms_per_frame_median": _median(runs, "cpu_ms_per_frame"),
    }
    if "cpu_ms_per_frame_by_process" in runs[0]:
        out["cpu_ms_per_frame_by_process_median"] = {
            name: round(statistics.median(r["cpu_ms_per_frame_by_process"][name] for r in runs), 1)
            for name in COMPONENTS
        }
    return out | {"runs": runs}


def measure(
    loop: str,
    launch: Path,
    seconds: float,
    repeats: int,
    *,
    layouts: tuple[str, ...] = LAYOUTS,
    torch_threads: tuple[int, ...] = (0,),
    oracle_blas: tuple[str, ...] = ("1",),
) -> dict[str, Any]:
    """One loop in its layouts: median frames per second and CPU time each, and the ratios.

    A repeat runs every stage and layout once, one after the other. Variants of the whole
    loop run in the same repeats, in both layouts: each further ``torch_threads`` (torch's
    threads in this process and in each component's; 0: torch's default) and each further
    ``oracle_blas`` (the enlil oracle's ``blas_threads``: a number or ``none``), the others
    as the first; they go to ``torch_threads_variants`` and ``oracle_blas_variants`` (the
    first included). The first of each gives the stages and ``processes``.
    """
    as_written = load_launch(launch).managed
    assert isinstance(as_written, SimKind)
    out: dict[str, Any] = {"launch": str(launch), "stages": {}}
    out["camera"] = _camera(as_written)
    out["scorer"] = "off" if as_written.options.scorer is not None else "none"
    out["oracle"] = str((as_written.options.oracle or {}).get("name"))
    torch = _torch()
    default_threads = torch.get_num_threads()

    # (label, torch threads, oracle options): the first is the baseline, as the launch says
    def blas(b: str) -> dict[str, Any] | None:  # the oracle's option; 1 is its default
        return None if b == "1" else {"blas_threads": None if b == "none" else int(b)}

    base = blas(oracle_blas[0])
    variants: list[tuple[str, int, dict[str, Any] | None]] = [("", torch_threads[0], base)]
    variants += [(f"torch threads {t}", t, base) for t in torch_threads[1:]]
    variants += [(f"oracle blas_threads {b}", torch_threads[0], blas(b)) for b in oracle_blas[1:]]
    stage_runs: dict[str, list[dict[str, Any]]] = {}
    whole: dict[str, dict[str, list[dict[str, Any]]]] = {label: {} for label, _, _ in variants}
    for _ in range(repeats):
        for label, threads, oracle in variants:
            tag = f" ({label})" if label else ""
            if "one_process" in layouts:
                torch.set_num_threads(threads or default_threads)
                try:
                    for name in ("utu",) if label else STAGES:
                        run = stage(name, seconds, launch, oracle)
                        if not label:
                            stage_runs.setdefault(name, []).append(run)
                        if name == "utu":
                            whole[label].setdefault("one_process", []).append(run)
                        print(f"  {name:9s} {_rate(run)}{tag}")
                finally:
                    torch.set_num_threads(default_threads)
            if "processes" in layouts:
                split = processes_run(launch, seconds, torch_threads=threads, oracle=oracle)
                whole[label].setdefault("processes", []).append(split)
                by = split["cpu_ms_per_frame_by_process"]
                print(
                    f"  processes {_rate(split)} ({', '.join(f'{k} {v}' for k, v in by.items())})"
                    + tag
                )
    aim = AIM_HZ[loop]
    out["aim_hz"] = aim
    if stage_runs:
        for name, runs in stage_runs.items():
            out["stages"][name] = _summary(runs)
        alone = out["stages"]["platform"]["fps_median"]
        for entry in out["stages"].values():
            entry["ratio_to_platform"] = round(entry["fps_median"] / alone, 3)
        out["whole_loop_hz"] = out["stages"]["utu"]["fps_median"]
        out["aim_met"] = out["whole_loop_hz"] >= aim
    first = whole[""]
    if "processes" in first:
        out["processes"] = _summary(first["processes"])
        out["processes_hz"] = out["processes"]["fps_median"]
        out["aim_met_processes"] = out["processes_hz"] >= aim
        if "whole_loop_hz" in out:
            out["processes"]["ratio_to_one_process"] = round(
                out["processes_hz"] / out["whole_loop_hz"], 3
            )

    def summaries(label: str) -> dict[str, Any]:
        return {layout: _summary(runs) for layout, runs in whole[label].items()}

    if len(torch_threads) > 1:
        out["torch_threads_variants"] = {
            str(t): {"torch_threads": t or default_threads}
            | summaries(f"torch threads {t}" if k else "")
            for k, t in enumerate(torch_threads)
        }
    if len(oracle_blas) > 1:
        out["oracle_blas_variants"] = {
            b: {"oracle_blas_threads": b} | summaries(f"oracle blas_threads {b}" if k else "")
            for k, b in enumerate(oracle_blas)
        }
    return out


def _rate(run: dict[str, Any]) -> str:
    return f"{run['fps']:6.1f} frames/s; {run['cpu_ms_per_frame']:6.1f} ms of CPU per frame"


def _camera(sim: SimKind) -> str:
    from anunnaki.sim import load_scenario

    cam = load_scenario(sim.options.scenario).camera
    return f"{cam.width}x{cam.height} at {cam.rate:g} Hz"


def _csv(text: str, allowed: tuple[str, ...], flag: str, ap: argparse.ArgumentParser) -> list[str]:
    items = [x.strip() for x in text.split(",") if x.strip()]
    unknown = sorted(set(items) - set(allowed))
    if unknown or not items:
        ap.error(f"{flag}: {' and/or '.join(allowed)}, not {', '.join(unknown) or 'nothing'}")
    return items


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=15.0, help="simulated seconds per run")
    ap.add_argument("--repeats", type=int, default=2, help="runs per stage (median kept)")
    ap.add_argument("--output", type=Path, default=RESULTS)
    ap.add_argument("--launch", type=Path, default=LAUNCH, help="the rover's launch file")
    ap.add_argument("--uav-launch", type=Path, default=UAV_LAUNCH, help="the UAV's launch file")
    ap.add_argument(
        "--loops", default="rover,uav", help="which loops to measure: rover, uav or both"
    )
    ap.add_argument(
        "--layouts",
        default=",".join(LAYOUTS),
        help="one_process (four stages in this process) and/or processes (one per component)",
    )
    ap.add_argument(
        "--torch-threads",
        default="0",
        help="torch threads in each component's process, comma-separated variants to compare "
        "in the same run (0: torch's default, one per core)",
    )
    ap.add_argument(
        "--profile",
        type=Path,
        metavar="FILE.json",
        help="instead: profile the first of --loops in one process (cProfile, every thread) "
        "and write where the CPU time per frame goes",
    )
    ap.add_argument(
        "--pstats",
        type=Path,
        metavar="FILE",
        help="with --profile: also keep the merged profile (python -m pstats FILE)",
    )
    ap.add_argument(
        "--oracle-blas-threads",
        default="1",
        help="the enlil oracle's BLAS threads (its blas_threads: 1, the default, or none: the "
        "process's), comma-separated variants to compare in the same run",
    )
    ap.add_argument(
        "--cli",
        action="store_true",
        help="instead: time `anunnaki run LAUNCH --speed 0 --until SECONDS --report` per loop "
        "(scorer and bring-up included): simulated seconds per wall second, CPU seconds",
    )
    ap.add_argument(
        "--cli-against",
        type=Path,
        metavar="DIR",
        help="with --cli: another checkout whose runs alternate with this one's",
    )
    ap.add_argument("--component", choices=COMPONENTS, help=argparse.SUPPRESS)
    ap.add_argument("--oracle-json", default="{}", help=argparse.SUPPRESS)
    ap.add_argument("--bus-json", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.component is not None:  # one component's process of the processes layout
        component(
            args.component,
            args.launch,
            args.bus_json,
            args.seconds,
            json.loads(args.oracle_json),
            torch_threads=int(args.torch_threads),
        )
        return
    loops = _csv(args.loops, ("rover", "uav"), "--loops", ap)
    if args.cli:
        cli: dict[str, Any] = {
            "benchmark": "loop --cli",
            "date": time.strftime("%Y-%m-%d %H:%M:%S"),
            "command": f"anunnaki run LAUNCH --speed 0 --until {args.seconds:g} --report FILE",
            "machine": {
                "python": platform.python_version(),
                "cpus": os.cpu_count(),
                "nice": os.nice(0),
                "PYTHONDONTWRITEBYTECODE": os.environ.get("PYTHONDONTWRITEBYTECODE"),
                "load_average_before": list(os.getloadavg()),
            },
            "simulated_seconds": args.seconds,
            "repeats": args.repeats,
            "against": None if args.cli_against is None else str(args.cli_against),
        }
        launches = {"rover": args.launch, "uav": args.uav_launch}
        cli |= cli_measure(
            {k: v for k, v in launches.items() if k in loops},
            args.seconds,
            args.repeats,
            against=args.cli_against,
        )
        cli["machine"]["load_average_after"] = list(os.getloadavg())
        args.output.parent.mkdir(parents=True, exist_ok=True)
        args.output.write_text(json.dumps(cli, indent=1) + "\n")
        print(f"wrote {args.output}")
        return
    torch = _torch()
    layouts = tuple(_csv(args.layouts, LAYOUTS, "--layouts", ap))
    try:
        variants = tuple(int(x) for x in args.torch_threads.split(","))
    except ValueError:
        ap.error(f"--torch-threads: whole numbers, e.g. 0,1, not {args.torch_threads!r}")
    blas = tuple(x.strip().lower() for x in args.oracle_blas_threads.split(","))
    if not all(x == "none" or (x.isdigit() and int(x) > 0) for x in blas):
        ap.error(f"--oracle-blas-threads: 1, 2, … or none, not {args.oracle_blas_threads!r}")
    if args.profile is not None:
        launch = args.launch if loops[0] == "rover" else args.uav_launch
        if variants[0] > 0:
            torch.set_num_threads(variants[0])
        found: dict[str, Any] = {"load_average_before": list(os.getloadavg())}
        found |= profile(launch, args.seconds, dump=args.pstats)
        found["load_average_after"] = list(os.getloadavg())
        args.profile.write_text(json.dumps(found, indent=1) + "\n")
        print(json.dumps(found["parts_ms_per_frame"], indent=1))
        print(f"wrote {args.profile}")
        return
    results: dict[str, Any] = {
        "benchmark": "loop",
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
        "machine": {
            "python": platform.python_version(),
            "cpus": os.cpu_count(),
            "torch_threads": torch.get_num_threads(),
            "load_average_before": list(os.getloadavg()),
        },
        "simulated_seconds": args.seconds,
        "repeats": args.repeats,
        "layouts": list(layouts),
    }
    if "rover" in loops:
        print(f"rover loop ({args.launch})")
        results.update(
            measure(
                "rover",
                args.launch,
                args.seconds,
                args.repeats,
                layouts=layouts,
                torch_threads=variants,
                oracle_blas=blas,
            )
        )
    if "uav" in loops:
        print(f"UAV loop ({args.uav_launch})")
        results["uav"] = measure(
            "uav",
            args.uav_launch,
            args.seconds,
            args.repeats,
            layouts=layouts,
            torch_threads=variants,
            oracle_blas=blas,
        )
    results["machine"]["load_average_after"] = list(os.getloadavg())
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(results, indent=1) + "\n")
    for name, doc in (("rover", results), ("UAV", results.get("uav"))):
        if doc is None:
            continue
        for key, what in (
            ("whole_loop_hz", "one process"),
            ("processes_hz", "one process per component"),
        ):
            if key in doc:
                print(
                    f"{name} whole loop, {what}: {doc[key]:.1f} Hz at {doc['camera']} "
                    f"(aim {doc['aim_hz']:g} Hz)"
                )
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
