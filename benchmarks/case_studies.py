"""The case studies under three managers: Utu, none (no adaptation) and random.

As the self-adaptive exemplars do (SUAVE, ReBeT ship a *none* and a *random* manager beside
theirs), each case's demo launch is run with ``--manager utu|none|random`` over ``--seeds``
seeds; the seed draws the scenario again (its ``vary:`` section: phase timing, pedestrian
placement, condition strength; :func:`anunnaki.sim.draw_scenario`) and seeds the random
manager. Every run is flat out in simulated time (one deterministic program on the run's
executor: :mod:`anunnaki.bus`), so the figures are in simulated seconds and frames. Per run,
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
  before the phase ended (a swap to another domain is no adaptation to the phase); beside
  it, ``degraded_at``, the first frame in the phase on which the ground-truth scorer found
  the *active* model degraded (category >= 1), and ``after_degraded_s``, the seconds from
  that frame to the adaptation (0 when the adaptation came first; ``null`` when none came):
  a condition ramps in, and the model in use may cope with its start (the UAV's rain model
  with thin fog), so the onset delay counts time in which nothing needed doing;
* ``false_alarms``: adaptation tactics started (swap to a robust model, fail-safe) while no
  adverse condition was in force nor had been in the last second;
* ``decisions``: tactics started (any);
* ``adaptations``: each adaptation tactic started, with the outcome of its postconditions
  (``ok``, ``failed``, or ``null`` when the run ended first).

The UAV (examples/uav/sim.yaml, ``platform: uav`` in :data:`CASES`) is measured on its
mission instead of pedestrians, from ``/uav/status``; its run ends at the touch-down after
its flight (nothing of the mission changes after it), or at the scenario's end:

* ``delivered``: 1 when the package was dropped at the delivery point (``delivered``);
* ``landing``: where the flight ended: ``home`` (within 1 m of it), ``elsewhere``,
  ``forced`` (the empty battery forced it down: phase ``forced landing``), ``airborne`` at
  the end, or ``ground`` (never took off); ``landed_home`` is 1 for ``home``;
* ``battery_at_landing``: % at the touch-down (at the end, still airborne);
  ``mission_time_s``: the touch-down's simulated time (``null`` while airborne);
* ``low_battery_s``: simulated seconds airborne below 20 % (obstacle O2 holding);
* ``degraded_frames``: frames the UAV flew on its detector (airborne in ``auto`` or
  ``return_home``) with a model in category >= 1 by the ground-truth scorer;
* onset delays, false alarms, decisions and adaptations as for the rover, with the UAV's
  tactics (:data:`CASES`): adaptations are the swaps, ``failsafe-f1``, ``return-home``,
  ``hold-route`` and ``link-lost``; a mode change adapts to a camera phase only from
  ``failsafe-f1``; an adverse condition is a phenomenon or a fault in force (a sensor off
  its nominal rate, the link down, the battery's extra drain).

The runs send no e-mail (the launch's ``notify`` section is dropped, so a
fail-safe's e-mail fails at once as not configured, recorded as a decision, its log lines
kept off the output): a benchmark must not mail whatever listens on the demo's port.

The summary gives per manager the mean, standard deviation, min and max over seeds, and the
onset delays' p95 over all phases of all seeds (and the delays after degradation's). A case
is one entry of :data:`CASES`: a launch file whose managed system is ``kind: sim``, whose
scenario has a ``vary:`` section;
the UAV (examples/uav) is the second. Writes ``benchmarks/results/case-studies.json``::

    .venv/bin/python benchmarks/case_studies.py                 # 10 seeds per manager
    .venv/bin/python benchmarks/case_studies.py --quick         # 1 seed: 14 s; a short UAV flight
    .venv/bin/python benchmarks/case_studies.py --cases uav --managers utu --merge

``--merge`` writes into the file (under a lock) after each run: its other cases stay, and
within a case the runs of the (manager, seed) pairs not run again (so managers and seeds,
``--first-seed``, can run in processes of their own, and an interrupted comparison keeps
what it measured); the case's summary is computed again. Each case records its own
``settings`` (seeds, simulated seconds, scenario, managers, date, load average).
"""

