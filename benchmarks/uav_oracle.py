"""The UAV demo's oracle against its live ground-truth scorer: per phase, per model, and why.

Issue 34, item 8: in ``make demo-uav`` (``examples/uav/sim.yaml``) the learned ``enlil``
oracle agreed with its live scorer on 68.3 % of 690 frames (the rover's: 94.8-99.4 %). This
script runs the demo once, flat out in simulated time, hearing its public topics
(``on_bus``): each frame's time, the camera frame and the same frame as rendered before the
scenario's phenomena (``/sim/camera/clean``, published because the demo's scorer compares
the two), the ground truth, the detector's detections and model, the oracle's assessment
(category, probabilities, predicted drop), the live scorer's, and ``/uav/status``. Then,
offline, every model of the registry detects on every frame, perturbed and clean, and each
frame gets the categories of the model that handled it:

* ``oracle``: what the enlil oracle said (Utu acts on it);
* ``scorer``: what the live scorer said, as the launch configures it (since issue 34:
  ``reference: paired``, the model's F1 over the window against its F1 on the same frames
  rendered clean, and ``sparse: withhold``, no category for a window with too few objects);
* ``before``: the scorer as shipped before issue 34, replayed from the run with a fresh
  :class:`~anunnaki.oracles.GroundTruthAssessor` (``reference: clean_f1``: the window's F1
  against the model's registry F1, i.e. its test split's; ``sparse: nominal``, category 0
  for a window of too few objects);
* the live scorer replayed the same way (``replayed_scorer_mismatches``: 0 when the
  recording is what the scorer heard), and the scorer's split-half agreement (the window's
  even frames against its odd frames, each half a window of its own: the label's own
  test-retest figure, printed beside any agreement measured against it).

It writes, overall and per phase of the scenario (airborne frames and frames on the ground
apart) and per active model: the confusion matrices (rows: the scorer; columns: the oracle),
the agreements before and after, the oracle's mean predicted drop against the paired drop,
and the model's F1 on the perturbed and the clean frames beside its registry reference
(every model's, so the swap shows too). ``benchmarks/results/uav-oracle.json``::

    .venv/bin/python benchmarks/uav_oracle.py                  # the demo + offline: ~10 min
    .venv/bin/python benchmarks/uav_oracle.py --quick          # 6 s of flight into fog
    .venv/bin/python benchmarks/uav_oracle.py --cache runs/uav-oracle            # keep the run
    .venv/bin/python benchmarks/uav_oracle.py --cache runs/uav-oracle --reuse    # analyse it again

``--oracle MODEL=FILE`` (repeatable) replays another oracle file of MODEL offline on the frames
MODEL handled, as the live node would (the launch's window), and scores it against the live
scorer beside the live oracle (``replayed_oracle``): the oracle shipped before on the flight
the new one made, or the new one on the flight the old one made (the live oracle replayed
the same way gives what it said live: ``checks.replayed_oracle_mismatched``).
``--views N`` measures uav-fog under the demo's fog on N views of the demo's town from the
UAV datasets' camera and from the UAV's own camera in flight, each as rendered and through
the camera's JPEG (``views``): where its drop comes from.

``--data DIR`` (repeatable) also measures every model and its oracle on a rendered split under
the demo's fog at full strength, the same images clean and perturbed, as stored and through
the scenario camera's encoding (JPEG at 90): the shipped results of 2026-12-02 used the demo's
town (layout 0, 100 random views) and the test layouts (44-53, 200 views)::

    anunnaki make-dataset uav --out data/uav-l0 --width 320 --height 240 --train-layouts 1 \
        --val-layouts 2 --test-layouts 0 --per-layout 100
    anunnaki make-dataset uav --out data/uav-test --width 320 --height 240 --train-layouts 0 \
        --val-layouts 1 --test-layouts 44-53 --per-layout 20
    .venv/bin/python benchmarks/uav_oracle.py --cache runs/uav-oracle --reuse \
        --data data/uav-l0 --data data/uav-test

The figures of the oracle retrained through the camera's JPEG (issue 34, item 8; docs/uav.md,
"The oracle against the ground truth"), the oracle shipped before kept as ``runs/old/``::

    git show 56c340b:examples/models/uav-fog.oracle.json > runs/old/uav-fog.oracle.json  # and
    # .safetensors; then the demo as shipped, the old oracle replayed on its frames:
    .venv/bin/python benchmarks/uav_oracle.py --cache runs/uav-oracle \
        --oracle uav-fog=runs/old/uav-fog.oracle --views 200 --data data/uav-test
"""

from __future__ import annotations

import argparse
import bisect
import dataclasses
import io
import itertools
import json
import logging
import os
import platform
import tempfile
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from anunnaki import topics
from anunnaki.launch import load_launch, run_launch
from anunnaki.lec import DetectionResult, ModelRegistry, load_registry, match_image
from anunnaki.managed import SimKind, scenario_phases
from anunnaki.messages import Assessment, Detections, Image, body_of
from anunnaki.oracles import GroundTruthAssessor, category_for_drop
from anunnaki.phenomena import CameraEncoding
from anunnaki.sim import Scenario, Timeline, load_scenario

