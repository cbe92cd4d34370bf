"""The case studies under three managers: Utu, none (no adaptation) and random.

As the self-adaptive exemplars do (SUAVE, ReBeT ship a *none* and a *random* manager beside
theirs), each case's demo launch is run with ``--manager utu|none|random`` over ``--seeds``
seeds; the seed draws the scenario again (its ``vary:`` section: phase timing, pedestrian
placement, condition strength; :func:`anunnaki.sim.draw_scenario`) and seeds the random
manager. Every run is flat out in simulated time (the simulator in lockstep with the
detector and both oracles), so the figures are in simulated seconds and frames. Per run,
measured from the run's public topics (``on_bus``), its decisions and its report:

* ``degraded_frames``: frames the rover drove autonomously with a model the ground-truth
  scorer (``/sim/oracle/scorer``, here over the last second: :data:`SCORER`) put in
  category >= 1 (the F1 drop over 5 %);
* ``pedestrian_misses``: frames in which a pedestrian stood within stopping distance in the
  rover's path (its ground-truth box is one the rover's stop rule stops for:
  :meth:`anunnaki.sim.StopRule.box_ahead`), the rover drove autonomously and the detector
  reported no pedestrian there (no detection box the stop rule stops for); they count only
  while autonomous, so a rover handed over or stopped early misses nothing, hence beside
  them ``autonomous_m`` (metres driven in autonomous mode) and
  ``misses_per_10_autonomous_m`` (misses per 10 of those metres; 0 when it drove none);
* ``collisions``: contacts with pedestrians or deer (the report's);
* ``distance_m``: how far the rover got along its route (its ``x`` on ``/rover/status`` at
  the end: a rover handed over, run-stopped or halted early is safe and gets nowhere), and
  ``final_mode``, its mode then (``autonomous``, ``manual``, ``stopped``);
* ``onset_delays``: per adverse phase of the scenario (phenomena starting together), the
  simulated seconds from its onset (the event's ``at``) to the first adaptation action in
  it that fits it (a swap of the detector's model to the domain for one of the phase's
  phenomena, :attr:`Case.fits`, or the fail-safe's mode change), or ``null`` when none came
  before the phase ended (a swap to another domain is no adaptation to the phase);
* ``false_alarms``: adaptation tactics started (swap to a robust model, fail-safe) while no
  adverse condition was in force nor had been in the last second;
* ``decisions``: tactics started (any);
* ``adaptations``: each adaptation tactic started, with the outcome of its postconditions
  (``ok``, ``failed``, or ``null`` when the run ended first).

The runs send no e-mail (the launch's ``notify`` section is dropped, so a fail-safe's e-mail
fails at once as not configured, recorded as a decision, its log lines kept off the output):
a benchmark must not mail whatever listens on the demo's port.

The summary gives per manager the mean, standard deviation, min and max over seeds, and the
onset delays' p95 over all phases of all seeds. A case is one entry of :data:`CASES`: a
launch file whose managed system is ``kind: sim``, whose scenario has a ``vary:`` section;
the UAV (examples/uav) joins with one entry. Writes ``benchmarks/results/case-studies.json``::

    .venv/bin/python benchmarks/case_studies.py                 # 10 seeds per manager
    .venv/bin/python benchmarks/case_studies.py --quick         # 1 seed, 14 s, a check
"""

from __future__ import annotations

import argparse
import dataclasses
import io
import json
import logging
import math
import os
import platform
import statistics
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from anunnaki import topics
from anunnaki.launch import load_launch, run_launch
from anunnaki.managed import SimKind
from anunnaki.messages import Assessment, Detections, body_of
from anunnaki.sim import StopRule, Timeline, draw_scenario, load_scenario

ROOT = Path(__file__).parents[1]
RESULTS = Path(__file__).parent / "results" / "case-studies.json"
MANAGERS = ("utu", "none", "random")
FAST = 0.0  # --speed 0: as fast as the lockstep allows
#: The live scorer of every run: the ground truth over the last second (10 frames), so that
#: a frame's category is that of the model that handled it, not of the last 3 s.
SCORER = {"name": "ground_truth", "window": 10, "min_frames": 5, "min_objects": 5}


