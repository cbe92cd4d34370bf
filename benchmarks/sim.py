"""Simulation throughput: frames per second per platform and image size.

Three figures per platform (rover, UAV) and size (128x128, 320x240), each the median of
``--repeats`` runs, in one process on the in-process bus:

* ``render``: :func:`anunnaki.sim.dataset_frames` — varying the scene, rendering with
  pybullet's tiny renderer (``DIRECT``, no shadows) and extracting the ground-truth boxes
  from the segmentation mask; what dataset generation costs per frame;
* ``platform``: a :class:`RoverSim` / :class:`UavSim` stepped flat out with its camera at
  30 Hz — physics at 240 Hz (rover), sensors, rendering, JPEG encoding and publishing the
  image, its info, the ground truth and ``/sim/phenomena`` — as frames per wall second;
* ``realtime_factor``: simulated seconds per wall second of the same run (camera at 10 Hz,
  the scenario default), i.e. the fastest ``--speed`` the CLI can keep.

Scene building is timed separately (``build_s``). The machine is shared: the load average
is recorded with the figures. Writes ``benchmarks/results/sim.json``::

    .venv/bin/python benchmarks/sim.py
    .venv/bin/python benchmarks/sim.py --repeats 1 --frames 40 --output /tmp/sim.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path
from typing import Any

from anunnaki.bus import open_bus
from anunnaki.sim import Platform, RoverSim, Scene, UavSim, dataset_frames

SIZES = ((128, 128), (320, 240))
PLATFORMS: tuple[Platform, ...] = ("rover", "uav")
RESULTS = Path(__file__).parent / "results" / "sim.json"


def render_fps(platform_name: Platform, width: int, height: int, n: int) -> float:
    frames = dataset_frames(platform_name, layout=0, seed=0, n=n + 1, width=width, height=height)
    next(iter(frames))  # the scene is built before the first frame: not timed
    t0 = time.perf_counter()
    count = sum(1 for _ in frames)
    return count / (time.perf_counter() - t0)


def build_seconds(platform_name: Platform) -> float:
    t0 = time.perf_counter()
    Scene(platform_name, 0).close()
    return time.perf_counter() - t0


def platform_run(
    platform_name: Platform, width: int, height: int, n: int, rate: float
) -> tuple[float, float]:
    """(frames per wall second, simulated seconds per wall second) for ``n`` frames."""
    scenario: dict[str, Any] = {
        "platform": platform_name,
        "camera": {"rate": rate, "width": width, "height": height, "encoding": "jpeg"},
    }
    if platform_name == "uav":
        scenario["mission"] = {"start_altitude": 30}
    cls = RoverSim if platform_name == "rover" else UavSim
    with open_bus("inproc") as bus, cls(bus, scenario) as sim:
        sim.step(2.0 / rate)  # warm up
        frames0, t_sim0 = sim.frames, sim.t
        t0 = time.perf_counter()
        sim.step(n / rate)
        wall = time.perf_counter() - t0
        return (sim.frames - frames0) / wall, (sim.t - t_sim0) / wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=120, help="frames per measurement")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args()
    results: dict[str, Any] = {
        "benchmark": "sim",
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
        "machine": {
            "python": platform.python_version(),
            "cpus": os.cpu_count(),
            "load_average_before": list(os.getloadavg()),
        },
        "renderer": "pybullet ER_TINY_RENDERER, DIRECT, shadow=0",
        "frames_per_measurement": args.frames,
        "repeats": args.repeats,
        "platforms": {},
    }
    for name in PLATFORMS:
        entry: dict[str, Any] = {
            "build_s": round(statistics.median(build_seconds(name) for _ in range(args.repeats)), 3)
        }
        for width, height in SIZES:
            render = [render_fps(name, width, height, args.frames) for _ in range(args.repeats)]
            plat = [
                platform_run(name, width, height, args.frames, 30.0) for _ in range(args.repeats)
            ]
            rt = [
                platform_run(name, width, height, args.frames // 3, 10.0)
                for _ in range(args.repeats)
            ]
            entry[f"{width}x{height}"] = {
                "render_fps": round(statistics.median(render), 1),
                "platform_fps": round(statistics.median(p[0] for p in plat), 1),
                "realtime_factor_camera_10hz": round(statistics.median(r[1] for r in rt), 2),
            }
            print(name, f"{width}x{height}", entry[f"{width}x{height}"], flush=True)
        results["platforms"][name] = entry
    results["machine"]["load_average_after"] = list(os.getloadavg())
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
