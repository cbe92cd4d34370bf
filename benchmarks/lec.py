"""Detector speed: inference ms per frame at 128x128 and 320x240 (batch 1 and 8), training img/s.

The network runs at each size natively (``input_size`` = the frame size, so no resizing is
timed); the weights come from ``--model`` when given (any trained CenterNet: the cost does not
depend on the weights), else a freshly initialised network of the same architecture. Every
case is timed once per round, round-robin, so load from other processes spreads over all of
them; we report the median, minimum and 90th percentile of ``--runs`` rounds after
``--warmup``. ``detect`` is timed end to end (numpy frame in, boxes out: padding, the network,
peak decoding), with torch on ``--threads`` threads.

Training throughput (``training`` in the entry): ``train_detector`` on ``--train-images``
synthetic 128x128 frames (noise with three labelled boxes and three ignore boxes each, so
target encoding with ignore boxes is timed too) for two epochs with the default settings
(batch 32, width 16, flips, zoom, photometric jitter, no phenomena), ``--threads`` threads;
the second epoch's images per second is reported, with the time it gives for the rover
default model's 14 epochs over 2000 images. The load average before and after is recorded:
on a shared machine the figure is only as idle as the machine was.

Writes the ``detector`` entry of ``benchmarks/results/lec.json`` and leaves other entries of
that file (the model manager's) untouched.

    .venv/bin/python benchmarks/lec.py
    .venv/bin/python benchmarks/lec.py --model examples/models/rover-default.safetensors
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from importlib.metadata import version
from pathlib import Path

import numpy as np
import torch

from anunnaki.datasets import Dataset
from anunnaki.lec import CenterNetDetector, TrainConfig, load_detector, train_detector

SIZES = {"128x128": (128, 128), "320x240": (320, 240)}  # label: (width, height)
BATCHES = (1, 8)
DEFAULT_OUTPUT = Path(__file__).parent / "results" / "lec.json"


def detectors(model: str | None, width: int) -> dict[str, CenterNetDetector]:
    """One detector per frame size, sharing one network."""
    if model is not None:
        base = load_detector(model)
        assert isinstance(base, CenterNetDetector)
        net, classes = base.network, base.classes
    else:
        base = CenterNetDetector.create(("pedestrian", "deer"), input_size=(128, 128), width=width)
        net, classes = base.network, base.classes
    return {
        label: CenterNetDetector(
            net, model_id="bench", classes=classes, input_size=size, score_threshold=0.3
        )
        for label, size in SIZES.items()
    }


def measure(
    dets: dict[str, CenterNetDetector], runs: int, warmup: int
) -> dict[str, dict[str, dict[str, float]]]:
    rng = np.random.default_rng(0)
    cases = []
    for label, (w, h) in SIZES.items():
        for batch in BATCHES:
            frames = rng.integers(0, 255, (batch, h, w, 3), dtype=np.uint8)
            cases.append((label, batch, frames))
    times: dict[tuple[str, int], list[float]] = {(c[0], c[1]): [] for c in cases}
    for round_ in range(warmup + runs):
        for label, batch, frames in cases:
            start = time.perf_counter_ns()
            dets[label].detect(frames)
            if round_ >= warmup:
                times[label, batch].append((time.perf_counter_ns() - start) / 1e6 / batch)
    out: dict[str, dict[str, dict[str, float]]] = {}
    for (label, batch), samples in times.items():
        out.setdefault(label, {})[f"batch{batch}"] = {
            "median_ms_per_frame": round(statistics.median(samples), 3),
            "min_ms_per_frame": round(min(samples), 3),
            "p90_ms_per_frame": round(float(np.percentile(samples, 90)), 3),
        }
    return out


def training_throughput(n_images: int, threads: int) -> dict[str, str | float]:
    """Images per second of the second of two training epochs on synthetic frames."""
    rng = np.random.default_rng(1)
    images, boxes, labels, ignore, ignore_labels = [], [], [], [], []
    for _ in range(n_images):
        images.append(rng.integers(0, 255, (128, 128, 3), dtype=np.uint8))
        xy = rng.uniform(0, 96, (6, 2))
        wh = rng.uniform(4, 32, (6, 2))
        b = np.concatenate([xy, xy + wh], axis=1).astype(np.float32)
        boxes.append(b[:3])
        labels.append(rng.integers(0, 2, 3))
        ignore.append(b[3:])
        ignore_labels.append(rng.integers(0, 2, 3))
    data = Dataset.from_arrays(
        images, boxes, labels, ("pedestrian", "deer"), ignore=ignore, ignore_labels=ignore_labels
    )
    load_before = os.getloadavg()[0]
    result = train_detector(data, data[:8], config=TrainConfig(epochs=2, threads=threads))
    seconds = result.history[1]["seconds"]
    per_s = n_images / seconds
    return {
        "what": "train_detector, 128x128, batch 32, width 16, images/s of epoch 2",
        "images": n_images,
        "images_per_second": round(per_s, 1),
        "rover_default_seconds_estimate": round(14 * 2000 / per_s, 1),
        "load_average_1min_before": round(load_before, 2),
        "load_average_1min_after": round(os.getloadavg()[0], 2),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", help="a trained model file (default: fresh weights)")
    parser.add_argument("--width", type=int, default=16, help="network width without --model")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--runs", type=int, default=50)
    parser.add_argument("--warmup", type=int, default=5)
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT)
    parser.add_argument(
        "--train-images", type=int, default=640, help="synthetic frames for the training figure"
    )
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    dets = detectors(args.model, args.width)
    net = next(iter(dets.values())).network
    results = measure(dets, args.runs, args.warmup)
    training = training_throughput(args.train_images, args.threads)
    entry = {
        "what": "CenterNetDetector.detect end to end, ms per frame (median of rounds)",
        "model": args.model or f"fresh centernet width {args.width}",
        "parameters": sum(p.numel() for p in net.parameters()),
        "threads": args.threads,
        "runs": args.runs,
        "warmup": args.warmup,
        "results": results,
        "training": training,
        "machine": {
            "python": platform.python_version(),
            "torch": version("torch"),
            "numpy": version("numpy"),
            "cpu_count": os.cpu_count(),
            "load_average_1min": round(os.getloadavg()[0], 2),
            "platform": platform.platform(),
        },
    }
    data = json.loads(args.output.read_text()) if args.output.is_file() else {}
    data["detector"] = entry
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(data, indent=2) + "\n")
    for label, by_batch in results.items():
        for batch, figures in by_batch.items():
            print(f"{label} {batch}: {figures['median_ms_per_frame']:.2f} ms/frame")
    print(
        f"training: {training['images_per_second']:.0f} images/s "
        f"(rover default, 14 x 2000 images: {training['rover_default_seconds_estimate']:.0f} s)"
    )
    print(f"wrote {args.output}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
