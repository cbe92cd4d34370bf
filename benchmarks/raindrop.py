"""Raindrops like for like (issue 33): F1 on all boxes and on the visible ones, and the ceiling.

A drop on the lens hides what is behind it, so a raindrop F1 on all boxes mixes what the
detector misses with what no detector could find. Every figure here is given twice: on all
boxes, and on the *visible* ones (a box at least half under the drop, mean occlusion mask
≥ ``anunnaki.phenomena.HIDDEN``, is an ignore box), with the *ceiling* beside them: the F1
on all boxes of a detector that finds every visible box and nothing else. Measured with the
project's own commands:

1. **random contexts**: ``anunnaki evaluate-detector REG --model ID --phenomenon P
   --contexts random:N --batch-images B --seed S --json``, run in this process (torch and
   the models load once, as in benchmarks/paper.py), for P = ``raindrop`` (one drop:
   the paper's Fig. 12(b), x, y, radius) and ``raindrop+raindrop+raindrop`` (the phenomenon
   ``rover-raindrop`` was made for), ID = ``rover-default`` and ``rover-raindrop`` — the
   setting of benchmarks/paper.py (100 contexts, 64 test images, seed 7);
2. **the demo's raindrop phase** (``examples/rover/demo.yaml``, one drop of radius 0.3 over
   the crossing pedestrian): ``anunnaki run … --speed 0 --report R.json`` with ``--manager
   none`` and ``rover-default`` active (the demo as shipped), with ``--manager none`` and
   ``rover-raindrop`` active all along (a copy of the registry with the two models' domains
   swapped), and with Utu (which swaps ``rover-raindrop`` in), each in a process of its
   own; the phase table's F1 and F1 on visible boxes.

    .venv/bin/python benchmarks/raindrop.py                 # -> benchmarks/results/raindrop.json
    .venv/bin/python benchmarks/raindrop.py --quick --data D --out F   # a check (the tests)
    .venv/bin/python benchmarks/raindrop.py --parts demo --merge    # one part again

It lowers its own priority by ``nice`` 10, and its runs inherit that: start it without
``nice`` (nice adds up).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml

sys.path.insert(0, str(Path(__file__).parent))
from paper import anunnaki as in_process  # benchmarks/ is no package: its folder on the path

ROOT = Path(__file__).resolve().parents[1]
REGISTRY = ROOT / "examples" / "models" / "rover.yaml"
DEMO = ROOT / "examples" / "rover" / "demo.yaml"
OUT = ROOT / "benchmarks" / "results" / "raindrop.json"
PHENOMENA = {"one drop": "raindrop", "three drops": "raindrop+raindrop+raindrop"}
MODELS = ("rover-default", "rover-raindrop")
#: Utu's watchdog in the runs (wall seconds; benchmarks/case_studies.py's, for the same reason).
WATCHDOG = 120.0
#: What the JSON keeps of a phase row (``anunnaki.managed.PhaseScore.as_dict``).
PHASE_KEYS = (
    "start", "end", "label", "frames", "f1", "tp", "fp", "fn", "f1_visible", "visible",
    "models", "tactics",
)  # fmt: skip


def anunnaki(*args: str, timeout: float = 3600) -> str:
    """Run ``anunnaki ARGS`` in a process of its own from the repository root; its stdout."""
    cmd = [sys.executable, "-m", "anunnaki", *args]
    done = subprocess.run(
        cmd, check=False, capture_output=True, text=True, cwd=ROOT, timeout=timeout
    )
    if done.returncode != 0:
        raise SystemExit(f"anunnaki {' '.join(args)} failed:\n{done.stderr[-3000:]}")
    return done.stdout


def anunnaki_here(*args: str) -> str:
    """Run ``anunnaki ARGS`` in this process (:func:`paper.anunnaki`); its stdout."""
    code, out, err = in_process(list(args))
    if code != 0:
        raise SystemExit(f"anunnaki {' '.join(args)} failed:\n{err[-3000:]}")
    return out


def contexts(data: Path, n: int, images: int, seed: int) -> dict[str, Any]:
    """Mean F1 on all and visible boxes, and the ceiling, per phenomenon and model."""
    out: dict[str, Any] = {}
    for label, phen in PHENOMENA.items():
        out[label] = {"phenomenon": phen}
        for model in MODELS:
            t0 = time.monotonic()
            r = json.loads(anunnaki_here(
                "evaluate-detector", str(REGISTRY), "--model", model, "--data", str(data),
                "--split", "test", "--phenomenon", phen, "--contexts", f"random:{n}",
                "--batch-images", str(images), "--seed", str(seed), "--json",
            ))  # fmt: skip
            out[label][model] = {
                "clean": r["clean"]["f1"],
                "f1": r["f1"],
                "f1_visible": r["f1_visible"],
                "ceiling_f1": r["ceiling_f1"],
                "hidden_share": r["hidden_share"],
                "seconds": round(time.monotonic() - t0, 1),
            }
            print(f"{label}, {model}: {out[label][model]}", flush=True)
    return out


def _absolute(launch: Path, swapped_registry: Path | None, folder: Path) -> Path:
    """A copy of the launch file with absolute paths (and the registry swapped, if given).

    Utu's wall-time watchdog gets :data:`WATCHDOG` and the ``notify`` section is dropped, as
    benchmarks/case_studies.py does: a loaded machine would trip the 3-s watchdog at the
    start and stop the rover for the host's load, and a benchmark sends no e-mail.
    """
    doc = yaml.safe_load(launch.read_text(encoding="utf-8"))
    base = launch.parent
    for key in ("goal_model", "binding", "tactics"):
        doc["utu"][key] = str((base / doc["utu"][key]).resolve())
    doc["utu"]["watchdog"] = WATCHDOG
    doc["utu"].pop("notify", None)
    sim = doc["managed"]["sim"]
    sim["scenario"] = str((base / sim["scenario"]).resolve())
    sim["models"] = str(swapped_registry or (base / sim["models"]).resolve())
    out = folder / launch.name
    out.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return out


def _swapped_registry(folder: Path) -> Path:
    """The registry with rover-raindrop as the default model (and rover-default as raindrop).

    A registry's files lie in its folder, so the models are copied beside the copy.
    """
    doc = yaml.safe_load(REGISTRY.read_text(encoding="utf-8"))
    swap = {"rover-default": "raindrop", "rover-raindrop": "default"}
    for m in doc["models"]:
        files = [m["file"], *([m["oracle"]["file"]] if m.get("oracle") else [])]
        for name in files:
            for f in (REGISTRY.parent / name, (REGISTRY.parent / name).with_suffix(".json")):
                if f.exists():
                    shutil.copy2(f, folder / f.name)
        m["domain"] = swap.get(m["id"], m["domain"])
    out = folder / "rover-swapped.yaml"
    out.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return out


def demo(until: float | None) -> dict[str, Any]:
    """The demo's raindrop phase three ways (see the module docstring).

    With *until* (the quick mode) only the run with the swapped registry, the one that
    builds most, and only to that time.
    """
    runs = {
        "none, rover-default": (["--manager", "none"], False),
        "none, rover-raindrop": (["--manager", "none"], True),
        "utu": ([], False),
    }
    if until is not None:
        runs = {"none, rover-raindrop": runs["none, rover-raindrop"]}
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="raindrop-demo-") as tmp:
        folder = Path(tmp)
        swapped = _swapped_registry(folder)
        for name, (manager, swap) in runs.items():
            sub = folder / name.replace(", ", "-")
            sub.mkdir()
            launch = _absolute(DEMO, swapped if swap else None, sub)
            report = sub / "report.json"
            extra = [] if until is None else ["--until", str(until)]
            t0 = time.monotonic()
            anunnaki("run", str(launch), "--speed", "0", *manager, *extra, "--report", str(report))
            doc = json.loads(report.read_text(encoding="utf-8"))
            phases = [p for p in doc["phases"] if "raindrop" in p["label"]] or doc["phases"][-1:]
            out[name] = {
                "seconds": round(time.monotonic() - t0, 1),
                "phases": [{k: p.get(k) for k in PHASE_KEYS} for p in phases],
            }
            print(f"demo, {name}: {out[name]}", flush=True)
    return out


def _shown(path: Path) -> str:
    """*path* relative to the repository when it lies inside it (the JSON is committed)."""
    resolved = path.resolve()
    return str(resolved.relative_to(ROOT)) if resolved.is_relative_to(ROOT) else str(path)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1 context of 2 images, one 2-s demo run")
    ap.add_argument("--data", type=Path, default=ROOT / "data" / "rover")
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument(
        "--parts",
        default="contexts,demo",
        help="what to measure (contexts,demo); with --merge, the others are kept from --out",
    )
    ap.add_argument("--merge", action="store_true", help="update --out instead of replacing it")
    args = ap.parse_args(argv)
    os.nice(10)
    parts = {p for p in args.parts.split(",") if p}
    if not parts <= {"contexts", "demo"}:
        ap.error(f"--parts: contexts and/or demo, got {args.parts}")
    n, images, seed = (1, 2, 7) if args.quick else (100, 64, 7)
    load_before = list(os.getloadavg())
    t0 = time.monotonic()
    old = (
        json.loads(args.out.read_text(encoding="utf-8")) if args.merge and args.out.exists() else {}
    )
    doc: dict[str, Any] = old | {
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "quick": args.quick,
        "setting": {"contexts": n, "batch_images": images, "seed": seed, "data": _shown(args.data)},
        "hidden_threshold": 0.5,
    }
    if "contexts" in parts:
        doc["contexts"] = contexts(args.data, n, images, seed)
    if "demo" in parts:
        doc["demo"] = demo(2.0 if args.quick else None)
    doc.setdefault("machine", {})[",".join(sorted(parts))] = {
        "wall_s": round(time.monotonic() - t0, 1),
        "load_before": load_before,
        "load_after": list(os.getloadavg()),
        "cpus": os.cpu_count(),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