from __future__ import annotations

import argparse
import bisect
import dataclasses
import fcntl
import io
import json
import logging
import math
import os
import platform
import statistics
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from anunnaki import topics
from anunnaki.launch import Launch, load_launch, run_launch
from anunnaki.managed import SimKind
from anunnaki.messages import Assessment, Detections, body_of
from anunnaki.sim import Scenario, StopRule, Timeline, draw_scenario, load_scenario

ROOT = Path(__file__).parents[1]
RESULTS = Path(__file__).parent / "results" / "case-studies.json"
MANAGERS = ("utu", "none", "random")
FAST = 0.0  # --speed 0: as fast as the work allows
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
    #: Tactic-name prefixes whose mode change adapts to any adverse phase (the fail-safe).
    failsafe: tuple[str, ...] = ("fail-safe",)
    #: The platform: which recorder hears the run and which measures it gets.
    platform: str = "rover"
    #: ``--quick``: simulated seconds per run (``None``: the whole scenario), and fields of
    #: the scenario replaced (a shorter mission; the drawn ``vary`` is dropped with it).
    quick_until: float | None = 14.0
    quick: dict[str, Any] = field(default_factory=dict)


CASES: dict[str, Case] = {
    "rover": Case(ROOT / "examples" / "rover" / "demo.yaml"),
    "uav": Case(
        ROOT / "examples" / "uav" / "sim.yaml",
        adaptations=("swap-to-", "failsafe-", "return-home", "hold-route", "link-lost"),
        fits=(("fog", "fog"), ("rain", "rain_brightness"), ("brightness", "rain_brightness")),
        failsafe=("failsafe-",),
        platform="uav",
        quick_until=None,
        # 26 s at most from the ground: climb at 10 m/s to 30 m (3 s), out east over 24 and
        # 48 m at 8 m/s; fog from 3 s; the battery (36 %) drains 1.5 %/s more from 2 s, below
        # G11's 30 % at about 5 s, when the UAV is 16 m out: home from there lands with about
        # 20 %, while the delivery (at 9-14 s) and the 48 m back empty it before home
        quick={
            "duration": 26,
            "mission": {
                "home": [0, 0],
                "waypoints": [[24, 0]],
                "delivery": [48, 0],
                "cruise_altitude": 30,
                "speed": 8,
                "climb_rate": 10,
                "battery": 36,
            },
            "phenomena": [{"at": 3, "phenomenon": "fog", "strength": 0.7, "ramp": 1}],
            "faults": [{"at": 2, "fault": "battery_drain", "rate": 1.5}],
            "vary": None,
        },
    ),
}
#: The UAV under the paper's power goal G11 (examples/uav/goals-g11.yaml), before the
#: anticipatory G15 (docs/uav.md, "Power"): the same case with that launch.
CASES["uav-g11"] = dataclasses.replace(
    CASES["uav"], launch=ROOT / "examples" / "uav" / "sim-g11.yaml"
)
#: The UAV's power obstacle O2 (examples/uav/goals.yaml): the battery below 20 %.
UAV_LOW_BATTERY = 20.0


