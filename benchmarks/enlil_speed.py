"""How long each step of rebuilding a behavior oracle takes, this code against a baseline.

Issue 13 asks that ``scripts/train-oracles.sh`` rebuild every shipped oracle in minutes. Its
steps are an Enlil assessment (``anunnaki assess``: one evaluation perturbs the fixed batch of
32 val images with a context and runs the detector over it), the oracle's training (perturbed
frames, then epochs of a small CNN) and, for the UAV, rendering its dataset. Each step is
timed here at a fixed small size on the rendered rover dataset:

- ``assess_<phenomenon>``: the worker's setup (model, batch, clean F1), then ``--evals``
  evaluations of seeded random contexts, as ``anunnaki assess`` runs them in a pool process
  (one torch thread);
- ``oracle_frames``: ``perturbed_frames`` of four phenomena, ``--frames`` train-split frames;
- ``oracle_fit``: the training loop over those frames, ``--epochs`` epochs, one thread;
- ``uav_render``: ``--uav-frames`` frames of a UAV scene at 320 x 240 (unchanged code);
- ``oracle_predict``: the ``rover-default`` oracle shipped at ``--predict-oracle`` (a git
  revision; an oracle both trees read: the one the speed-up was made for, a ``small_cnn``
  of ``anunnaki-oracle/2`` without a drop head) and its whole ``predict`` (network,
  context lookup, mix) on one 128 x 128 frame at a time, ``--predict-calls`` calls over 16
  val frames under fog, HSL and raindrop contexts (the ``enlil`` plugin's per-frame work;
  aim <= 3 ms); its baseline is ``--predict-baseline`` (the commit before its speed-up),
  and both must give the same probabilities to float rounding (``max_prob_diff``).

The baseline is the source tree of ``--baseline`` (a git revision, default the commit before
the speed-ups; extracted with ``git archive``). Baseline and current code run in alternation,
each step in a fresh process, one torch thread, in the same run; each step's CPU seconds
(of that process) and wall seconds are the minimum over ``--rounds`` rounds, and the ratio
is baseline / current. Whether both computed the same is checked too: a digest of the
evaluations' F1 and of the frames' pixels must match; the fit's losses may differ by float
summation order (``fit_loss_max_rel_diff``).

    .venv/bin/python benchmarks/enlil_speed.py --quick   # about 3 minutes
    .venv/bin/python benchmarks/enlil_speed.py           # -> benchmarks/results/enlil_speed.json
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "examples" / "models" / "rover-default.safetensors"
DEFAULT_OUTPUT = ROOT / "benchmarks" / "results" / "enlil_speed.json"
#: The last commit before the speed-ups of this benchmark's change (issue 13).
BASELINE = "f6199dffe105fc8d4e679e6baaba8d1ddffad15b"
#: The last commit before the oracle's per-frame speed-up (``oracle_predict``).
PREDICT_BASELINE = "b23725c3e1a5e82f7dd570fefbed67d1e878d845"
#: The revision whose shipped ``rover-default`` oracle ``oracle_predict`` times: the last one
#: the ``--predict-baseline`` tree can read (later ones have a drop head, or are patch_cnn).
PREDICT_ORACLE = "32e59dc76dbe0612ba80de4f1894e3aa5ada0702"
STEPS = ("assess_fog", "assess_hsl", "oracle_frames", "oracle_fit", "uav_render", "oracle_predict")
#: Sizes: assess evaluations, perturbed frames, fit frames and epochs, UAV frames, rounds.
FULL = {
    "evals": 24,
    "frames": 600,
    "fit_frames": 640,
    "epochs": 2,
    "uav_frames": 10,
    "predict_calls": 1000,
    "rounds": 2,
}
QUICK = {
    "evals": 8,
    "frames": 200,
    "fit_frames": 192,
    "epochs": 1,
    "uav_frames": 4,
    "predict_calls": 200,
    "rounds": 1,
}
#: The context sets of the frame and fit steps: four phenomena, 200 contexts each.
PHENOMENA = {
    "fog": ("density", "intensity"),
    "hsl": ("hue", "saturation", "lightness"),
    "raindrop": ("x", "y", "radius", "feather"),
    "brightness": ("gain", "gamma"),
}


# -- one step, in a child process -----------------------------------------------------------


def _assess(phenomenon: str, data: str, evals: int) -> dict[str, Any]:
    import numpy as np

    from anunnaki.enlil._run import Job, _loaded, evaluate_task

    job = Job(str(MODEL), data, phenomenon)
    t0, c0 = time.perf_counter(), time.process_time()
    _loaded(job)
    setup = (time.perf_counter() - t0, time.process_time() - c0)
    dim = len(PHENOMENA[phenomenon])
    vectors = np.random.default_rng(1).random((evals, dim))
    t0, c0 = time.perf_counter(), time.process_time()
    f1 = [evaluate_task((job, v.tolist())).f1 for v in vectors]
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {
        "setup_wall": setup[0],
        "setup_cpu": setup[1],
        "wall": wall,
        "cpu": cpu,
        "per_eval_cpu": cpu / evals,
        "digest": hashlib.sha256(json.dumps(f1).encode()).hexdigest(),
    }


def _sets() -> list[Any]:
    import numpy as np

    from anunnaki.enlil._oracle_train import ContextSet

    rng = np.random.default_rng(0)
    return [
        ContextSet(name, names, rng.random((200, len(names))), rng.integers(0, 3, 200), "bench")
        for name, names in PHENOMENA.items()
    ]


def _frames(data: str, n: int) -> tuple[Any, dict[str, Any]]:
    from anunnaki.datasets import load_split
    from anunnaki.enlil._oracle_train import perturbed_frames

    train = load_split(data, "train")
    t0, c0 = time.perf_counter(), time.process_time()
    frames = perturbed_frames(train, _sets(), n, seed=0)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    digest = hashlib.sha256()
    for f in frames.frames:
        digest.update(f.tobytes())
    digest.update(frames.category.tobytes() + frames.params.tobytes())
    return frames, {"wall": wall, "cpu": cpu, "digest": digest.hexdigest()}


def _fit(data: str, n: int, epochs: int) -> dict[str, Any]:
    import torch

    from anunnaki.enlil._oracle_net import OracleCard, PhenomenonSpec, build_network
    from anunnaki.enlil._oracle_train import OracleTrainConfig
    from anunnaki.enlil._oracle_train import _fit as fit

    frames, _ = _frames(data, n)
    specs = [PhenomenonSpec(name=k, param_names=list(v)) for k, v in PHENOMENA.items()]
    card = OracleCard(model_id="bench", phenomena=specs)
    torch.manual_seed(0)
    net = build_network(card)
    cfg = OracleTrainConfig(frames=n, epochs=epochs, threads=1)
    t0, c0 = time.perf_counter(), time.process_time()
    losses = fit(net, frames, cfg)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {"wall": wall, "cpu": cpu, "losses": losses}


def _render(n: int) -> dict[str, Any]:
    from anunnaki.sim._scene import dataset_frames

    t0, c0 = time.perf_counter(), time.process_time()
    images = [f.image for f in dataset_frames("uav", layout=0, seed=0, n=n, width=320, height=240)]
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    digest = hashlib.sha256(b"".join(i.tobytes() for i in images)).hexdigest()
    return {"wall": wall, "cpu": cpu, "per_frame_wall": wall / n, "digest": digest}


def _predict(data: str, calls: int, oracle_file: str) -> dict[str, Any]:
    import numpy as np

    from anunnaki.datasets import load_split
    from anunnaki.enlil import load_oracle

    oracle = load_oracle(oracle_file)  # its sidecar's weights_sha256 is checked
    val = load_split(data, "val")
    rng = np.random.default_rng(0)
    frames = []
    for i in range(16):
        image = val.image(i % len(val))
        name = ("clear", "fog", "hsl", "raindrop")[i % 4]
        if name != "clear":
            ph = _phenomenon(name)
            low, high = np.asarray(ph.bounds(), np.float64).T
            vector = low + rng.random(len(low)) * (high - low)
            image = ph.apply(image, ph.from_vector(vector), seed=i)
        frames.append(image)
    for frame in frames:  # warm-up
        oracle.predict([frame])
    times = []
    t0, c0 = time.perf_counter(), time.process_time()
    for i in range(calls):
        start = time.perf_counter()
        oracle.predict([frames[i % len(frames)]])
        times.append(time.perf_counter() - start)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    probs = [list(oracle.predict([f])[0].probs) for f in frames]
    return {
        "wall": wall,
        "cpu": cpu,
        "median_ms": 1000 * float(np.median(times)),
        "p90_ms": 1000 * float(np.percentile(times, 90)),
        "probs": probs,
    }


def _phenomenon(name: str) -> Any:
    """A phenomenon by name, in this tree or a baseline's (the slot or the old function)."""
    import anunnaki.phenomena as phenomena

    # Both looked up by name: the baseline may predate the slot, and this tree has no function.
    slot = getattr(phenomena, "PHENOMENA", None)
    if slot is not None:
        return slot.create(name)
    make = getattr(phenomena, "get_phenomenon", None)
    if make is None:
        raise RuntimeError(f"{phenomena.__file__}: neither PHENOMENA nor get_phenomenon")
    return make(name)


