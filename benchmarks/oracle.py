"""Behavior oracle figures (issue 13, Measure). So far: inference per 128 x 128 frame.

The ``small_cnn`` oracle (its cost does not depend on its weights) assesses one 128 x 128
frame at a time with torch on one thread, as the ``enlil`` plugin does at run time; the
median and p90 over ``--frames`` calls after a warm-up go to
``benchmarks/results/oracle.json`` (aim: median <= 3 ms). Accuracy, macro-F1, baselines and
ramps are not measured yet.

Run: ``.venv/bin/python benchmarks/oracle.py [--frames 500]``
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time
from pathlib import Path

import numpy as np
import torch

from anunnaki.enlil import OracleCard, OracleModel
from anunnaki.enlil._oracle_net import PhenomenonSpec, build_network

OUT = Path(__file__).resolve().parent / "results" / "oracle.json"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=500)
    args = parser.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(0)
    card = OracleCard(
        model_id="rover-default",
        phenomena=[PhenomenonSpec(name="fog", param_names=["density", "intensity"])],
    )
    oracle = OracleModel(card, build_network(card))
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 256, (128, 128, 3), dtype=np.uint8) for _ in range(32)]
    for f in frames:
        oracle.predict([f])
    times = []
    for i in range(args.frames):
        t0 = time.perf_counter()
        oracle.predict([frames[i % len(frames)]])
        times.append((time.perf_counter() - t0) * 1e3)
    times.sort()
    result = {
        "inference_ms_per_frame_128": {
            "median": round(statistics.median(times), 3),
            "p90": round(times[int(0.9 * len(times))], 3),
            "frames": args.frames,
            "threads": 1,
            "parameters": sum(p.numel() for p in oracle.net.parameters()),
        },
        "not_measured_yet": ["accuracy", "macro_f1", "baselines", "ramps", "loop_rate"],
        "machine": {"python": platform.python_version(), "torch": torch.__version__},
    }
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