@dataclass(kw_only=True)
class _Heard:
    """What both recorders keep: each frame's simulated time and ground-truth category, the
    statuses in order (all under ``lock``, which guards the subclasses' fields too), and
    their subscriptions.

    Everything is heard *in the publisher's thread* (pull subscribers drained by their
    ``on_ready``, as Utu hears its inputs), and a frame's mode is the one of the last status
    at or before the frame's simulated time. Before, callbacks on the bus's dispatcher
    threads attributed a frame to whatever status the status thread had reached, which a
    loaded machine put behind (the same seed counted 39 and 56 degraded frames), and the
    run's last messages could still be queued when it ended.
    """

    lock: threading.Lock = field(default_factory=threading.Lock)
    scorer: dict[int, int] = field(default_factory=dict)  # seq -> ground-truth category
    times: dict[int, float] = field(default_factory=dict)  # seq -> simulated time
    statuses: list[dict[str, Any]] = field(default_factory=list)  # in order of their "t"
    status_t: list[float] = field(default_factory=list)  # their "t"
    subs: list[Any] = field(default_factory=list)

    def _hear(self, bus: Any, topic: str, handle: Callable[[Any], None]) -> None:
        """Hear ``topic`` in its publisher's thread, every message in order."""
        box: list[Any] = []
        order = threading.Lock()  # one drain at a time: messages handled in their order

        def drain() -> None:
            with order:
                while box and (sample := box[0].try_recv()) is not None:
                    handle(sample)

        box.append(bus.subscribe(topic, queue=1024, on_ready=drain))
        self.subs.append(box[0])

    def _hear_frames(self, bus: Any, status: str) -> None:
        """The subscriptions both recorders make: the scorer, each frame's time, the status."""
        self._hear(bus, topics.SCORER, self._on_scorer)
        self._hear(bus, topics.PHENOMENA, self._on_frame)
        self._hear(bus, status, self._on_status)

    def _on_scorer(self, sample: Any) -> None:
        message = sample.message
        if isinstance(message, Assessment) and message.frame_seq is not None:
            with self.lock:
                self.scorer[message.frame_seq] = message.category

    def _on_frame(self, sample: Any) -> None:
        body = body_of(sample.message)
        with self.lock:
            self.times[int(body["seq"])] = float(body["t"])

    def _on_status(self, sample: Any) -> None:
        with self.lock:
            self._keep_status(body_of(sample.message))

    def _keep_status(self, body: dict[str, Any]) -> None:
        self.statuses.append(body)
        self.status_t.append(float(body["t"]))

    def status_at(self, seq: int) -> dict[str, Any]:
        """The last status at or before frame ``seq``'s time (``{}``: none yet); under lock."""
        t = self.times.get(seq)
        k = 0 if t is None else bisect.bisect_right(self.status_t, t)
        return self.statuses[k - 1] if k else {}

    def degraded_times(self) -> list[float]:
        """Simulated times of the frames the scorer put in category >= 1, in order."""
        with self.lock:
            return sorted(
                self.times[s] for s, c in self.scorer.items() if c >= 1 and s in self.times
            )

    def close(self) -> None:
        for sub in self.subs:
            sub.close()


@dataclass
class _Recorder(_Heard):
    """What a run publishes, heard on its bus (public topics only)."""

    width: int
    height: int
    truth: dict[int, list[list[float]]] = field(default_factory=dict)  # seq -> pedestrian boxes
    ahead: dict[int, bool] = field(default_factory=dict)  # seq -> the detector saw one ahead
    rule: StopRule = field(default_factory=StopRule)

    def attach(self, bus: Any) -> None:
        self._hear(bus, topics.GROUND_TRUTH, self._on_truth)
        self._hear(bus, topics.DETECTIONS, self._on_detections)
        self._hear_frames(bus, "/rover/status")

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

    def counts(self) -> dict[str, Any]:
        with self.lock:
            auto = {
                s for s in self.ahead if self.status_at(s).get("mode", "autonomous") == "autonomous"
            }
            degraded = sum(1 for s, c in self.scorer.items() if c >= 1 and s in auto)
            misses = sum(
                1 for s, boxes in self.truth.items() if boxes and s in auto and not self.ahead[s]
            )
            x, mode, auto_m = 0.0, "autonomous", 0.0
            for status in self.statuses:  # metres driven while autonomous, status by status
                mode = str(status.get("mode", mode))
                if mode == "autonomous":
                    auto_m += max(0.0, float(status["x"]) - x)
                x = float(status["x"])
        return {
            "degraded_frames": degraded,
            "pedestrian_misses": misses,
            "autonomous_m": round(auto_m, 2),
            "misses_per_10_autonomous_m": round(10.0 * misses / auto_m, 3) if auto_m else 0.0,
            "distance_m": round(x, 2),
            "final_mode": mode,
        }