@dataclass(frozen=True)
class Case:
    """One case study: its launch file and the tactics that count as adaptations."""

    launch: Path
    #: Tactic-name prefixes of the adaptations (onset delay, false alarms).
    adaptations: tuple[str, ...] = ("swap-to-", "fail-safe")
    #: The model domain that fits each phenomenon: a swap adapts to a phase only to a
    #: domain fitting one of its phenomena (a hand-over to a human fits any).
    fits: tuple[tuple[str, str], ...] = (
        ("hsl", "hsl"),
        ("fog", "fog"),
        ("raindrop", "raindrop"),
        ("brightness", "low_light"),
    )


CASES: dict[str, Case] = {
    "rover": Case(ROOT / "examples" / "rover" / "demo.yaml"),
}


@dataclass
class _Recorder:
    """What a run publishes, heard on its bus (public topics only)."""

    width: int
    height: int
    lock: threading.Lock = field(default_factory=threading.Lock)
    truth: dict[int, list[list[float]]] = field(default_factory=dict)  # seq -> pedestrian boxes
    ahead: dict[int, bool] = field(default_factory=dict)  # seq -> the detector saw one ahead
    scorer: dict[int, int] = field(default_factory=dict)  # seq -> ground-truth category
    mode: dict[int, str] = field(default_factory=dict)  # seq -> rover mode when detected
    current_mode: str = "autonomous"
    x: float = 0.0
    autonomous_m: float = 0.0  # metres driven in autonomous mode
    subs: list[Any] = field(default_factory=list)
    rule: StopRule = field(default_factory=StopRule)

    def attach(self, bus: Any) -> None:
        self.subs = [
            bus.subscribe(topics.GROUND_TRUTH, self._on_truth, queue=1024),
            bus.subscribe(topics.DETECTIONS, self._on_detections, queue=1024),
            bus.subscribe(topics.SCORER, self._on_scorer, queue=1024),
            bus.subscribe("/rover/status", self._on_status, queue=1024),
        ]

    def _box_ahead(self, box: list[float]) -> bool:
        return self.rule.box_ahead(box, self.width, self.height)

    def _on_truth(self, sample: Any) -> None:
        body = body_of(sample.message)
        boxes = [
            list(map(float, b))
            for b, label in zip(body.get("boxes") or [], body.get("labels") or [], strict=False)
            if label == "pedestrian"
        ]
        with self.lock:
            self.truth[int(body["seq"])] = [b for b in boxes if self._box_ahead(b)]

    def _on_detections(self, sample: Any) -> None:
        det = sample.message
        if not isinstance(det, Detections):
            return
        seen = any(
            label == "pedestrian" and score >= self.rule.min_score and self._box_ahead(box)
            for box, label, score in zip(det.boxes, det.labels, det.scores, strict=True)
        )
        with self.lock:
            self.ahead[det.frame_seq] = seen
            self.mode[det.frame_seq] = self.current_mode

    def _on_scorer(self, sample: Any) -> None:
        message = sample.message
        if isinstance(message, Assessment) and message.frame_seq is not None:
            with self.lock:
                self.scorer[message.frame_seq] = message.category

    def _on_status(self, sample: Any) -> None:
        body = body_of(sample.message)
        mode, x = body.get("mode"), body.get("x")
        with self.lock:
            if isinstance(mode, str):
                self.current_mode = mode
            if isinstance(x, int | float):
                if self.current_mode == "autonomous":
                    self.autonomous_m += max(0.0, float(x) - self.x)
                self.x = float(x)

    def close(self) -> None:
        for sub in self.subs:
            sub.close()

    def counts(self) -> dict[str, Any]:
        with self.lock:
            auto = {s for s, m in self.mode.items() if m == "autonomous"}
            degraded = sum(1 for s, c in self.scorer.items() if c >= 1 and s in auto)
            misses = sum(
                1 for s, boxes in self.truth.items() if boxes and s in auto and not self.ahead[s]
            )
            x, mode, auto_m = self.x, self.current_mode, self.autonomous_m
        return {
            "degraded_frames": degraded,
            "pedestrian_misses": misses,
            "autonomous_m": round(auto_m, 2),
            "misses_per_10_autonomous_m": round(10.0 * misses / auto_m, 3) if auto_m else 0.0,
            "distance_m": round(x, 2),
            "final_mode": mode,
        }


