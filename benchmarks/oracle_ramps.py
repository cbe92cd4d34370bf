"""The learned oracle on scripted ramps in the simulator: delay, false alarms, loop rate.

Issue #13's run-time figures for the shipped ``enlil`` oracle of ``rover-default``
(examples/models/rover.yaml). Each run is the simulated rover (background clutter as in
the datasets, a pedestrian and a deer in view) with the detector and the ``enlil`` oracle on
one thread of delivery (an executor), no Utu (no swap: the default model stays active):
``--clean`` seconds of clear weather, then one scripted ramp, then ``--hold`` seconds at its end:

* ``fog``: fog from nothing to full strength (10 layers at opacity 0.3) over ``--ramp`` s;
* ``raindrop``: a drop appearing on the lens, its radius growing to 0.3 of the image width
  over 1 s, at a position drawn per seed;
* ``hsl``: an HSL sweep from the identity to poor light (saturation -0.6, lightness -0.8,
  a hue shift drawn per seed in [-90, 90] degrees) over ``--ramp`` s;
* ``dusk``: the demo's dusk onset (examples/rover/demo-scenario.yaml): brightness falling
  to strength 0.8 over 2 s, on the demo's bare ground (``background: false``);

and two cases with no phenomenon at all:

* ``close``: close pedestrians in clear weather, the view behind the demo's false alarm
  (docs/enlil.md, "In the loop"): the rover creeps (1 cm/s) on bare ground while a
  pedestrian crosses its path at a distance drawn per seed in [0.3, 1.0] m from the
  camera. Every frame is clean; ``in_view_frames`` counts those in which the pedestrian
  stands in the camera's field;
* ``demo_close``: the demo's own clear-weather close-up, its first 8 s without a phenomenon
  (the rover stops for a crossing pedestrian, who walks on half a metre in front of the
  camera), on the demo's ground (seed 0) and others (layout 3 + seed).

The ground-truth category of a frame is the assessment rule applied to the context in force
at its time: the model's F1 on a fixed batch of 32 test-split images perturbed with exactly
those parameters, against its clean F1 (``anunnaki.enlil.evaluate_context``). The ramps are
monotone, so the time the true category first reaches 1 is found by bisection (to a tenth of
a frame period). Per run:

* **delay**: frames from that true change to the oracle's first category >= 1 at or after
  the ramp's start (negative: the oracle said so before the detector was measurably worse);
* **false alarms**: clean frames (before the ramp; every frame of the close cases) the
  oracle called category >= 1, reported per 1,000 clean frames over all runs
  (``false_alarms``: with and without the close pedestrians; ``onset_delay_frames``: the
  delays per phenomenon).

Then the whole loop's rate with the oracle in place of ground truth:
``examples/rover/sim-enlil.yaml`` (Utu's five nodes, the enlil oracle as A4; its live
scorer left out) run flat out for ``--loop-seconds`` simulated seconds, camera frames per
wall second; and ``examples/rover/sim.yaml`` (ground truth as A4) the same way.

Writes ``benchmarks/results/oracle_ramps.json``::

    .venv/bin/python benchmarks/oracle_ramps.py --data data/rover          # 10 seeds
    .venv/bin/python benchmarks/oracle_ramps.py --data data/rover --quick  # 2 seeds, shorter

Options given with ``--quick`` (``--seeds``, ``--clean``, ``--ramp``, ``--loop-seconds``)
keep their value.
"""

from __future__ import annotations

import argparse
import io
import json
import math
import os
import platform
import statistics
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from anunnaki import topics
from anunnaki.bus import Executor, open_bus
from anunnaki.enlil import evaluate_context, fixed_batch, normalise
from anunnaki.launch import load_launch, run_launch
from anunnaki.lec import evaluate_detector, load_registry
from anunnaki.managed import SimKind, SimulatedSystem
from anunnaki.messages import Assessment, body_of
from anunnaki.phenomena import PHENOMENA
from anunnaki.sim import load_scenario