@dataclass
class _UavRecorder(_Heard):
    """What a UAV run publishes, heard on its bus: its frames' categories and its battery.

    A frame counts as handled by the detector while the UAV flies on it (airborne in
    ``auto`` or ``return_home`` at the frame's time; hovering or landing it waits). The
    seconds airborne below O2's 20 % are read from ``/uav/status``; the mission's outcome
    (delivered, where and with what battery it landed) from the run's report
    (:func:`mission_outcome`).
    """

    detected: set[int] = field(default_factory=set)  # frames the detector handled
    low_battery_s: float = 0.0

    def attach(self, bus: Any) -> None:
        self._hear(bus, topics.DETECTIONS, self._on_detections)
        self._hear_frames(bus, "/uav/status")

    def _on_detections(self, sample: Any) -> None:
        det = sample.message
        if isinstance(det, Detections):
            with self.lock:
                self.detected.add(det.frame_seq)

    def _on_status(self, sample: Any) -> None:
        body = body_of(sample.message)
        t = float(body["t"])
        with self.lock:
            last = self.statuses[-1] if self.statuses else {}
            if last and float(last["altitude"]) > 0.05 and float(last["battery"]) < UAV_LOW_BATTERY:
                self.low_battery_s += max(0.0, t - float(last["t"]))
            self._keep_status(body)

    def _flying(self, seq: int) -> bool:
        s = self.status_at(seq)
        return float(s.get("altitude", 0.0)) > 0.05 and s.get("mode") in ("auto", "return_home")

    def counts(self) -> dict[str, Any]:
        with self.lock:
            degraded = sum(
                1
                for s, c in self.scorer.items()
                if c >= 1 and s in self.detected and self._flying(s)
            )
            low = self.low_battery_s
        return {"degraded_frames": degraded, "low_battery_s": round(low, 2)}


def mission_outcome(flight: dict[str, Any]) -> dict[str, Any]:
    """A UAV run's outcome from its report's ``flight`` (``anunnaki run --report``)."""
    landing = str(flight["landing"])
    battery = flight["battery_at_landing"]
    return {
        "delivered": int(bool(flight["delivered"])),
        "landing": landing,
        "landed_home": int(landing == "home"),
        "forced_landing": int(landing == "forced"),
        "landed_xy": flight["landed_xy"],
        "battery_at_landing": round(float(flight["battery"] if battery is None else battery), 2),
        "mission_time_s": None if flight["landed"] is None else round(float(flight["landed"]), 2),
    }


def _adverse(scenario: Any, timeline: Timeline, t: float) -> bool:
    """A condition in force at ``t``: a phenomenon or a fault (a rate off the nominal one)."""
    if timeline.phenomena(t):
        return True
    nominal = {
        "camera": scenario.camera.rate,
        "ultrasonic": scenario.ultrasonic.rate,
        "gps": scenario.mission.gps_rate,
        "battery": scenario.mission.battery_rate,
    }
    return any(
        f["fault"] != "rate" or f["rate"] != nominal.get(f.get("sensor", ""))
        for f in timeline.faults(t)
    )


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


def _sim_launch(case: Case) -> tuple[Launch, SimKind]:
    """The case's launch and its simulated system."""
    launch = load_launch(case.launch)
    managed = launch.managed
    assert isinstance(managed, SimKind), f"{case.launch}: not a 'managed: sim' launch"
    return launch, managed