def run_step(step: str, args: argparse.Namespace) -> dict[str, Any]:
    """Time one step in this process (the code imported is whatever ``sys.path`` finds)."""
    import torch

    torch.set_num_threads(1)
    if step.startswith("assess_"):
        return _assess(step.removeprefix("assess_"), args.data, args.evals)
    if step == "oracle_frames":
        return _frames(args.data, args.frames)[1]
    if step == "oracle_fit":
        return _fit(args.data, args.fit_frames, args.epochs)
    if step == "oracle_predict":
        return _predict(args.data, args.predict_calls, args.predict_oracle_file)
    return _render(args.uav_frames)


# -- the comparison, in the parent ------------------------------------------------------------


def _extract(rev: str, into: Path) -> Path:
    archive = into / "src.tar"
    with archive.open("wb") as fh:
        subprocess.run(["git", "-C", str(ROOT), "archive", rev, "src"], stdout=fh, check=True)
    with tarfile.open(archive) as tar:
        tar.extractall(into, filter="data")
    return into / "src"


def _oracle_at(rev: str, into: Path) -> str:
    """``rover-default``'s oracle file (both halves) as shipped at *rev*, under *into*."""
    into.mkdir()
    for suffix in (".safetensors", ".json"):
        name = f"rover-default.oracle{suffix}"
        blob = subprocess.run(
            ["git", "-C", str(ROOT), "show", f"{rev}:examples/models/{name}"],
            capture_output=True, check=True,
        ).stdout  # fmt: skip
        (into / name).write_bytes(blob)
    return str(into / "rover-default.oracle.safetensors")