ROOT = Path(__file__).parents[1]
MODELS = ROOT / "examples" / "models" / "rover.yaml"
RESULTS = Path(__file__).parent / "results" / "oracle_ramps.json"
LAUNCHES = {
    "enlil": ROOT / "examples" / "rover" / "sim-enlil.yaml",
    "ground_truth": ROOT / "examples" / "rover" / "sim.yaml",
}
RATE = 10.0  # camera frames per second
FAST = 1000.0  # simulated seconds per wall second asked for: as fast as the loop goes


KINDS = ("fog", "raindrop", "hsl", "dusk", "close", "demo_close")
CLEAN = ("close", "demo_close")  # the cases with no phenomenon: every frame clean
DEMO = ROOT / "examples" / "rover" / "demo-scenario.yaml"
#: The phenomenon a ramp scripts (``close``: none).
PHENOMENON = {"fog": "fog", "raindrop": "raindrop", "hsl": "hsl", "dusk": "brightness"}
CAMERA_FORWARD = 0.55  # m: the rover's camera sits this far ahead of its base (anunnaki.sim)
HALF_FOV = math.radians(30.0)  # the rover camera's half field of view (square frames)
CLOSE_RANGE = (0.3, 1.0)  # m from the camera: where the close pedestrian crosses
CLOSE_SPEED, CLOSE_HALF_PATH, CLOSE_START = 0.4, 1.2, 1.0  # m/s, m, s
PERSON_HALF_WIDTH = 0.25  # m: a pedestrian's half width, for in_view_frames


def ramp_event(kind: str, seed: int, at: float, ramp: float) -> dict[str, Any]:
    """The scenario's phenomenon event of one ramp (parameters drawn from ``seed``)."""
    rng = np.random.default_rng(seed)
    if kind == "fog":
        return {"at": at, "phenomenon": "fog", "params": {"density": 10, "intensity": 0.3},
                "ramp": ramp}  # fmt: skip
    if kind == "raindrop":
        x, y = (float(v) for v in rng.uniform(0.25, 0.75, 2))
        params = {"x": round(x, 3), "y": round(y, 3), "radius": 0.3, "feather": 0.25}
        return {"at": at, "phenomenon": "raindrop", "params": params, "ramp": 1.0}
    if kind == "hsl":
        hue = round(float(rng.uniform(-90.0, 90.0)), 1)
        params = {"hue": hue, "saturation": -0.6, "lightness": -0.8}
        return {"at": at, "phenomenon": "hsl", "params": params, "ramp": ramp}
    if kind == "dusk":  # as examples/rover/demo-scenario.yaml's dusk
        return {"at": at, "phenomenon": "brightness", "strength": 0.8, "ramp": 2.0}
    raise ValueError(f"unknown ramp {kind!r}: {', '.join(KINDS)}")


def scenario(kind: str, seed: int, clean: float, ramp: float, hold: float) -> dict[str, Any]:
    """A rover scenario: ``clean`` s of clear weather, the ramp, ``hold`` s at its end."""
    if kind == "close":
        return close_scenario(seed)
    if kind == "demo_close":
        return demo_close_scenario(seed)
    event = ramp_event(kind, seed, clean, ramp)
    return {
        "anunnaki": "scenario/1",
        "platform": "rover",
        "name": f"ramp-{kind}-s{seed}",
        "layout": 44 + seed % 10,  # test layouts: never seen by the detector or the oracle
        "background": kind != "dusk",  # the dusk on the demo's bare ground
        "seed": seed,
        "duration": clean + event["ramp"] + hold,
        "camera": {"rate": RATE, "width": 128, "height": 128},
        "route": [[0, 0], [40, 0]],
        "cruise_speed": 0.3,
        "objects": [
            {"kind": "pedestrian", "x": 5.0, "y": -2.0, "walk_to": [5.0, 2.0], "speed": 0.2},
            {"kind": "deer", "x": 8.0, "y": 2.5, "yaw": 1.57},
        ],
        "phenomena": [event],
    }


def close_distance(seed: int) -> float:
    """The close pedestrian's distance from the camera (m), drawn per seed."""
    return round(float(np.random.default_rng([seed, 7]).uniform(*CLOSE_RANGE)), 3)