ROOT = Path(__file__).parents[1]
LAUNCH = ROOT / "examples" / "uav" / "sim.yaml"
RESULTS = Path(__file__).parent / "results" / "uav-oracle.json"
#: The quick mode's scenario: 6 s, climbing at 10 m/s to the demo's cruise altitude (objects
#: in view from about 2 s), into the demo's fog at 2 s.
QUICK = {
    "duration": 6,
    "phenomena": [{"at": 2, "phenomenon": "fog", "strength": 0.7, "ramp": 0.5}],
    "faults": [],
    "vary": None,
}
QUICK_MISSION = {"climb_rate": 10.0}
#: Altitude (m) above which a frame is airborne (on the ground the camera sees nobody).
AIRBORNE = 0.05
#: The scorer as shipped before issue 34 (examples/uav/sim.yaml's window, its reference and
#: sparse rule): replayed from the run for the "before" figures.
BEFORE = {"reference": "clean_f1", "sparse": "nominal"}

Counts = dict[int, tuple[int, int, int]]  # seq -> (true positives, false positives, misses)


# -- recording -----------------------------------------------------------------------------------
@dataclass
class Tape:
    """What one run published, by frame ``seq``."""

    times: dict[int, float] = field(default_factory=dict)
    images: dict[int, bytes] = field(default_factory=dict)  # JPEG, as the camera sent it
    clean: dict[int, bytes] = field(default_factory=dict)  # the same before the phenomena
    truth: dict[int, dict[str, Any]] = field(default_factory=dict)  # boxes, labels, ignore
    detections: dict[int, dict[str, Any]] = field(default_factory=dict)  # model, boxes, …
    oracle: dict[int, dict[str, Any]] = field(default_factory=dict)  # category, probs, drop
    scorer: dict[int, dict[str, Any]] = field(default_factory=dict)  # category, confidence
    statuses: list[dict[str, Any]] = field(default_factory=list)
    record_wall_s: float | None = None  # how long the run took to record
    lock: threading.Lock = field(default_factory=threading.Lock)
    subs: list[Any] = field(default_factory=list)

    def attach(self, bus: Any) -> None:
        """Subscribe to the run's public topics (``run_launch(on_bus=…)``)."""
        self._hear(bus, topics.PHENOMENA, self._on_phenomena)
        self._hear(bus, "/uav/camera/image", self._on_image)
        self._hear(bus, topics.CLEAN_FRAMES, self._on_clean)
        self._hear(bus, topics.GROUND_TRUTH, self._on_truth)
        self._hear(bus, topics.DETECTIONS, self._on_detections)
        self._hear(bus, topics.ORACLE_OUTPUT, self._on_oracle)
        self._hear(bus, topics.SCORER, self._on_scorer)
        self._hear(bus, "/uav/status", self._on_status)

    def close(self) -> None:
        for sub in self.subs:
            sub.close()
        self.subs = []

    def _hear(self, bus: Any, topic: str, handle: Callable[[Any], None]) -> None:
        """Hear ``topic`` in its publisher's thread, in order (as case_studies.py does)."""
        box: list[Any] = []
        order = threading.Lock()

        def drain() -> None:
            with order:
                while box and (sample := box[0].try_recv()) is not None:
                    with self.lock:
                        handle(sample.message)

        box.append(bus.subscribe(topic, queue=1024, on_ready=drain))
        self.subs.append(box[0])

    def _on_phenomena(self, message: Any) -> None:
        body = body_of(message)
        self.times[int(body["seq"])] = float(body["t"])

    def _on_image(self, message: Any) -> None:
        if isinstance(message, Image):
            self.images[message.seq] = bytes(message.data)

    def _on_clean(self, message: Any) -> None:
        if isinstance(message, Image):
            self.clean[message.seq] = bytes(message.data)

    def _on_truth(self, message: Any) -> None:
        body = body_of(message)
        self.truth[int(body["seq"])] = {
            "boxes": body.get("boxes") or [],
            "labels": body.get("labels") or [],
            "ignore": body.get("ignore") or [],
        }

    def _on_detections(self, message: Any) -> None:
        if isinstance(message, Detections):
            self.detections[message.frame_seq] = {
                "model": message.model_id,
                "boxes": message.boxes,
                "labels": message.labels,
                "scores": message.scores,
            }

    def _on_oracle(self, message: Any) -> None:
        if isinstance(message, Assessment) and message.frame_seq is not None:
            self.oracle[message.frame_seq] = {
                "category": message.category,
                "model": message.model_id,
                "drop": message.drop,
                "probs": message.context.get("probs"),
                "phenomenon": message.context.get("phenomenon"),
            }

    def _on_scorer(self, message: Any) -> None:
        if isinstance(message, Assessment) and message.frame_seq is not None:
            self.scorer[message.frame_seq] = {
                "category": message.category,
                "confidence": round(message.confidence, 4),
                "model": message.model_id,
            }

    def _on_status(self, message: Any) -> None:
        body = body_of(message)
        self.statuses.append({k: body.get(k) for k in ("t", "altitude", "mode", "phase")})

    def altitude_at(self, t: float) -> float:
        """The UAV's altitude in the last status at or before ``t`` (0 before the first)."""
        ts = [float(s["t"]) for s in self.statuses]
        k = bisect.bisect_right(ts, t + 1e-9)
        return float(self.statuses[k - 1]["altitude"]) if k else 0.0

    # the cache: a JSON file and the JPEGs
    _FIELDS = ("times", "truth", "detections", "oracle", "scorer")

    def save(self, folder: Path) -> None:
        """Write the tape into ``folder`` (``tape.json``, ``images/``, ``clean/``)."""
        folder.mkdir(parents=True, exist_ok=True)
        doc: dict[str, Any] = {
            n: {str(k): v for k, v in getattr(self, n).items()} for n in self._FIELDS
        }
        doc["statuses"] = self.statuses
        doc["record_wall_s"] = self.record_wall_s
        (folder / "tape.json").write_text(json.dumps(doc), encoding="utf-8")
        for name in ("images", "clean"):
            (folder / name).mkdir(exist_ok=True)
            for seq, data in getattr(self, name).items():
                (folder / name / f"{seq:06d}.jpg").write_bytes(data)

    @classmethod
    def load(cls, folder: Path) -> Tape:
        """Read what :meth:`save` wrote."""
        doc = json.loads((folder / "tape.json").read_text(encoding="utf-8"))
        tape = cls(statuses=list(doc["statuses"]), record_wall_s=doc.get("record_wall_s"))
        for name in cls._FIELDS:
            setattr(tape, name, {int(k): v for k, v in doc[name].items()})
        for name in ("images", "clean"):
            for path in sorted((folder / name).glob("*.jpg")):
                getattr(tape, name)[int(path.stem)] = path.read_bytes()
        return tape


