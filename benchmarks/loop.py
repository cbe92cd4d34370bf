"""The whole loop's throughput: simulator, phenomena, bus, detector, oracle and Utu.

The rover demo (``examples/rover/sim.yaml``: 128 × 128 camera at 10 Hz, the fog-then-dusk
scenario, the default/fog/low-light registry, the ground-truth oracle, Utu's five nodes in
one process on the in-process bus) is run flat out — ``--speed`` far above what the machine
can keep, with the simulator in lockstep with the detector — and timed in wall seconds.
Four stages are run in the same process, each adding a part, so the ratios show what each
part costs on this (shared, noisy) machine:

* ``platform``: the rover alone (physics, rendering, phenomena, JPEG, publishing);
* ``detector``: + the LEC node running the active model on every frame, in lockstep;
* ``oracle``: + the ground-truth oracle node;
* ``utu``: the whole launch, + Utu's monitor, analyzer, planner, executor and knowledge.

The figure of merit is camera frames per wall second of the ``utu`` stage (the issue's aim:
10 Hz or more on 2 cores): each frame is rendered, perturbed, published, detected, assessed
and fed to Utu before the next.

Each run also gives the process's CPU time per frame (``cpu_ms_per_frame``, every thread of
the process: simulator, detector, oracle, Utu): on a machine shared with other work the
frame rate measures the load as much as the loop, the CPU time much less so.

The UAV's loop (``examples/uav/sim.yaml``: 320 × 240 camera at 10 Hz, the delivery scenario
from take-off, uav-default/uav-fog, the learned ``enlil`` oracle as A4) is measured the same
way, in the same four stages (aim: 10 Hz at 320 × 240, issue #24). Its launch runs the
ground-truth oracle beside enlil as a live scorer; that is scoring, not the loop, so the
``utu`` stage runs without it (``"scorer": "off"`` in the results). The rover's figures stay
at the top level of the results (as before); the UAV's are under ``"uav"``. Writes
``benchmarks/results/loop.json``::

    .venv/bin/python benchmarks/loop.py
    .venv/bin/python benchmarks/loop.py --seconds 10 --repeats 1 --output /tmp/loop.json
    .venv/bin/python benchmarks/loop.py --loops uav        # the UAV's loop only
"""

from __future__ import annotations

import argparse
import io
import json
import os
import platform
import statistics
import threading
import time
from pathlib import Path
from typing import Any

import torch

from anunnaki.bus import open_bus
from anunnaki.launch import load_launch, run_launch
from anunnaki.managed import SimKind, SimulatedSystem

ROOT = Path(__file__).parents[1]
LAUNCH = ROOT / "examples" / "rover" / "sim.yaml"
UAV_LAUNCH = ROOT / "examples" / "uav" / "sim.yaml"
AIM_HZ = 10.0
RESULTS = Path(__file__).parent / "results" / "loop.json"
FAST = 1000.0  # simulated seconds per wall second asked for: far beyond the machine


def stage(name: str, seconds: float, launch_path: Path) -> dict[str, float]:
    """Run one stage for ``seconds`` of simulated time; frames and wall time."""
    launch = load_launch(launch_path)
    assert isinstance(launch.managed, SimKind)
    if launch.managed.options.scorer is not None:  # scoring, not the loop (see above)
        launch.managed.options = launch.managed.options.model_copy(update={"scorer": None})
    sim = launch.managed.options
    if name == "utu":
        out = io.StringIO()
        t0, cpu0 = time.perf_counter(), time.process_time()
        result = run_launch(launch, speed=FAST, until=seconds, out=out, handle_signals=False)
        wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
        line = next(x for x in out.getvalue().splitlines() if x.startswith("simulated "))
        frames = int(line.split("(")[1].split()[0])
        return {
            "frames": frames,
            "wall_s": round(wall, 3),
            "run_s": round(result.ran, 3),
            "fps": round(frames / result.ran, 2),
            "cpu_ms_per_frame": round(1000 * cpu / max(frames, 1), 1),
            "decisions": len(result.decisions),
        }
    with open_bus("inproc") as bus:
        system = SimulatedSystem(
            bus,
            sim.scenario,
            models=sim.models if name in ("detector", "oracle") else None,
            oracle=sim.oracle if name == "oracle" else None,
            lockstep=True,
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


def measure(launch: Path, seconds: float, repeats: int) -> dict[str, Any]:
    """The four stages of one loop: median frames per second each, and the ratios."""
    out: dict[str, Any] = {"launch": str(launch), "stages": {}}
    sim = load_launch(launch).managed
    assert isinstance(sim, SimKind)
    camera = _camera(sim)
    out["camera"] = camera
    out["scorer"] = "off" if sim.options.scorer is not None else "none"
    for name in ("platform", "detector", "oracle", "utu"):
        runs = [stage(name, seconds, launch) for _ in range(repeats)]
        fps = statistics.median(r["fps"] for r in runs)
        cpu = statistics.median(r["cpu_ms_per_frame"] for r in runs)
        out["stages"][name] = {"fps_median": fps, "cpu_ms_per_frame_median": cpu, "runs": runs}
        print(
            f"{name:9s} {fps:6.1f} frames/s  ({', '.join(str(r['fps']) for r in runs)}); "
            f"{cpu:6.1f} ms of CPU per frame"
        )
    base = out["stages"]["platform"]["fps_median"]
    for entry in out["stages"].values():
        entry["ratio_to_platform"] = round(entry["fps_median"] / base, 3)
    whole = out["stages"]["utu"]["fps_median"]
    out["whole_loop_hz"] = whole
    out["aim_hz"] = AIM_HZ
    out["aim_met"] = whole >= AIM_HZ
    return out


def _camera(sim: SimKind) -> str:
    from anunnaki.sim import load_scenario

    cam = load_scenario(sim.options.scenario).camera
    return f"{cam.width}x{cam.height} at {cam.rate:g} Hz"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=30.0, help="simulated seconds per run")
    ap.add_argument("--repeats", type=int, default=3, help="runs per stage (median kept)")
    ap.add_argument("--output", type=Path, default=RESULTS)
    ap.add_argument("--launch", type=Path, default=LAUNCH, help="the rover's launch file")
    ap.add_argument("--uav-launch", type=Path, default=UAV_LAUNCH, help="the UAV's launch file")
    ap.add_argument(
        "--loops", default="rover,uav", help="which loops to measure: rover, uav or both"
    )
    args = ap.parse_args()
    loops = [x.strip() for x in args.loops.split(",") if x.strip()]
    unknown = sorted(set(loops) - {"rover", "uav"})
    if unknown or not loops:
        ap.error(f"--loops: rover and/or uav, not {', '.join(unknown) or 'nothing'}")
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
    }
    if "rover" in loops:
        print(f"rover loop ({args.launch})")
        results.update(measure(args.launch, args.seconds, args.repeats))
    if "uav" in loops:
        print(f"UAV loop ({args.uav_launch})")
        results["uav"] = measure(args.uav_launch, args.seconds, args.repeats)
    results["machine"]["load_average_after"] = list(os.getloadavg())
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(results, indent=1) + "\n")
    for name, doc in (("rover", results), ("UAV", results.get("uav"))):
        if doc is not None and "whole_loop_hz" in doc:
            print(
                f"{name} whole loop {doc['whole_loop_hz']:.1f} Hz at {doc['camera']} "
                f"(aim {doc['aim_hz']:g} Hz)"
            )
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