def close_scenario(seed: int) -> dict[str, Any]:
    """Clear weather, bare ground, a pedestrian crossing 0.3-1 m in front of the camera."""
    d = close_distance(seed)
    side = 1.0 if seed % 2 == 0 else -1.0  # from the left or the right
    x = CAMERA_FORWARD + d
    walk = 2 * CLOSE_HALF_PATH / CLOSE_SPEED
    return {
        "anunnaki": "scenario/1",
        "platform": "rover",
        "name": f"close-pedestrian-s{seed}",
        "layout": 44 + seed % 10,
        "background": False,  # the demo's ground, where the close-up alarm was seen
        "seed": seed,
        "duration": CLOSE_START + walk + 1.0,
        "camera": {"rate": RATE, "width": 128, "height": 128},
        "route": [[0, 0], [40, 0]],
        "cruise_speed": 0.01,  # all but standing: the pedestrian stays at its distance
        "objects": [
            {
                "kind": "pedestrian",
                "x": x,
                "y": -side * CLOSE_HALF_PATH,
                "walk_to": [x, side * CLOSE_HALF_PATH],
                "speed": CLOSE_SPEED,
                "start": CLOSE_START,
            }
        ],
        "phenomena": [],
    }


def demo_close_scenario(seed: int) -> dict[str, Any]:
    """The demo's first 8 s without a phenomenon: the rover stops close to a pedestrian.

    examples/rover/demo-scenario.yaml's first pedestrian crosses 6 m ahead from 2 s; the
    rover (0.8 m/s) stops for it and the pedestrian walks on about half a metre in front
    of the camera at 6.5-7.6 s, where the shipped oracle's clear-weather alarm was seen
    (docs/enlil.md, "In the loop"). Seed 0 is the demo's ground (layout 3), seed S layout
    3 + S.
    """
    demo = load_scenario(DEMO).model_dump(mode="json")
    return demo | {
        "name": f"demo-close-s{seed}",
        "layout": 3 + seed,
        "seed": seed,
        "duration": 8.0,
        "objects": demo["objects"][:1],
        "phenomena": [],
        "faults": [],
    }


def close_in_view(seed: int, t: float) -> bool:
    """Whether the close pedestrian of *seed* stands in the camera's field at time *t*."""
    d = close_distance(seed)
    walked = min(max(t - CLOSE_START, 0.0) * CLOSE_SPEED, 2 * CLOSE_HALF_PATH)
    y = -CLOSE_HALF_PATH + walked  # the side does not matter: the field is symmetric
    return abs(y) < d * math.tan(HALF_FOV) + PERSON_HALF_WIDTH


class Truth:
    """The true category of a context, measured on a fixed batch of test images."""

    def __init__(self, data: str, model_id: str, models: Path = MODELS) -> None:
        registry = load_registry(models)
        self.detector = registry.load(registry.get(model_id))
        self.batch = fixed_batch(data, "test", 32, seed=0)
        self.clean_f1 = float(evaluate_detector(self.detector, self.batch).f1)
        self.evaluations = 0

    def category(self, phenomena: list[tuple[str, dict[str, float]]]) -> int:
        """The category under the phenomena in force (clear weather: 0)."""
        if not phenomena:
            return 0
        (name, params), *rest = phenomena
        assert not rest, "one phenomenon per ramp"
        phen = PHENOMENA.create(name)
        unit = normalise(phen, phen.to_vector(params))
        self.evaluations += 1
        return evaluate_context(
            self.detector, self.batch, phen, unit, clean_f1=self.clean_f1, seed=0
        ).category

    def change_time(self, timeline: Any, start: float, end: float) -> float | None:
        """The first time in ``[start, end]`` the category is >= 1 (bisection), or ``None``."""
        if self.category(timeline.phenomena(end)) == 0:
            return None
        low, high = start, end  # category(low) is taken as 0 (the ramp starts at identity)
        while high - low > 0.1 / RATE:
            mid = (low + high) / 2
            if self.category(timeline.phenomena(mid)) >= 1:
                high = mid
            else:
                low = mid
        return high


