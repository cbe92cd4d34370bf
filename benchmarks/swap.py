"""Swap latency of the learning model manager, with the real detector, under a 30 Hz camera.

Two CenterNet detectors (the demos' default LEC: base width 16, 128 × 128 input, the UAV's
classes; untrained weights — latency does not depend on what the weights learned) are saved
as safetensors + sidecar and listed in a registry with their sha256. A ``LecNode`` runs on the
in-process bus; a camera thread publishes 128 × 128 JPEG frames at 30 Hz. Each round asks
``/lm_manager/swap`` for the other domain, and measures:

* ``reply_ms``: request → reply (resolve, sha256, load, switch);
* ``load_ms``: what the node reports (resolve + sha256 + load);
* ``first_detection_ms``: request → the first detection tagged with the new model (what
  a tactic waits for), which adds at most one frame period and one inference;
* that every frame got exactly one detection and the switch was monotone.

Two setups: ``cold`` (``cache=0``: every swap hashes and loads the file) and ``cached``
(the default ``cache=2``: after the first round both models stay in memory, as for the
swap back to the default model). Results: ``benchmarks/results/swap.json``.

Run: ``.venv/bin/python benchmarks/swap.py [--rounds 20]``
"""

from __future__ import annotations

import argparse
import functools
import itertools
import json
import platform
import statistics
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch

from anunnaki.bus import Sample, open_bus
from anunnaki.lec import (
    CenterNetDetector,
    LecNode,
    ModelRegistry,
    detections_topic,
    save_detector,
    sha256_file,
)
from anunnaki.messages import Detections, Image
from anunnaki.phenomena import synthetic_scene
from anunnaki.sim import UAV_CLASSES

RESULTS = Path(__file__).parent / "results" / "swap.json"
CAMERA = "/uav/camera/image"
SIZE = 128
RATE = 30.0


def make_models(folder: Path) -> ModelRegistry:
    registry = ModelRegistry()
    for seed, (model_id, domain) in enumerate((("uav-default", "default"), ("uav-fog", "fog"))):
        det = CenterNetDetector.create(
            UAV_CLASSES, input_size=(SIZE, SIZE), width=16, seed=seed, model_id=model_id,
            domain=domain,
        )  # fmt: skip
        path = folder / f"{model_id}.safetensors"
        save_detector(det, path)
        registry.add(id=model_id, domain=domain, file=path, sha256=sha256_file(path))
    return registry


def stats(values: list[float]) -> dict[str, float]:
    ordered = sorted(values)
    q = statistics.quantiles(ordered, n=10, method="inclusive") if len(ordered) > 1 else ordered
    return {
        "p50": round(statistics.median(ordered), 1),
        "p90": round(q[-1], 1),
        "max": round(ordered[-1], 1),
        "mean": round(statistics.fmean(ordered), 1),
        "n": len(ordered),
    }


def _first_from(got: list[tuple[float, Detections]], model: str, t0: float) -> float | None:
    """When the first detections of ``model`` at or after ``t0`` arrived, if they have."""
    return next((t for t, d in got if d.model_id == model and t >= t0), None)


def run(registry: ModelRegistry, *, cache: int, rounds: int) -> dict[str, Any]:
    frames = [
        cv2.imencode(".jpg", cv2.cvtColor(synthetic_scene(SIZE, SIZE, seed=i), cv2.COLOR_RGB2BGR))[
            1
        ].tobytes()
        for i in range(8)
    ]
    got: list[tuple[float, Detections]] = []
    cond = threading.Condition()
    with (
        open_bus("inproc") as bus,
        LecNode(bus, registry, camera=CAMERA, cache=cache, active_period=None) as node,
    ):

        def on(sample: Sample) -> None:
            assert isinstance(sample.message, Detections)
            with cond:
                got.append((time.perf_counter(), sample.message))
                cond.notify_all()

        bus.subscribe(detections_topic("detector"), on, queue=4096)
        stop = threading.Event()
        published = [0]

        def camera() -> None:
            period = 1.0 / RATE
            next_t = time.perf_counter()
            while not stop.is_set():
                seq = published[0]
                data = frames[seq % len(frames)]
                bus.publish(
                    CAMERA, Image(encoding="jpeg", width=SIZE, height=SIZE, data=data, seq=seq)
                )
                published[0] += 1
                next_t += period
                stop.wait(max(0.0, next_t - time.perf_counter()))

        cam = threading.Thread(target=camera, daemon=True)
        cam.start()
        with cond:  # warm-up: the first inferences are slower
            cond.wait_for(lambda: len(got) >= 15, 30.0)
        reply_ms, load_ms, first_ms = [], [], []
        domains = ["fog", "default"]
        for r in range(rounds):
            target = domains[r % 2]
            t0 = time.perf_counter()
            reply = bus.request("/lm_manager/swap", {"lec": "detector", "domain": target}, 30.0)
            t1 = time.perf_counter()
            body = reply.to_body()["body"]
            model = body["model"]
            with cond:
                first = cond.wait_for(functools.partial(_first_from, got, model, t0), 30)
            if first is None:
                raise RuntimeError(f"no detections from {model} within 30 s of the swap")
            reply_ms.append((t1 - t0) * 1000)
            load_ms.append(float(body["load_ms"]))
            first_ms.append((first - t0) * 1000)
            pause = threading.Event()
            pause.wait(0.3)  # let the camera run between swaps (pacing, not synchronisation)
        stop.set()
        cam.join()
        with cond:
            cond.wait_for(lambda: len(got) >= published[0], 30.0)
        dets = [d for _, d in got]
        inference = [d.latency_ms or 0.0 for d in dets]
        swaps = node.stats().swaps
    seqs = [d.frame_seq for d in dets]
    switches = sum(1 for a, b in itertools.pairwise(dets) if a.model_id != b.model_id)
    return {
        "cache": cache,
        "rounds": rounds,
        "swaps": swaps,
        "frames": published[0],
        "detections": len(dets),
        "every_frame_once_in_order": seqs == list(range(published[0])),
        "monotone_switches": switches == swaps,
        "reply_ms": stats(reply_ms),
        "load_ms": stats(load_ms),
        "first_detection_ms": stats(first_ms),
        "inference_ms": stats(inference),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=20)
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args()
    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as folder:
        registry = make_models(Path(folder))
        size = (Path(folder) / "uav-default.safetensors").stat().st_size
        results = {
            "cold": run(registry, cache=0, rounds=args.rounds),
            "cached": run(registry, cache=2, rounds=args.rounds),
        }
    out = {
        "benchmark": "swap",
        "camera": f"{SIZE}x{SIZE} JPEG at {RATE:g} Hz, in-process bus",
        "model": f"CenterNet width 16, {SIZE}x{SIZE} input, {len(UAV_CLASSES)} classes, "
        f"{size} bytes of safetensors",
        "torch_threads": 1,
        "machine": {
            "python": platform.python_version(),
            "platform": platform.platform(),
            "torch": torch.__version__,
            "numpy": np.__version__,
        },
        "results": results,
    }
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(out, indent=2) + "\n", encoding="utf-8")
    print(json.dumps(out["results"], indent=2))


if __name__ == "__main__":
    main()