def run_once(
    case: Case,
    manager: str,
    seed: int,
    until: float | None,
    scenario_file: Path | None = None,
    *,
    measure: Callable[[dict[str, Any], Any, Any], dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """One run of ``case`` under ``manager`` with the scenario drawn from ``seed``.

    ``scenario_file`` replaces the launch's scenario (the quick mode's shortened one). A UAV
    run ends at the touch-down after its flight (or at ``until``, the scenario's end).
    ``measure(report, scenario, result)``, when given, adds its measures to the run's (the
    report is the run's ``sim-report/1`` JSON, the scenario the drawn one, the result the
    launch's, with its decisions).
    """
    launch, managed = _sim_launch(case)  # managed: the same object in the launch replaced below
    update: dict[str, Any] = {"report": False, "scorer": SCORER}
    if scenario_file is not None:
        update["scenario"] = str(scenario_file)
    managed.options = managed.options.model_copy(update=update)
    # the seed's draw and the end at the touch-down, as `anunnaki run --seed N --until-landed`
    managed.with_scenario(seed=seed, until_landed=case.platform == "uav")
    options = managed.options
    utu = launch.utu.model_copy(update={"notify": {}})
    launch = dataclasses.replace(launch, utu=utu)
    scenario = draw_scenario(load_scenario(options.scenario), seed)
    end = scenario.duration if until is None else min(until, scenario.duration)
    recorder: _Recorder | _UavRecorder
    if case.platform == "uav":
        recorder = _UavRecorder()
    else:
        recorder = _Recorder(scenario.camera.width, scenario.camera.height)
    report_path = Path(os.environ.get("TMPDIR", "/tmp")) / f"case-{os.getpid()}-{seed}.json"
    managed.with_reports(report=str(report_path), plot=None)
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
    adaptive = [  # (t, tactic, data) of the adaptation actions
        (d.t, d.tactic, d.data)
        for d in result.decisions
        if d.kind == "action"
        and d.tactic is not None
        and d.tactic.startswith(case.adaptations)
        and d.data.get("type") in ("swap_model", "change_mode")
    ]
    started = [d for d in result.decisions if d.kind == "started" and d.tactic is not None]
    degraded_at = recorder.degraded_times()
    delays: list[dict[str, Any]] = []
    for onset, phase_end, label in _phases(scenario):
        if onset >= end:
            continue
        domains = {dict(case.fits).get(p) for p in label.split("+")}
        first = next(
            (
                t
                for t, tactic, data in adaptive
                if onset <= t < phase_end
                and (
                    (data.get("type") == "change_mode" and tactic.startswith(case.failsafe))
                    or data.get("domain") in domains
                )
            ),
            None,
        )
        # the first frame in the phase the ground truth found the active model degraded on
        hurt = next((t for t in degraded_at if onset <= t < phase_end), None)
        after: float | None = None
        if first is not None:
            after = 0.0 if hurt is None or hurt > first else round(first - hurt, 3)
        delays.append(
            {
                "onset": round(onset, 3),
                "phase": label,
                "delay_s": None if first is None else round(first - onset, 3),
                "degraded_at": None if hurt is None else round(hurt, 3),
                "after_degraded_s": after,
            }
        )

    def calm(t: float) -> bool:
        return not any(_adverse(scenario, timeline, max(0.0, t - dt)) for dt in (0.0, 0.5, 1.0))

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
        **(mission_outcome(report["flight"]) if case.platform == "uav" else {}),
        **({"collisions": len(report["collisions"])} if case.platform == "rover" else {}),
        "onset_delays": delays,
        "false_alarms": len(alarms),
        "false_alarm_tactics": [f"{d.tactic}@{d.t:.1f}" for d in alarms],
        "decisions": len(started),
        "adaptations": adaptations,
        "tactics": [f"{d.tactic}@{d.t:.1f}" for d in started],
        **(measure(report, scenario, result) if measure is not None else {}),
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
#: The UAV's measures: the mission's outcome first (``mission_time_s`` over the runs that
#: landed), then the common ones.
UAV_MEASURES = (
    "delivered",
    "landed_home",
    "forced_landing",
    "battery_at_landing",
    "mission_time_s",
    "low_battery_s",
    "degraded_frames",
    "false_alarms",
    "decisions",
)


def measures_of(case: Case) -> tuple[str, ...]:
    """The measures summarised for ``case``'s platform."""
    return UAV_MEASURES if case.platform == "uav" else MEASURES


def summarise(runs: list[dict[str, Any]], measures: tuple[str, ...] = MEASURES) -> dict[str, Any]:
    """Mean and spread per measure, onset delays pooled over phases and seeds."""
    out: dict[str, Any] = {
        m: _spread([float(r[m]) for r in runs if r.get(m) is not None]) for m in measures
    }
    delays = [p["delay_s"] for r in runs for p in r["onset_delays"]]
    known = [float(d) for d in delays if d is not None]
    out["onset_delay_s"] = {**_spread(known), "p95": _p95(known)}
    after = [
        float(p["after_degraded_s"])
        for r in runs
        for p in r["onset_delays"]
        if p.get("after_degraded_s") is not None
    ]
    out["after_degraded_s"] = {**_spread(after), "p95": _p95(after)}
    out["phases_without_adaptation"] = sum(1 for d in delays if d is None)
    out["phases"] = len(delays)
    if "landing" in (runs[0] if runs else {}):
        landings = [r["landing"] for r in runs]
        out["landings"] = ", ".join(f"{w} ×{landings.count(w)}" for w in sorted(set(landings)))
    return out


def table(summary: dict[str, dict[str, Any]], measures: tuple[str, ...] = MEASURES) -> str:
    """The managers side by side (mean ± std [min–max])."""

    def cell(s: dict[str, Any]) -> str:
        if s["mean"] is None:
            return "–"
        return f"{s['mean']:.2f} ± {s['std']:.2f} [{s['min']:g}–{s['max']:g}]"

    rows = [f"{'measure':<22} " + " ".join(f"{m:<30}" for m in summary)]
    for measure in (*measures, "onset_delay_s", "after_degraded_s"):
        rows.append(
            f"{measure:<22} " + " ".join(f"{cell(s[measure]):<30}" for s in summary.values())
        )
    rows.append(
        f"{'onset delay p95 (s)':<22} "
        + " ".join(f"{s['onset_delay_s']['p95']!s:<30}" for s in summary.values())
    )
    rows.append(
        f"{'after degraded p95 (s)':<22} "
        + " ".join(f"{s['after_degraded_s']['p95']!s:<30}" for s in summary.values())
    )
    rows.append(
        f"{'phases not adapted':<22} "
        + " ".join(f"{s['phases_without_adaptation']}/{s['phases']:<28}" for s in summary.values())
    )
    if all("landings" in s for s in summary.values()):
        rows.append(
            f"{'landings':<22} " + " ".join(f"{s['landings']:<30}" for s in summary.values())
        )
    return "\n".join(rows)


def quick_scenario(case: Case, folder: Path) -> Path | None:
    """``case``'s scenario with its ``quick`` fields replaced, written in ``folder``."""
    if not case.quick:
        return None
    _, managed = _sim_launch(case)
    base = load_scenario(managed.options.scenario).model_dump(mode="json")
    scenario = Scenario.model_validate({**base, **case.quick})
    path = folder / f"{case.launch.parent.name}-quick.yaml"
    path.write_text(json.dumps(scenario.model_dump(mode="json"), indent=1), encoding="utf-8")
    return path


def _order(run: dict[str, Any]) -> tuple[int, int]:
    return (MANAGERS.index(run["manager"]), int(run["seed"]))


def write(doc: dict[str, Any], path: Path, *, merge: bool) -> None:
    """Write ``doc`` to ``path``; with ``merge``, into what the file holds (under a lock).

    Merging keeps the file's other cases and, within a case, the runs of the (manager, seed)
    pairs this run did not run (so managers and seeds can run in separate processes); the
    case's summary is computed again over its runs.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a+", encoding="utf-8") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        f.seek(0)
        text = f.read()
        if merge and text.strip():
            old = json.loads(text)
            for name, case in doc["cases"].items():
                before = old.get("cases", {}).get(name)
                if before is not None:
                    ran = {_order(r) for r in case["runs"]}
                    runs = [r for r in before["runs"] if _order(r) not in ran] + case["runs"]
                    runs.sort(key=_order)
                    managers = [m for m in MANAGERS if any(r["manager"] == m for r in runs)]
                    seeds = max(sum(r["manager"] == m for r in runs) for m in managers)
                    case["runs"] = runs
                    case["settings"] = {**case["settings"], "managers": managers, "seeds": seeds}
                    measures = measures_of(CASES[name])
                    case["summary"] = {
                        m: summarise([r for r in runs if r["manager"] == m], measures)
                        for m in managers
                    }
                old.setdefault("cases", {})[name] = case
            doc = old
        f.seek(0)
        f.truncate()
        f.write(json.dumps(doc, indent=1) + "\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated (default: all)")
    ap.add_argument("--managers", default=",".join(MANAGERS), help="comma-separated")
    ap.add_argument("--seeds", type=int, help="seeds per manager (10; quick: 1)")
    ap.add_argument("--first-seed", type=int, default=0, help="seeds from this one (0)")
    ap.add_argument("--until", type=float, help="simulated seconds per run (the scenario's)")
    ap.add_argument(
        "--quick", action="store_true", help="1 seed; the rover's first 14 s, a short UAV mission"
    )
    ap.add_argument("--output", type=Path, default=RESULTS)
    ap.add_argument(
        "--merge",
        action="store_true",
        help="write into the output file: keep its other cases and other managers' runs",
    )
    args = ap.parse_args()
    seeds = args.seeds if args.seeds is not None else (1 if args.quick else 10)
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
        "settings": {
            "seeds": seeds,
            "until": args.until,
            "quick": args.quick,
            "managers": managers,
        },
        "cases": {},
    }
    with tempfile.TemporaryDirectory(prefix="case-studies-") as tmp:
        for name in (c for c in args.cases.split(",") if c):

            def save(entry: dict[str, Any], name: str = name) -> None:
                write({**doc, "cases": {name: entry}}, args.output, merge=True)

            doc["cases"][name] = run_case(
                CASES[name], name, args, managers, seeds, Path(tmp), save if args.merge else None
            )
    doc["machine"]["load_average_after"] = list(os.getloadavg())
    write(doc, args.output, merge=args.merge)
    print(f"wrote {args.output}")


def run_case(
    case: Case,
    name: str,
    args: argparse.Namespace,
    managers: list[str],
    seeds: int,
    tmp: Path,
    save: Callable[[dict[str, Any]], None] | None = None,
) -> dict[str, Any]:
    """``case`` under each manager over ``seeds`` seeds: its entry of the JSON's ``cases``.

    ``save`` is called with the entry so far after each run (``--merge``: an interrupted
    comparison keeps the runs it made).
    """
    until = args.until if args.until is not None else (case.quick_until if args.quick else None)
    scenario_file = quick_scenario(case, tmp) if args.quick else None
    load_before = list(os.getloadavg())
    measures = measures_of(case)
    runs: list[dict[str, Any]] = []

    def entry() -> dict[str, Any]:
        ran = [m for m in managers if any(r["manager"] == m for r in runs)]
        return {
            "launch": str(case.launch.relative_to(ROOT)),
            "summary": {
                m: summarise([r for r in runs if r["manager"] == m], measures) for m in ran
            },
            "runs": list(runs),
            "settings": {
                "seeds": seeds,
                "until": until,
                "scenario": "quick" if scenario_file is not None else "the launch's",
                "managers": ran,
                "date": time.strftime("%Y-%m-%d %H:%M:%S"),
                "load_average": [load_before, list(os.getloadavg())],
            },
        }

    for manager in managers:
        for seed in range(args.first_seed, args.first_seed + seeds):
            run = run_once(case, manager, seed, until, scenario_file)
            runs.append(run)
            print(f"{name} {manager:<6} seed {seed}: {_line(run)}", flush=True)
            if save is not None:
                save(entry())
    done = entry()
    print(f"\n{name}:\n{table(done['summary'], measures)}\n")
    return done


def _line(run: dict[str, Any]) -> str:
    """One run's figures in a line."""
    delays = [p["delay_s"] for p in run["onset_delays"]]
    common = f"delays {delays}, false alarms {run['false_alarms']}, decisions {run['decisions']}"
    if "landing" in run:
        return (
            f"{run['frames']} frames in {run['wall_s']:.0f} s; delivered {run['delivered']}, "
            f"landing {run['landing']} at {run['mission_time_s']} s with "
            f"{run['battery_at_landing']:.1f} %, {run['low_battery_s']:.1f} s below "
            f"{UAV_LOW_BATTERY:g} %, degraded {run['degraded_frames']}, {common}"
        )
    return (
        f"{run['frames']} frames in {run['wall_s']:.0f} s; degraded {run['degraded_frames']}, "
        f"missed {run['pedestrian_misses']}, collisions {run['collisions']}, "
        f"{run['distance_m']:.1f} m ({run['final_mode']}), {common}"
    )


if __name__ == "__main__":
    main()