def run_ramp(
    kind: str,
    seed: int,
    truth: Truth,
    *,
    clean: float,
    ramp: float,
    hold: float,
    window: int,
    models: Path = MODELS,
) -> dict[str, Any]:
    """One scripted ramp: the oracle's per-frame categories against the true change."""
    sc = scenario(kind, seed, clean, ramp, hold)
    said: dict[int, int] = {}
    times: dict[int, float] = {}
    lock = threading.Lock()

    def on_assessment(sample: Any) -> None:
        m = sample.message
        if isinstance(m, Assessment) and m.frame_seq is not None:
            with lock:
                said[m.frame_seq] = m.category

    def on_truth(sample: Any) -> None:
        body = body_of(sample.message)
        with lock:
            times[int(body["seq"])] = float(body.get("t", 0.0))

    with open_bus("inproc", executor=Executor()) as bus:  # one thread: every frame assessed
        bus.subscribe(topics.ORACLE_OUTPUT, on_assessment, queue=1024)
        bus.subscribe(topics.GROUND_TRUTH, on_truth, queue=1024)
        with SimulatedSystem(
            bus, sc, models=models, oracle={"name": "enlil", "window": window}
        ) as system:
            t0 = time.perf_counter()
            system.run(threading.Event(), speed=FAST)
            wall = time.perf_counter() - t0
            frames = system.platform.frames
            timeline = system.platform.timeline
    event = sc["phenomena"][0] if sc["phenomena"] else None
    start = math.inf if event is None else float(event["at"])  # close: every frame clean
    changed = None
    if event is not None:
        changed = truth.change_time(timeline, start, float(event["at"] + event["ramp"]))
    with lock:
        seqs = sorted(set(said) & set(times))
        clean_frames = [s for s in seqs if times[s] < start]
        alarms = [s for s in clean_frames if said[s] >= 1]
        first = next((s for s in seqs if times[s] >= start and said[s] >= 1), None)
        true_frame = None
        if changed is not None:
            true_frame = next((s for s in seqs if times[s] >= changed - 1e-9), None)
        in_view = [s for s in seqs if kind == "close" and close_in_view(seed, times[s])]
    delay = None if first is None or true_frame is None else first - true_frame
    out = {
        "ramp": kind,
        "seed": seed,
        "event": event,
        "frames": frames,
        "assessed": len(seqs),
        "wall_s": round(wall, 2),
        "true_change_s": None if changed is None else round(changed, 3),
        "true_change_frame": true_frame,
        "oracle_change_frame": first,
        "delay_frames": delay,
        "clean_frames": len(clean_frames),
        "false_alarms": len(alarms),
    }
    if kind in CLEAN:
        out["categories"] = [said[s] for s in seqs]
    if kind == "close":
        out |= {
            "distance_m": close_distance(seed),
            "in_view_frames": len(in_view),
            "false_alarms_in_view": sum(said[s] >= 1 for s in in_view),
        }
    return out