def _phases(scenario: Any) -> list[tuple[float, float, str]]:
    """The adverse phases: (onset, end, label) per group of events starting together."""
    starts = sorted({e.at for e in scenario.phenomena})
    out = []
    for at in starts:
        events = [e for e in scenario.phenomena if e.at == at]
        ends = [e.until if e.until is not None else scenario.duration for e in events]
        label = "+".join(sorted(e.phenomenon for e in events))
        out.append((at, min(max(ends), scenario.duration), label))
    return out


def run_once(case: Case, manager: str, seed: int, until: float | None) -> dict[str, Any]:
    """One run of ``case`` under ``manager`` with the scenario drawn from ``seed``."""
    launch = load_launch(case.launch)
    assert isinstance(launch.managed, SimKind), f"{case.launch}: not a 'managed: sim' launch"
    options = launch.managed.options.model_copy(
        update={"scenario_seed": seed, "report": False, "scorer": SCORER}
    )
    launch.managed.options = options
    launch = dataclasses.replace(launch, utu=launch.utu.model_copy(update={"notify": {}}))
    scenario = draw_scenario(load_scenario(options.scenario), seed)
    end = scenario.duration if until is None else min(until, scenario.duration)
    recorder = _Recorder(scenario.camera.width, scenario.camera.height)
    report_path = Path(os.environ.get("TMPDIR", "/tmp")) / f"case-{os.getpid()}-{seed}.json"
    launch.managed.with_reports(report=str(report_path), plot=None)
    t0 = time.perf_counter()
    try:
        result = run_launch(
            launch,
            speed=FAST,
            until=end,
            out=io.StringIO(),
            handle_signals=False,
            on_bus=recorder.attach,
            manager=manager,
            manager_seed=seed,
        )
    finally:
        recorder.close()
    wall = time.perf_counter() - t0
    report = json.loads(report_path.read_text(encoding="utf-8"))
    report_path.unlink(missing_ok=True)
    timeline = Timeline(scenario)
    adaptive = [
        d
        for d in result.decisions
        if d.kind == "action"
        and d.tactic is not None
        and d.tactic.startswith(case.adaptations)
        and d.data.get("type") in ("swap_model", "change_mode")
    ]
    started = [d for d in result.decisions if d.kind == "started" and d.tactic is not None]
    delays: list[dict[str, Any]] = []
    for onset, phase_end, label in _phases(scenario):
        if onset >= end:
            continue
        domains = {dict(case.fits).get(p) for p in label.split("+")}
        first = next(
            (
                d.t
                for d in adaptive
                if onset <= d.t < phase_end
                and (d.data.get("type") == "change_mode" or d.data.get("domain") in domains)
            ),
            None,
        )
        delays.append(
            {
                "onset": round(onset, 3),
                "phase": label,
                "delay_s": None if first is None else round(first - onset, 3),
            }
        )

    def calm(t: float) -> bool:
        return not any(timeline.phenomena(max(0.0, t - dt)) for dt in (0.0, 0.5, 1.0))

    alarms = [
        d
        for d in started
        if d.tactic is not None and d.tactic.startswith(case.adaptations) and calm(d.t)
    ]
    outcomes = {"postcondition_ok": "ok", "postcondition_failed": "failed"}
    adaptations = []
    for d in started:
        if d.tactic is None or not d.tactic.startswith(case.adaptations):
            continue
        ended = next(
            (
                e
                for e in result.decisions
                if e.tactic == d.tactic and e.t >= d.t and e.kind in outcomes
            ),
            None,
        )
        adaptations.append(
            {
                "tactic": d.tactic,
                "t": round(d.t, 3),
                "postcondition": None if ended is None else outcomes[ended.kind],
            }
        )
    return {
        "manager": manager,
        "seed": seed,
        "simulated_s": round(report["duration"], 3),
        "frames": len(report["frames"]),
        "wall_s": round(wall, 2),
        **recorder.counts(),
        "collisions": len(report["collisions"]),
        "onset_delays": delays,
        "false_alarms": len(alarms),
        "false_alarm_tactics": [f"{d.tactic}@{d.t:.1f}" for d in alarms],
        "decisions": len(started),
        "adaptations": adaptations,
        "tactics": [f"{d.tactic}@{d.t:.1f}" for d in started],
    }


def _spread(values: list[float]) -> dict[str, float | None]:
    if not values:
        return {"mean": None, "std": None, "min": None, "max": None}
    return {
        "mean": round(statistics.fmean(values), 3),
        "std": round(statistics.stdev(values), 3) if len(values) > 1 else 0.0,
        "min": round(min(values), 3),
        "max": round(max(values), 3),
    }