def record(launch_file: Path, scenario_file: Path | None = None) -> Tape:
    """Run the launch (Utu as configured, flat out, on its executor); keep what it published."""
    launch = load_launch(launch_file)
    managed = launch.managed
    assert isinstance(managed, SimKind), f"{launch_file}: not a 'managed: sim' launch"
    update: dict[str, Any] = {"report": False}
    if scenario_file is not None:
        update["scenario"] = str(scenario_file)
    managed.options = managed.options.model_copy(update=update)
    # no e-mail from a benchmark
    utu = launch.utu.model_copy(update={"notify": {}})
    tape = Tape()
    try:
        run_launch(
            dataclasses.replace(launch, utu=utu),
            speed=0.0,
            out=io.StringIO(),
            handle_signals=False,
            on_bus=tape.attach,
        )
    finally:
        tape.close()
    return tape


# -- counting ------------------------------------------------------------------------------------
def decode(data: bytes) -> Any:
    """A recorded JPEG as the detector saw it (``(H, W, 3)`` RGB)."""
    return Image(encoding="jpeg", width=1, height=1, data=data).to_array()


def count_frame(
    pred: DetectionResult, truth: Mapping[str, Any], classes: Sequence[str]
) -> tuple[int, int, int]:
    """One frame's ``(tp, fp, fn)`` by the F1 rule the scorer uses (``match_image``: class-aware,
    IoU 0.5, ignore boxes); ``pred.labels`` index ``classes``."""
    index = {name: k for k, name in enumerate(classes)}
    labels = [index.setdefault(str(n), len(index)) for n in truth["labels"]]
    _, is_tp, n_truth = match_image(
        pred,
        np.asarray(truth["boxes"], dtype=np.float64).reshape(-1, 4),
        np.asarray(labels, dtype=np.int64),
        iou=0.5,
        ignore=np.asarray(truth["ignore"], dtype=np.float64).reshape(-1, 4),
    )
    tp = int(is_tp.sum())
    return tp, len(is_tp) - tp, n_truth - tp


def live_counts(tape: Tape, classes: Sequence[str]) -> Counts:
    """Each frame's counts for what the live detector published on it."""
    index = {name: k for k, name in enumerate(classes)}
    out: Counts = {}
    for seq, det in tape.detections.items():
        if seq in tape.truth:
            pred = DetectionResult(
                np.asarray(det["boxes"], dtype=np.float32).reshape(-1, 4),
                np.asarray([index[n] for n in det["labels"]], dtype=np.int64),
                np.asarray(det["scores"], dtype=np.float32),
            )
            out[seq] = count_frame(pred, tape.truth[seq], classes)
    return out


def detect_all(tape: Tape, images: Mapping[int, bytes], detector: Any, batch: int = 16) -> Counts:
    """Each frame's counts for ``detector`` run offline on ``images`` (the tape's frames)."""
    seqs = sorted(s for s in images if s in tape.truth)
    out: Counts = {}
    for k in range(0, len(seqs), batch):
        chunk = seqs[k : k + batch]
        found = detector.detect([decode(images[s]) for s in chunk])
        for seq, pred in zip(chunk, found, strict=True):
            out[seq] = count_frame(pred, tape.truth[seq], detector.classes)
    return out