def loop_rate(name: str, seconds: float) -> dict[str, Any]:
    """The whole launch (Utu included) flat out for ``seconds`` of simulated time.

    The enlil launch runs without its live scorer: the oracle *in place of* ground truth.
    """
    launch = load_launch(LAUNCHES[name])
    assert isinstance(launch.managed, SimKind)
    launch.managed.options = launch.managed.options.model_copy(update={"scorer": None})
    out = io.StringIO()
    result = run_launch(launch, speed=FAST, until=seconds, out=out, handle_signals=False)
    line = next(x for x in out.getvalue().splitlines() if x.startswith("simulated "))
    frames = int(line.split("(")[1].split()[0])
    return {
        "launch": str(LAUNCHES[name].relative_to(ROOT)),
        "frames": frames,
        "run_s": round(result.ran, 2),
        "fps": round(frames / result.ran, 2),
    }


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Median delay, changes missed, false alarms per 1,000 clean frames."""
    delays = [r["delay_frames"] for r in runs if r["delay_frames"] is not None]
    ramps = [r for r in runs if r["event"] is not None]  # close runs have no change
    clean = sum(r["clean_frames"] for r in runs)
    alarms = sum(r["false_alarms"] for r in runs)
    out = {
        "runs": len(runs),
        "median_delay_frames": statistics.median(delays) if delays else None,
        "delays_frames": delays,
        "no_true_change": sum(r["true_change_frame"] is None for r in ramps),
        # a ramp whose end the detector copes with, yet the oracle called it degraded
        "alarms_without_true_change": sum(
            r["true_change_frame"] is None and r["oracle_change_frame"] is not None for r in ramps
        ),
        "missed": sum(
            r["true_change_frame"] is not None and r["oracle_change_frame"] is None for r in ramps
        ),
        "clean_frames": clean,
        "false_alarms": alarms,
        "false_alarms_per_1000": per_1000(alarms, clean),
    }
    close = [r for r in runs if r["ramp"] == "close"]
    if close:
        in_view = sum(r["in_view_frames"] for r in close)
        alarms_in_view = sum(r["false_alarms_in_view"] for r in close)
        out |= {
            "close_in_view_frames": in_view,
            "close_false_alarms_in_view": alarms_in_view,
            "close_false_alarms_per_1000_in_view": per_1000(alarms_in_view, in_view),
        }
    return out


def per_1000(count: int, frames: int) -> float | None:
    return round(1000.0 * count / frames, 2) if frames else None


def headline(runs: dict[str, list[dict[str, Any]]]) -> dict[str, Any]:
    """The issue's two figures: false alarms per 1,000 clean frames, onset delay per phenomenon.

    ``false_alarms``: over every clean frame (``with_close_pedestrians``), and without the
    ``close`` runs; ``onset_delay_frames``: per ramp (its phenomenon named), the delays
    (frames from the true change to the oracle's first category >= 1; negative: early),
    their median, min and max, and the ramps the oracle missed or the detector coped with.
    """
    every = [r for rs in runs.values() for r in rs]
    ramps = [r for r in every if r["ramp"] not in CLEAN]

    def alarms(rs: list[dict[str, Any]]) -> dict[str, Any]:
        clean, count = sum(r["clean_frames"] for r in rs), sum(r["false_alarms"] for r in rs)
        return {"clean_frames": clean, "false_alarms": count, "per_1000": per_1000(count, clean)}

    onset: dict[str, Any] = {}
    for kind, rs in runs.items():
        if kind in CLEAN:
            continue
        d = summarise(rs)
        delays = d["delays_frames"]
        onset[kind] = {
            "phenomenon": PHENOMENON[kind],
            "median": d["median_delay_frames"],
            "min": min(delays) if delays else None,
            "max": max(delays) if delays else None,
            "delays": delays,
            "missed": d["missed"],
            "no_true_change": d["no_true_change"],
        }
    return {
        "false_alarms": {
            "with_close_pedestrians": alarms(every),
            "without_close_pedestrians": alarms(ramps),
            "close_pedestrians_only": alarms([r for r in every if r["ramp"] in CLEAN]),
        },
        "onset_delay_frames": onset,
    }


def write(path: Path, results: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(results, indent=1) + "\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="data/rover", help="the rover dataset (its test split)")
    ap.add_argument("--seeds", type=int, help="seeds per case (10; --quick: 2)")
    ap.add_argument("--ramps", default=",".join(KINDS), help=f"cases ({','.join(KINDS)})")
    ap.add_argument("--clean", type=float, help="clear seconds before the ramp (10; quick: 5)")
    ap.add_argument("--ramp", type=float, help="fog and hsl ramp seconds (10; quick: 5)")
    ap.add_argument("--hold", type=float, default=3.0, help="seconds at the ramp's end")
    ap.add_argument("--window", type=int, default=3, help="the oracle's window (frames)")
    ap.add_argument("--loop-seconds", type=float, help="simulated s per loop run (20; quick: 10)")
    ap.add_argument("--quick", action="store_true", help="2 seeds, 5 s clean, 5 s ramps")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument(
        "--models",
        type=Path,
        default=MODELS,
        help="the model registry of the ramps (examples/models/rover.yaml; e.g. a copy, so "
        "that oracles re-pinned meanwhile do not change a run; the loop runs the examples')",
    )
    ap.add_argument("--output", type=Path, default=RESULTS)
    args = ap.parse_args()
    defaults = (2, 5.0, 5.0, 10.0) if args.quick else (10, 10.0, 10.0, 20.0)
    for name, value in zip(("seeds", "clean", "ramp", "loop_seconds"), defaults, strict=True):
        if getattr(args, name) is None:
            setattr(args, name, value)
    kinds = args.ramps.split(",")
    unknown = sorted(set(kinds) - set(KINDS))
    if unknown:
        ap.error(f"--ramps: unknown {', '.join(unknown)}; the cases are {', '.join(KINDS)}")
    torch.set_num_threads(args.threads)
    truth = Truth(args.data, "rover-default", args.models)
    results: dict[str, Any] = {
        "benchmark": "oracle_ramps",
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
        "machine": {
            "python": platform.python_version(),
            "cpus": os.cpu_count(),
            "torch_threads": torch.get_num_threads(),
            "load_average_before": list(os.getloadavg()),
        },
        "model": "rover-default",
        "oracle": oracle_file(args.models),
        "settings": {
            k: getattr(args, k) for k in ("seeds", "clean", "ramp", "hold", "window", "quick")
        },
        "clean_f1_test_batch": round(truth.clean_f1, 4),
        "aims": {"median_delay_frames": 3, "false_alarms_per_1000": 1, "loop_hz": 10},
        "ramps": {},
    }
    runs: dict[str, list[dict[str, Any]]] = {kind: [] for kind in kinds}
    for seed in range(args.seeds):  # seed-major: an interrupted run covers every ramp
        for kind in kinds:
            r = run_ramp(
                kind,
                seed,
                truth,
                clean=args.clean,
                ramp=args.ramp,
                hold=args.hold,
                window=args.window,
                models=args.models,
            )
            runs[kind].append(r)
            print(
                f"{kind:8s} seed {seed}: true change frame {r['true_change_frame']}, oracle "
                f"{r['oracle_change_frame']}, delay {r['delay_frames']}; false alarms "
                f"{r['false_alarms']}/{r['clean_frames']} ({r['wall_s']} s)",
                flush=True,
            )
            results["ramps"][kind] = {"summary": summarise(runs[kind]), "runs": runs[kind]}
            results["all"] = summarise([x for k in kinds for x in runs[k]])
            results |= headline(runs)
            write(args.output, results)  # after every run: an interrupted run keeps its figures
    results["truth_evaluations"] = truth.evaluations
    results["loop"] = {}
    for name in LAUNCHES:
        results["loop"][name] = loop_rate(name, args.loop_seconds)
        write(args.output, results)
    results["machine"]["load_average_after"] = list(os.getloadavg())
    write(args.output, results)
    a, onset = results["false_alarms"]["with_close_pedestrians"], results["onset_delay_frames"]
    delays = ", ".join(f"{k} {v['median']}" for k, v in onset.items())
    print(
        f"false alarms {a['per_1000']} per 1,000 clean frames, close pedestrians included "
        f"({a['false_alarms']}/{a['clean_frames']}; aim <= 1); median onset delay (frames): "
        f"{delays or '-'} (aim <= 3); loop {results['loop']['enlil']['fps']} Hz with enlil "
        f"(aim >= 10), {results['loop']['ground_truth']['fps']} Hz with ground truth; "
        f"wrote {args.output}"
    )


def oracle_file(models: Path = MODELS) -> dict[str, Any]:
    """The oracle the ramps assessed with: the registry's pin of rover-default's oracle."""
    ref = load_registry(models).get("rover-default").oracle
    if ref is None:
        return {}
    path = Path(ref.file).resolve()
    shown = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
    return {"file": str(shown), "sha256": ref.sha256}


if __name__ == "__main__":
    main()