def _p95(values: list[float]) -> float | None:
    if not values:
        return None
    ordered = sorted(values)
    return round(ordered[min(len(ordered) - 1, math.ceil(0.95 * len(ordered)) - 1)], 3)


MEASURES = (
    "degraded_frames",
    "pedestrian_misses",
    "misses_per_10_autonomous_m",
    "autonomous_m",
    "collisions",
    "distance_m",
    "false_alarms",
    "decisions",
)


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Mean and spread per measure, onset delays pooled over phases and seeds."""
    out: dict[str, Any] = {m: _spread([float(r[m]) for r in runs]) for m in MEASURES}
    delays = [p["delay_s"] for r in runs for p in r["onset_delays"]]
    known = [float(d) for d in delays if d is not None]
    out["onset_delay_s"] = {**_spread(known), "p95": _p95(known)}
    out["phases_without_adaptation"] = sum(1 for d in delays if d is None)
    out["phases"] = len(delays)
    return out


def table(summary: dict[str, dict[str, Any]]) -> str:
    """The managers side by side (mean ± std [min–max])."""

    def cell(s: dict[str, Any]) -> str:
        if s["mean"] is None:
            return "–"
        return f"{s['mean']:.2f} ± {s['std']:.2f} [{s['min']:g}–{s['max']:g}]"

    rows = [f"{'measure':<22} " + " ".join(f"{m:<30}" for m in summary)]
    for measure in (*MEASURES, "onset_delay_s"):
        rows.append(
            f"{measure:<22} " + " ".join(f"{cell(s[measure]):<30}" for s in summary.values())
        )
    rows.append(
        f"{'onset delay p95 (s)':<22} "
        + " ".join(f"{s['onset_delay_s']['p95']!s:<30}" for s in summary.values())
    )
    rows.append(
        f"{'phases not adapted':<22} "
        + " ".join(f"{s['phases_without_adaptation']}/{s['phases']:<28}" for s in summary.values())
    )
    return "\n".join(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated (default: all)")
    ap.add_argument("--managers", default=",".join(MANAGERS), help="comma-separated")
    ap.add_argument("--seeds", type=int, help="seeds per manager (10; quick: 1)")
    ap.add_argument("--until", type=float, help="simulated seconds per run (the scenario's)")
    ap.add_argument("--quick", action="store_true", help="1 seed, 14 simulated seconds")
    ap.add_argument("--output", type=Path, default=RESULTS)
    args = ap.parse_args()
    seeds = args.seeds if args.seeds is not None else (1 if args.quick else 10)
    until = args.until if args.until is not None else (14.0 if args.quick else None)
    logging.getLogger("anunnaki.utu.notify").setLevel(logging.CRITICAL)
    managers = [m for m in args.managers.split(",") if m]
    doc: dict[str, Any] = {
        "benchmark": "case_studies",
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
        "machine": {
            "python": platform.python_version(),
            "cpus": os.cpu_count(),
            "load_average_before": list(os.getloadavg()),
        },
        "settings": {"seeds": seeds, "until": until, "quick": args.quick, "managers": managers},
        "cases": {},
    }
    for name in (c for c in args.cases.split(",") if c):
        case = CASES[name]
        runs = []
        for manager in managers:
            for seed in range(seeds):
                run = run_once(case, manager, seed, until)
                runs.append(run)
                print(
                    f"{name} {manager:<6} seed {seed}: {run['frames']} frames in "
                    f"{run['wall_s']:.0f} s; degraded {run['degraded_frames']}, missed "
                    f"{run['pedestrian_misses']}, collisions {run['collisions']}, "
                    f"{run['distance_m']:.1f} m ({run['final_mode']}), delays "
                    f"{[p['delay_s'] for p in run['onset_delays']]}, false alarms "
                    f"{run['false_alarms']}, decisions {run['decisions']}",
                    flush=True,
                )
        summary = {m: summarise([r for r in runs if r["manager"] == m]) for m in managers}
        doc["cases"][name] = {
            "launch": str(case.launch.relative_to(ROOT)),
            "summary": summary,
            "runs": runs,
        }
        print(f"\n{name}:\n{table(summary)}\n")
    doc["machine"]["load_average_after"] = list(os.getloadavg())
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