def f1_of(tp: int, fp: int, fn: int) -> float | None:
    """Pooled F1 (``None`` with nothing to find and nothing found)."""
    return None if tp + fp + fn == 0 else 2 * tp / (2 * tp + fp + fn)


def pooled(counts: Mapping[int, tuple[int, int, int]], seqs: Iterable[int]) -> dict[str, Any]:
    """Counts summed over the ``seqs`` in ``counts``, and their F1."""
    tp = fp = fn = 0
    for s in seqs:
        if s in counts:
            a, b, c = counts[s]
            tp, fp, fn = tp + a, fp + b, fn + c
    f1 = f1_of(tp, fp, fn)
    return {"tp": tp, "fp": fp, "fn": fn, "f1": None if f1 is None else round(f1, 4)}


def windows(seqs: Sequence[int], model_of: Mapping[int, str], size: int) -> dict[int, list[int]]:
    """Each frame's window as the scorer keeps it when it assesses the frame: the ``size``
    frames of the same model before it (its own truth comes after the assessment), started
    afresh at every change of model."""
    out: dict[int, list[int]] = {}
    current: list[int] = []
    last: str | None = None
    for seq in seqs:
        if model_of[seq] != last:
            current, last = [], model_of[seq]
        out[seq] = list(current)
        current = [*current, seq][-size:]
    return out


def paired_category(
    pert: Counts, clean: Counts, frames: Sequence[int], options: Mapping[str, Any]
) -> int | None:
    """The paired scorer's category from offline counts (``None``: withheld)."""
    got, ref = pooled(pert, frames), pooled(clean, frames)
    if len(frames) < options["min_frames"] or got["tp"] + got["fn"] < options["min_objects"]:
        return None
    f1 = 1.0 if got["f1"] is None else float(got["f1"])
    ref_f1 = 1.0 if ref["f1"] is None else float(ref["f1"])
    drop = max(0.0, (ref_f1 - f1) / ref_f1) if ref_f1 > 0 else 0.0
    low, high = options.get("thresholds", (0.05, 0.10))
    return category_for_drop(drop, (float(low), float(high)))


def replay(
    tape: Tape, seqs: Sequence[int], options: Mapping[str, Any], registry: ModelRegistry
) -> dict[int, int]:
    """The categories a fresh ``ground_truth`` scorer with ``options`` gives the run, fed in
    the order the live one is fed (a frame's clean render and detections, then its
    assessment, then its truth)."""
    scorer = GroundTruthAssessor(**{**GroundTruthAssessor.options_from_models(registry), **options})
    out: dict[int, int] = {}
    for seq in seqs:
        det, truth = tape.detections[seq], tape.truth[seq]
        if scorer.clean_frames:
            scorer.observe_clean_frame(seq, decode(tape.clean[seq]))
        scorer.observe_detections(
            Detections(
                frame_seq=seq,
                model_id=det["model"],
                width=1,
                height=1,
                boxes=det["boxes"],
                labels=det["labels"],
                scores=det["scores"],
            )
        )
        a = scorer.assess(np.zeros((1, 1, 3), np.uint8), seq=seq, model_id=det["model"])
        if a is not None:
            out[seq] = a.category
        scorer.observe_ground_truth(seq, truth["boxes"], truth["labels"], ignore=truth["ignore"])
    return out


def confusion(
    rows: Mapping[int, int], cols: Mapping[int, int], seqs: Iterable[int]
) -> dict[str, Any]:
    """``rows`` (the reference) × ``cols`` over the frames of ``seqs`` both have."""
    matrix = [[0, 0, 0] for _ in range(3)]
    for s in seqs:
        if s in rows and s in cols:
            matrix[rows[s]][cols[s]] += 1
    n = sum(map(sum, matrix))
    agree = sum(matrix[c][c] for c in range(3))
    return {"frames": n, "agreement": None if n == 0 else round(agree / n, 4), "confusion": matrix}


# -- the analysis --------------------------------------------------------------------------------
def _file_sha(path: Path) -> str:
    """The sha256 of an oracle's weights (``NAME.safetensors``, or ``NAME``)."""
    import hashlib

    weights = path if path.suffix == ".safetensors" else path.with_name(path.name + ".safetensors")
    return hashlib.sha256(weights.read_bytes()).hexdigest()


def _oracle_sha(registry: ModelRegistry, model_id: str) -> str | None:
    """The sha256 the registry pins for ``model_id``'s oracle."""
    spec = next((m for m in registry if m.id == model_id), None)
    return None if spec is None or spec.oracle is None else spec.oracle.sha256


def _mean(values: Sequence[float]) -> float | None:
    return round(float(np.mean(values)), 4) if values else None


