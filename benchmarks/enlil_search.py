"""Enlil's search against its baselines: occupied category-1 cells at 500 and 1,000 evaluations.

Renders a small rover dataset (or uses ``--data``), then runs ``enlil``, ``random`` and
``sobol`` with the same budget, evaluator and seed on the shipped ``rover-default`` model and
counts, at each checkpoint, the distinct cells of the fixed grid (10 per axis, a 256-cell CVT
above 3 parameters) occupied by category-1 (degraded) contexts. The aim (issue 13): Enlil's
count ≥ 1.5 × random's. Writes ``benchmarks/results/enlil_search.json``.

Run: ``.venv/bin/python benchmarks/enlil_search.py [--phenomenon hsl] [--budget 1000]``
"""

from __future__ import annotations

import argparse
import json
import platform
import shutil
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "examples" / "models" / "rover-default.safetensors"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--data", help="dataset folder (default: render a small one)")
    parser.add_argument("--phenomenon", default="hsl")
    parser.add_argument("--budget", type=int, default=1000)
    parser.add_argument("--checkpoints", default="500,1000")
    parser.add_argument("--batch-images", type=int, default=16)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "enlil_search.json"))
    args = parser.parse_args()

    from anunnaki.enlil import Job, occupied_cells, run_search

    tmp = Path(tempfile.mkdtemp(prefix="enlil-bench-"))
    data = args.data
    if data is None:
        from anunnaki.sim import make_dataset

        data = str(tmp / "data")
        make_dataset(
            "rover", data, train_layouts=[0], val_layouts=[40, 41], test_layouts=[42],
            per_layout=12, width=128, height=128, seed=0, workers=args.workers,
        )  # fmt: skip
    job = Job(
        model=str(MODEL), data=data, phenomenon=args.phenomenon,
        batch_images=args.batch_images, seed=args.seed,
    )  # fmt: skip
    checkpoints = [int(c) for c in args.checkpoints.split(",") if int(c) <= args.budget]
    results: dict[str, dict[str, object]] = {}
    cells: dict[str, dict[str, dict[int, int]]] = {}  # search -> n -> category -> cells
    for search in ("enlil", "random", "sobol"):
        start = time.perf_counter()
        outcome = run_search(
            job, tmp / search, search=search, budget=args.budget, seed=args.seed,
            workers=args.workers,
        )  # fmt: skip
        seconds = round(time.perf_counter() - start, 1)
        arch = outcome.archive
        cells[search] = {str(n): occupied_cells(arch, n) for n in checkpoints}
        results[search] = {
            "seconds": seconds,
            "cells": cells[search],
            "counts": outcome.summary["counts"],
        }
        print(search, results[search], flush=True)
    ratio = {
        str(n): cells["enlil"][str(n)][1] / max(1, cells["random"][str(n)][1]) for n in checkpoints
    }
    report = {
        "phenomenon": args.phenomenon,
        "model": "rover-default",
        "budget": args.budget,
        "batch_images": args.batch_images,
        "seed": args.seed,
        "clean_f1": outcome.summary["clean_f1"],
        "searches": results,
        "enlil_over_random_category1_cells": ratio,
        "aim": 1.5,
        "machine": platform.platform(),
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    shutil.rmtree(tmp, ignore_errors=True)  # the searches' archives and the rendered data
    print(json.dumps(report["enlil_over_random_category1_cells"]))


if __name__ == "__main__":
    main()
