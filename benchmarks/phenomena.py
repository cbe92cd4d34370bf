"""Milliseconds per frame for every phenomenon at 128x128 and 320x240.

Each phenomenon runs at strength 0.5 on the synthetic road scene; each round uses a different
seed (so random draws are included) and times every case once, round-robin. We report the
median, minimum and 90th percentile of ``--runs`` timed rounds after ``--warmup`` untimed
ones; OpenCV and BLAS are single-threaded so the figures do not depend on the core count.

    .venv/bin/python benchmarks/phenomena.py            # writes benchmarks/results/phenomena.json
    .venv/bin/python benchmarks/phenomena.py --runs 5 --output /tmp/p.json
"""

from __future__ import annotations

import os

# Single-threaded numpy BLAS too (set before numpy loads), like OpenCV below.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import json
import platform
import statistics
import sys
import time
from importlib.metadata import version
from pathlib import Path
from typing import Any

import numpy as np

from anunnaki.phenomena import PHENOMENA, synthetic_scene

SIZES = {"128x128": (128, 128), "320x240": (240, 320)}  # label (W x H): (height, width)
EXTRA = ["fog+raindrop", "raindrop+raindrop+raindrop"]
DEFAULT_OUTPUT = Path(__file__).parent / "results" / "phenomena.json"


def measure(
    names: list[str], runs: int, warmup: int, strength: float
) -> dict[str, dict[str, dict[str, Any]]]:
    """Time every (phenomenon, size) once per round, round-robin, so that load from other
    processes spreads over all of them instead of spoiling one."""
    cases = []
    for name in names:
        for label, (height, width) in SIZES.items():
            phenomenon = PHENOMENA.create(name)
            params = phenomenon.strength_params(strength)
            cases.append((name, label, phenomenon, synthetic_scene(height, width), params))
    times: dict[tuple[str, str], list[float]] = {(c[0], c[1]): [] for c in cases}
    for round_ in range(warmup + runs):
        for name, label, phenomenon, image, params in cases:
            start = time.perf_counter_ns()
            phenomenon.apply(image, params, seed=round_)
            if round_ >= warmup:
                times[name, label].append((time.perf_counter_ns() - start) / 1e6)
    results: dict[str, dict[str, dict[str, Any]]] = {}
    for name, label, _, _, params in cases:
        samples = times[name, label]
        results.setdefault(name, {})[label] = {
            "median_ms": round(statistics.median(samples), 4),
            "min_ms": round(min(samples), 4),
            "p90_ms": round(float(np.percentile(samples, 90)), 4),
            "params": params,
        }
    return results


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=100)
    parser.add_argument("--warmup", type=int, default=5)
    parser.add_argument("--strength", type=float, default=0.5)
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT)
    args = parser.parse_args(argv)

    import cv2

    cv2.setNumThreads(1)
    results = measure([*PHENOMENA.names(), *EXTRA], args.runs, args.warmup, args.strength)
    for name, sizes in results.items():
        for label, entry in sizes.items():
            print(f"{name:28s} {label:8s} {entry['median_ms']:8.3f} ms/frame")
    report = {
        "benchmark": "phenomena ms/frame (median of runs, strength 0.5, synthetic scene)",
        "runs": args.runs,
        "warmup": args.warmup,
        "strength": args.strength,
        "opencv_threads": 1,
        "machine": {
            "python": sys.version.split()[0],
            "platform": platform.platform(),
            "processor": platform.processor() or platform.machine(),
            "cpu_count": os.cpu_count(),
        },
        "versions": {
            pkg: version(pkg) for pkg in ("numpy", "opencv-python-headless", "albumentations")
        },
        "results": results,
    }
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(report, indent=2) + "\n")
    print(f"wrote {args.output}")
    return report


if __name__ == "__main__":
    main()