def _child(step: str, src: Path, args: argparse.Namespace) -> dict[str, Any]:
    env = dict(os.environ, PYTHONPATH=str(src), OMP_NUM_THREADS="1")
    cmd = [sys.executable, __file__, "--step", step, "--data", args.data]
    cmd += ["--evals", str(args.evals), "--frames", str(args.frames)]
    cmd += ["--fit-frames", str(args.fit_frames), "--epochs", str(args.epochs)]
    cmd += ["--uav-frames", str(args.uav_frames), "--predict-calls", str(args.predict_calls)]
    cmd += ["--predict-oracle-file", getattr(args, "predict_oracle_file", "")]
    out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
    result: dict[str, Any] = json.loads(out.strip().splitlines()[-1])
    return result


def _best(runs: list[dict[str, Any]]) -> dict[str, Any]:
    best = dict(min(runs, key=lambda r: r["cpu"]))
    best["wall"] = min(r["wall"] for r in runs)
    return best


def compare(args: argparse.Namespace) -> dict[str, Any]:
    """Run every step for the baseline and the current tree, alternating, and compare."""
    tmp = Path(tempfile.mkdtemp(prefix="enlil-speed-"))
    trees = {"baseline": _extract(args.baseline, tmp), "current": ROOT / "src"}
    if "oracle_predict" in args.steps:
        (tmp / "predict").mkdir()
        trees["predict_baseline"] = _extract(args.predict_baseline, tmp / "predict")
        args.predict_oracle_file = _oracle_at(args.predict_oracle, tmp / "oracle")
    runs: dict[str, dict[str, list[dict[str, Any]]]] = {
        s: {"baseline": [], "current": []} for s in args.steps
    }
    load_before = os.getloadavg()
    for _ in range(args.rounds):
        for step in args.steps:
            for side in ("baseline", "current"):
                own = side == "baseline" and step == "oracle_predict"
                tree = "predict_baseline" if own else side
                runs[step][side].append(_child(step, trees[tree], args))
                print(step, side, round(runs[step][side][-1]["cpu"], 2), file=sys.stderr)
    steps: dict[str, Any] = {}
    for step, sides in runs.items():
        base, cur = _best(sides["baseline"]), _best(sides["current"])
        entry: dict[str, Any] = {
            "baseline_cpu_s": round(base["cpu"], 3),
            "current_cpu_s": round(cur["cpu"], 3),
            "cpu_ratio": round(base["cpu"] / cur["cpu"], 2),
            "baseline_wall_s": round(base["wall"], 3),
            "current_wall_s": round(cur["wall"], 3),
            "wall_ratio": round(base["wall"] / cur["wall"], 2),
        }
        if "setup_cpu" in base:
            entry["setup_cpu_s"] = [round(base["setup_cpu"], 3), round(cur["setup_cpu"], 3)]
        if "digest" in base:
            entry["identical"] = base["digest"] == cur["digest"]
        if "median_ms" in base:
            entry["baseline_median_ms"] = round(base["median_ms"], 3)
            entry["current_median_ms"] = round(cur["median_ms"], 3)
            entry["median_ratio"] = round(base["median_ms"] / cur["median_ms"], 2)
            entry["current_p90_ms"] = round(cur["p90_ms"], 3)
            diff = max(
                abs(a - b)
                for pa, pb in zip(base["probs"], cur["probs"], strict=True)
                for a, b in zip(pa, pb, strict=True)
            )
            entry["max_prob_diff"] = float(f"{diff:.2e}")
            entry["baseline"] = args.predict_baseline
            entry["oracle_shipped_at"] = args.predict_oracle
        if "losses" in base:
            rel = [abs(a - b) / abs(a) for a, b in zip(base["losses"], cur["losses"], strict=True)]
            entry["fit_loss_max_rel_diff"] = float(f"{max(rel):.2e}")
        steps[step] = entry
    return {
        "what": "seconds per step, baseline tree vs current tree, one torch thread each, "
        "minimum over rounds (see the module docstring)",
        "baseline": args.baseline,
        "sizes": {
            "assess_evaluations": args.evals,
            "batch_images": 32,
            "oracle_frames": args.frames,
            "fit_frames": args.fit_frames,
            "fit_epochs": args.epochs,
            "uav_frames": args.uav_frames,
            "predict_calls": args.predict_calls,
        },
        "rounds": args.rounds,
        "steps": steps,
        "machine": {
            "python": platform.python_version(),
            "cpu_count": os.cpu_count(),
            "load_average_1min_before": round(load_before[0], 2),
            "load_average_1min_after": round(os.getloadavg()[0], 2),
            "platform": platform.platform(),
        },
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="smaller sizes, one round")
    parser.add_argument("--data", default=str(ROOT / "data" / "rover"))
    parser.add_argument("--baseline", default=BASELINE, help="git revision of the baseline")
    parser.add_argument(
        "--predict-baseline", default=PREDICT_BASELINE, help="baseline revision of oracle_predict"
    )
    for name, value in FULL.items():  # --quick: QUICK's value unless given
        parser.add_argument(f"--{name.replace('_', '-')}", type=int, help=f"default {value}")
    parser.add_argument(
        "--predict-oracle",
        default=PREDICT_ORACLE,
        help="git revision whose shipped rover-default oracle oracle_predict times",
    )
    parser.add_argument("--predict-oracle-file", help=argparse.SUPPRESS)  # internal: its file
    parser.add_argument("--steps", default=",".join(STEPS))
    parser.add_argument("--step", help=argparse.SUPPRESS)  # internal: run one step, print JSON
    parser.add_argument("--output", default=str(DEFAULT_OUTPUT))
    args = parser.parse_args()
    for name, value in (QUICK if args.quick else FULL).items():
        if getattr(args, name) is None:
            setattr(args, name, value)
    if args.step:
        print(json.dumps(run_step(args.step, args)))
        return
    args.steps = [s for s in args.steps.split(",") if s]
    if not (Path(args.data) / "val.json").is_file():
        sys.exit(f"{args.data}: no rendered rover dataset; run anunnaki make-dataset rover")
    result = compare(args)
    result["quick"] = args.quick
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result["steps"], indent=2))


if __name__ == "__main__":
    main()