def scorer_options(launch: Path) -> dict[str, Any]:
    """The live scorer's options (``managed.sim.scorer``), name left out."""
    managed = load_launch(launch).managed
    assert isinstance(managed, SimKind) and managed.options.scorer is not None
    options = {k: v for k, v in managed.options.scorer.items() if k != "name"}
    window = int(options.get("window", 30))
    options.setdefault("window", window)
    options.setdefault("min_frames", max(1, window // 3))
    options.setdefault("min_objects", 0)
    return options


def replay_oracle(
    tape: Tape,
    seqs: Sequence[int],
    model_of: Mapping[int, str],
    registry: ModelRegistry,
    oracles: Mapping[str, str | Path],
    window: int,
) -> dict[int, int]:
    """The categories an ``enlil`` oracle node with ``oracles`` (model id -> oracle file, on
    top of the registry's) gives the run's frames, as the live node would (the camera's
    frames in order, the model that handled each, ``window`` frames averaged)."""
    from anunnaki.enlil import EnlilOracle

    node = EnlilOracle(models=registry, oracles=dict(oracles), window=window)
    out: dict[int, int] = {}
    for seq in seqs:
        said = node.assess(decode(tape.images[seq]), seq=seq, model_id=model_of[seq])
        if said is not None:
            out[seq] = said.category
    return out


def oracle_window(launch: Path) -> int:
    """The live ``enlil`` oracle's window (``managed.sim.oracle.window``)."""
    managed = load_launch(launch).managed
    assert isinstance(managed, SimKind)
    return int((managed.options.oracle or {}).get("window", 1))


def analyse(
    tape: Tape,
    *,
    scenario: Scenario,
    registry: ModelRegistry,
    options: Mapping[str, Any],
    replayed: Mapping[str, str | Path] | None = None,
    window: int = 3,
) -> dict[str, Any]:
    """The figures of one recorded run (see the module's docstring); with ``replayed``
    (model id -> oracle file), those oracles too, run offline on the same frames."""
    ids = registry.ids()
    detectors = {m: registry.load(m) for m in ids}
    classes = detectors[ids[0]].classes
    live = live_counts(tape, classes)
    seqs = sorted(live)
    model_of = {s: tape.detections[s]["model"] for s in seqs}
    pert = {m: detect_all(tape, tape.images, d) for m, d in detectors.items()}
    clean = {m: detect_all(tape, tape.clean, d) for m, d in detectors.items()}
    mismatched = sum(1 for s in seqs if pert[model_of[s]].get(s) != live[s])
    oracle = {s: int(tape.oracle[s]["category"]) for s in seqs if s in tape.oracle}
    scorer = {s: int(tape.scorer[s]["category"]) for s in seqs if s in tape.scorer}
    # the live oracle replayed offline must give what it said live (the check of the replay)
    live_again = replay_oracle(tape, seqs, model_of, registry, {}, window)
    other = replay_oracle(tape, seqs, model_of, registry, replayed, window) if replayed else {}
    before = replay(tape, seqs, {**options, **BEFORE}, registry)
    again = replay(tape, seqs, options, registry)
    paired = options.get("reference") == "paired" and bool(tape.clean)
    # the label's own test-retest: the window's even frames against its odd frames
    halves: list[dict[int, int]] = [{}, {}]
    if paired:
        half = {**options, "min_frames": options["min_frames"] // 2}
        half["min_objects"] = options["min_objects"] // 2
        win = windows(seqs, model_of, int(options["window"]))
        for parity in (0, 1):
            for s in seqs:
                m = model_of[s]
                cat = paired_category(live, clean[m], [x for x in win[s] if x % 2 == parity], half)
                if cat is not None:
                    halves[parity][s] = cat
    airborne = [s for s in seqs if tape.altitude_at(tape.times.get(s, 0.0)) > AIRBORNE]
    air = set(airborne)
    win = windows(seqs, model_of, int(options["window"]))
    paired_drop: dict[int, float] = {}
    for s in seqs:
        got, ref = pooled(live, win[s]), pooled(clean[model_of[s]], win[s])
        if got["tp"] + got["fn"] >= max(1, options["min_objects"]) and ref["f1"]:
            paired_drop[s] = max(0.0, (ref["f1"] - (got["f1"] or 0.0)) / ref["f1"])

    def agreements(part: Sequence[int]) -> dict[str, Any]:
        out = {
            "before": confusion(before, oracle, part),
            "after": confusion(scorer, oracle, part),
            "after_x_before": confusion(scorer, before, part),
            "split_half": confusion(halves[0], halves[1], part) if paired else None,
        }
        if replayed:
            out["replayed_oracle"] = confusion(scorer, other, part)
        return out

    def block(part: Sequence[int]) -> dict[str, Any]:
        out: dict[str, Any] = {"frames": len(part), **agreements(part)}
        for m in sorted({model_of[s] for s in part}):
            mine = [s for s in part if model_of[s] == m]
            drops = [
                float(tape.oracle[s]["drop"])
                for s in mine
                if tape.oracle.get(s, {}).get("drop") is not None
            ]
            out[m] = {
                "frames": len(mine),
                "objects_per_frame": round(
                    float(np.mean([live[s][0] + live[s][2] for s in mine])), 2
                ),
                **agreements(mine),
                "withheld_by_scorer": sum(1 for s in mine if s not in scorer),
                "oracle_mean_drop": _mean(drops),
                "paired_mean_drop": _mean([paired_drop[s] for s in mine if s in paired_drop]),
                "f1": {
                    "registry_clean": registry.clean_f1(m),
                    "perturbed": pooled(live, mine),
                    "clean": pooled(clean[m], mine),
                    "every_model": {
                        o: {
                            "perturbed": pooled(pert[o], mine)["f1"],
                            "clean": pooled(clean[o], mine)["f1"],
                        }
                        for o in ids
                    },
                },
            }
        return out

    end = max(tape.times.values()) + 1e-6 if tape.times else float(scenario.duration)
    timeline = Timeline(scenario)
    phases = []
    for a, b in scenario_phases(scenario, end):
        label = "+".join(n for n, _ in timeline.phenomena((a + b) / 2)) or "clear"
        span = [s for s in seqs if a <= tape.times.get(s, -1.0) < b]
        phases.append(
            {
                "start": round(a, 3),
                "end": round(min(b, float(scenario.duration)), 3),
                "label": label,
                "airborne": block([s for s in span if s in air]),
                "ground": block([s for s in span if s not in air]),
            }
        )
    return {
        "frames": len(seqs),
        "airborne_frames": len(airborne),
        "scorer": {"options": dict(options), "before": BEFORE},
        "checks": {
            "offline_vs_live_detections_mismatched": mismatched,
            "replayed_scorer_mismatched": sum(
                1 for s in set(scorer) | set(again) if scorer.get(s) != again.get(s)
            ),
            "clean_frames": len(tape.clean),
            # frames both assessed, categories apart (the replay is the live node's)
            "replayed_oracle_mismatched": sum(
                1 for s in set(oracle) & set(live_again) if oracle[s] != live_again[s]
            ),
            # frames the replay assessed and the recording holds no assessment of (the run's
            # first frame: published before the recorder heard the oracle's topic)
            "replayed_oracle_unrecorded": len(set(live_again) - set(oracle)),
        },
        "oracles": {
            "live": {m: _oracle_sha(registry, m) for m in ids},
            "replayed": {m: _file_sha(Path(f)) for m, f in (replayed or {}).items()},
        },
        "clean_f1": {
            m: {
                "registry": registry.clean_f1(m),
                "simulator": pooled(clean[m], airborne)["f1"],
            }
            for m in ids
        },
        "overall": {"all": agreements(seqs), "airborne": agreements(airborne)},
        "phases": phases,
    }


def dataset_figures(
    data: Path,
    split: str,
    scenario: Scenario,
    registry: ModelRegistry,
    encoding: CameraEncoding | None = None,
) -> dict[str, Any]:
    """Each model on a rendered split (``anunnaki make-dataset uav``), clean and under the
    phenomena in force at the scenario's end (the demo's fog at full strength; image ``i``
    perturbed with seed ``i``): F1 on both and the relative drop (paired, as Enlil labels a
    context), and what the model's enlil oracle says of the perturbed images (per image).
    With ``encoding`` (the scenario camera's), every image, clean or perturbed, goes through
    it last, as the camera sends it."""
    from anunnaki.datasets import load_split
    from anunnaki.enlil import EnlilOracle
    from anunnaki.phenomena import PHENOMENA

    ds = load_split(data, split)
    applied = Timeline(scenario).phenomena(float(scenario.duration) - 1e-6)
    truths = [
        {"boxes": b, "labels": [ds.classes[int(k)] for k in lab], "ignore": ig}
        for b, lab, ig in ds.truths()
    ]
    clean_images = [ds[i][0] for i in range(len(ds))]
    perturbed = []
    for i, image in enumerate(clean_images):
        out_image = image
        for name, params in applied:
            out_image = PHENOMENA.create(name).apply(out_image, params, i)
        perturbed.append(out_image)
    if encoding is not None:
        clean_images = [encoding.apply(im) for im in clean_images]
        perturbed = [encoding.apply(im) for im in perturbed]
    oracle = EnlilOracle(models=registry, window=1)
    out: dict[str, Any] = {
        "data": str(data),
        "split": split,
        "images": len(ds),
        "encoding": "none" if encoding is None else str(encoding),
        "phenomena": [{"name": n, "params": dict(p)} for n, p in applied],
        "models": {},
    }
    for m in registry.ids():
        detector = registry.load(m)
        counts = {}
        for name, images in (("clean", clean_images), ("perturbed", perturbed)):
            found: list[DetectionResult] = []
            for k in range(0, len(images), 16):
                found += detector.detect(images[k : k + 16])
            per = {i: count_frame(f, truths[i], detector.classes) for i, f in enumerate(found)}
            counts[name] = pooled(per, range(len(images)))
        said = [oracle.assess(image, seq=i, model_id=m) for i, image in enumerate(perturbed)]
        cats = [a.category for a in said if a is not None]
        drops = [a.drop for a in said if a is not None and a.drop is not None]
        c, p = counts["clean"]["f1"], counts["perturbed"]["f1"]
        drop = None if not c or p is None else round(max(0.0, (c - p) / c), 4)
        out["models"][m] = {
            **counts,
            "drop": drop,
            "category": None if drop is None else category_for_drop(drop),
            "oracle": {"categories": [cats.count(k) for k in range(3)], "mean_drop": _mean(drops)},
        }
    return out


def _flight_camera(
    scenario: Scenario, rng: np.random.Generator, legs: Sequence[tuple[float, float]]
) -> Any:
    """The UAV's camera somewhere along the mission's legs at cruise altitude, looking ahead
    along the leg :data:`~anunnaki.sim.CAMERA_DOWN` degrees below the horizon (as
    ``UavSim`` renders it in flight)."""
    import math

    from anunnaki.sim import CAMERA_DOWN, UAV_CAMERA_FOV, Camera

    pairs = list(itertools.pairwise(legs))
    lengths = [math.dist(a, b) for a, b in pairs]
    at = float(rng.uniform(0.0, sum(lengths)))
    k = 0
    while at > lengths[k] and k < len(lengths) - 1:
        at, k = at - lengths[k], k + 1
    (ax, ay), (bx, by) = pairs[k]
    f = at / lengths[k] if lengths[k] else 0.0
    x, y, yaw = ax + f * (bx - ax), ay + f * (by - ay), math.atan2(by - ay, bx - ax)
    z = float(scenario.mission.cruise_altitude)
    reach = z / math.tan(math.radians(CAMERA_DOWN))
    target = (x + reach * math.cos(yaw), y + reach * math.sin(yaw), 0.0)
    return Camera((x, y, z), target, fov=UAV_CAMERA_FOV, near=0.3, far=250.0)


def view_figures(
    scenario: Scenario, registry: ModelRegistry, n: int, model_id: str = "uav-fog", seed: int = 1
) -> dict[str, Any]:
    """``model_id`` under the phenomena in force at the scenario's end, on ``n`` views of the
    scenario's town from two cameras, each as rendered and through the scenario camera's
    encoding (image ``i`` perturbed with seed ``i``; the drop paired, as Enlil labels):

    * ``dataset``: the UAV datasets' camera (``make-dataset uav``: 15-40 m up, 35-80 degrees
      down, aimed near an object eight times in ten, varied daylight and object poses);
    * ``flight``: the UAV's own camera in flight (cruise altitude, 50 degrees down, looking
      ahead along the mission's legs, the simulator's daylight), views with nobody in them
      left out.
    """
    from anunnaki.phenomena import PHENOMENA
    from anunnaki.sim import Scene, layout_placements

    camera = scenario.camera
    sent = CameraEncoding(camera.quality) if camera.encoding == "jpeg" else None
    applied = Timeline(scenario).phenomena(float(scenario.duration) - 1e-6)
    detector = registry.load(model_id)
    m = scenario.mission
    legs = [(float(p[0]), float(p[1])) for p in (m.home, *m.waypoints, m.delivery, m.home)]
    out: dict[str, Any] = {
        "model": model_id,
        "layout": scenario.layout,
        "views": n,
        "phenomena": [{"name": k, "params": dict(p)} for k, p in applied],
        "cameras": {},
    }
    placements = layout_placements("uav", scenario.layout)
    with Scene(
        "uav", scenario.layout, width=camera.width, height=camera.height, placements=placements
    ) as scene:
        for kind in ("dataset", "flight"):
            rng = np.random.default_rng(seed)
            frames: list[Any] = []
            while len(frames) < n:
                if kind == "dataset":
                    scene.vary(rng)
                    frame = scene.render(scene.random_camera(rng), light=scene.random_light(rng))
                else:
                    frame = scene.render(_flight_camera(scenario, rng, legs))
                    if len(frame.boxes) == 0:
                        continue
                frames.append(frame)
            truths = [
                {"boxes": f.boxes, "labels": [detector.classes[int(k)] for k in f.labels],
                 "ignore": f.ignore}
                for f in frames
            ]  # fmt: skip
            rendered = [f.image for f in frames]
            perturbed = []
            for i, image in enumerate(rendered):
                out_image = image
                for name, params in applied:
                    out_image = PHENOMENA.create(name).apply(out_image, params, i)
                perturbed.append(out_image)
            heights = np.concatenate([np.asarray(f.boxes).reshape(-1, 4) for f in frames])
            entry: dict[str, Any] = {
                "objects_per_view": round(sum(len(f.boxes) for f in frames) / n, 2),
                "median_box_height_px": float(np.median(heights[:, 3] - heights[:, 1])),
            }
            for label, codec in (("rendered", None), ("through_camera", sent)):
                if label == "through_camera" and codec is None:
                    continue
                counts = {}
                for name, shown in (("clean", rendered), ("perturbed", perturbed)):
                    images = shown if codec is None else [codec.apply(im) for im in shown]
                    found: list[DetectionResult] = []
                    for k in range(0, len(images), 16):
                        found += detector.detect(images[k : k + 16])
                    per = {
                        i: count_frame(f, truths[i], detector.classes) for i, f in enumerate(found)
                    }
                    counts[name] = pooled(per, range(len(images)))
                c, p = counts["clean"]["f1"], counts["perturbed"]["f1"]
                drop = None if not c or p is None else round(max(0.0, (c - p) / c), 4)
                entry[label] = {
                    **counts,
                    "encoding": "none" if codec is None else str(codec),
                    "drop": drop,
                    "category": None if drop is None else category_for_drop(drop),
                }
            out["cameras"][kind] = entry
    return out


# -- the script ----------------------------------------------------------------------------------
def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--launch", type=Path, default=LAUNCH)
    ap.add_argument("--quick", action="store_true", help="6 s into fog instead of the demo")
    ap.add_argument("--output", type=Path, default=RESULTS)
    ap.add_argument("--cache", type=Path, help="keep the recorded run here (frames, topics)")
    ap.add_argument("--reuse", action="store_true", help="analyse the run kept in --cache")
    ap.add_argument(
        "--data",
        type=Path,
        action="append",
        default=[],
        help="also measure the models and oracles on this rendered dataset's --split, under "
        "the scenario's last phenomena (repeatable)",
    )
    ap.add_argument("--split", default="test", help="the split of --data (test)")
    ap.add_argument(
        "--oracle",
        action="append",
        default=[],
        metavar="MODEL=FILE",
        help="also replay this oracle file of MODEL offline on the frames MODEL handled, "
        "scored against the live scorer as replayed_oracle (repeatable; e.g. the oracle "
        "shipped before, beside the one the run used)",
    )
    ap.add_argument(
        "--views",
        type=int,
        default=0,
        metavar="N",
        help="also measure uav-fog under the scenario's last phenomena on N views of its town "
        "from the datasets' camera and from the UAV's camera in flight, each as rendered and "
        "through the camera's encoding",
    )
    args = ap.parse_args()
    replayed = dict(item.split("=", 1) for item in args.oracle)
    logging.getLogger("anunnaki.utu.notify").setLevel(logging.CRITICAL)
    load_before = list(os.getloadavg())
    t0 = time.perf_counter()
    managed = load_launch(args.launch).managed
    assert isinstance(managed, SimKind) and managed.options.models is not None
    scenario = load_scenario(managed.options.scenario)
    if args.quick:
        data = scenario.model_dump(mode="json")
        data["mission"] = {**data["mission"], **QUICK_MISSION}
        scenario = Scenario.model_validate({**data, **QUICK})
    if args.reuse:
        assert args.cache is not None, "--reuse needs --cache"
        tape = Tape.load(args.cache)
    else:
        with tempfile.TemporaryDirectory(prefix="uav-oracle-") as tmp:
            path = None
            if args.quick:
                path = Path(tmp) / "quick.yaml"
                path.write_text(json.dumps(scenario.model_dump(mode="json")), encoding="utf-8")
            tape = record(args.launch, path)
        tape.record_wall_s = round(time.perf_counter() - t0, 1)
        if args.cache is not None:
            tape.save(args.cache)
    registry = load_registry(managed.options.models)
    figures = analyse(
        tape,
        scenario=scenario,
        registry=registry,
        options=scorer_options(args.launch),
        replayed=replayed,
        window=oracle_window(args.launch),
    )
    if args.data:
        camera = scenario.camera
        sent = CameraEncoding(camera.quality) if camera.encoding == "jpeg" else None
        figures["datasets"] = [
            dataset_figures(d, args.split, scenario, registry, encoding)
            for d in args.data
            for encoding in dict.fromkeys([None, sent])
        ]
    if args.views:
        figures["views"] = view_figures(scenario, registry, args.views)
    launch = args.launch.resolve()
    doc = {
        "benchmark": "uav_oracle",
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
        "machine": {
            "python": platform.python_version(),
            "cpus": os.cpu_count(),
            "load_average": [load_before, list(os.getloadavg())],
        },
        "settings": {
            "launch": str(launch.relative_to(ROOT)) if launch.is_relative_to(ROOT) else str(launch),
            "scenario": "quick" if args.quick else "the launch's",
            "reused": bool(args.reuse),
            "record_wall_s": tape.record_wall_s,
            "wall_s": round(time.perf_counter() - t0, 1),
        },
        **figures,
    }
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    print(summary(doc))
    print(f"wrote {args.output}")


def summary(doc: Mapping[str, Any]) -> str:
    """Agreement before and after, overall and per phase and model, as plain lines."""

    def pair(e: Mapping[str, Any]) -> str:
        b, a = e["before"], e["after"]
        half, other = e.get("split_half"), e.get("replayed_oracle")
        return (
            f"before {b['agreement']} of {b['frames']}, after {a['agreement']} of {a['frames']}"
            + (f" (split-half {half['agreement']})" if half else "")
            + (f"; replayed oracle {other['agreement']} of {other['frames']}" if other else "")
        )

    lines = [f"{k:<9} {pair(v)}" for k, v in doc["overall"].items()]
    for p in doc["phases"]:
        for where in ("airborne", "ground"):
            for model, e in p[where].items():
                if isinstance(e, dict) and "f1" in e:
                    f1 = e["f1"]
                    lines.append(
                        f"{p['start']:5.1f}-{p['end']:5.1f} s {p['label']:<16} {where:<8} "
                        f"{model:<20} {e['frames']:>3} frames: {pair(e)}; F1 "
                        f"{f1['perturbed']['f1']} (clean {f1['clean']['f1']}, registry "
                        f"{f1['registry_clean']:.3f})"
                    )
    return "\n".join(lines)


if __name__ == "__main__":
    main()
