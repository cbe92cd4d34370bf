"""The whole loop's managed system: a simulated platform, its detector and its oracle.

What ``managed: sim`` in a launch file (``anunnaki run``) starts, on the launch's bus::

    RoverSim/UavSim ─/rover/camera/image─▶ LecNode (the registry's active model)
        ▲                                     │ /lec/detector/detections (seq, model id)
        │ stop rule ◀─────────────────────────┤
        │                                     ▼
        │             /sim/ground_truth ─▶ OracleNode (ground_truth) ─/utu/oracle/output─▶ Utu
        └── /rover/set_mode, /rover/stop ◀── Utu's tactics ──▶ /lm_manager/swap ─▶ LecNode

:class:`SimulatedSystem` owns the three, runs the simulation in a thread (live at ``speed``
× real time) and scores what happened per phase of the scenario (:class:`PhaseScore`):
the active model's F1 against the simulator's ground truth (with its counts: a phase with no
object to find has none), the categories the oracle reported, how often it agreed with its
live scorer, the models that ran, the tactics Utu started and the collisions. A UAV's phases
end at its touch-down; the time it then spends on the ground is a row of its own. The rover
never sees the ground truth; only the scorer and the ground-truth oracle do.

On a bus delivered by a deterministic executor (``open_bus("inproc", executor=ex)``, what
``anunnaki run`` opens for a simulated run in one process) the simulation's thread is the
run's one thread of delivery: after each camera frame and at each instant (1/40 s) it drains
the executor — the detector, the oracles, the scorer, the platform's own subscriptions and
Utu take what was published, in publication order, and Utu's actions are answered — and only
then moves its clock on. The run is one deterministic program: the same scenario, seed and
manager give the same report, loaded or not. On any other bus the nodes run on the bus's
threads and the simulation does not wait for them (a live deployment).
"""

from __future__ import annotations

import bisect
import itertools
import logging
import threading
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from anunnaki import topics
from anunnaki._closing import Closing
from anunnaki.bus import LivelinessGuard, Sample
from anunnaki.managed._camera import CameraChain
from anunnaki.messages import Assessment, Detections, body_of
from anunnaki.sim import (
    GROUND,
    FrameScore,
    RunReport,
    Scenario,
    SimPlatform,
    Timeline,
    compare_assessors,
    f1_score,
    tactic_events,
)

__all__ = [
    "PhaseScore",
    "SimulatedSystem",
    "format_phases",
    "format_scoring",
    "phase_spans",
    "scenario_phases",
    "score_phases",
]

log = logging.getLogger("anunnaki.managed")


@dataclass
class PhaseScore:
    """What happened in one phase of a scenario.

    Attributes:
        start: Phase start (simulated s).
        end: Phase end (simulated s).
        label: The phenomena in force (``clear``, ``fog``, ``brightness+fog`` …).
        frames: Frames whose detections and ground truth were both seen.
        tp: Matched detections (class-aware, IoU ≥ 0.5).
        fp: Unmatched detections.
        fn: Unmatched ground-truth objects.
        categories: How many assessments of each category the oracle published.
        models: The models that produced the phase's detections, in order of first use.
        tactics: Tactics started in the phase, with their outcome when known.
        collisions: Collisions counted in the phase.
        agree: Frames of the phase on which the oracle and its live scorer agreed.
        compared: Frames of the phase both assessed (0 without a scorer).
        visible: ``[frames, tp, fp, fn, hidden]`` over the frames whose ground truth said
            which boxes a phenomenon hides (``/sim/ground_truth``'s ``hidden``): the hidden
            boxes are ignore boxes there. Zeros when no phenomenon of the phase has a mask.

    """

    start: float
    end: float
    label: str
    frames: int = 0
    tp: int = 0
    fp: int = 0
    fn: int = 0
    categories: Counter[int] = field(default_factory=Counter)
    models: list[str] = field(default_factory=list)
    tactics: list[str] = field(default_factory=list)
    collisions: int = 0
    agree: int = 0
    compared: int = 0
    visible: list[int] = field(default_factory=lambda: [0, 0, 0, 0, 0])

    @property
    def f1(self) -> float | None:
        """The phase's detector F1 (``None`` without a ground-truth object: :func:`f1_score`)."""
        return f1_score(self.tp, self.fp, self.fn)

    @property
    def f1_visible(self) -> float | None:
        """F1 on the boxes less than half hidden (``None``: no frame said, or nothing to find)."""
        frames, tp, fp, fn, _ = self.visible
        return None if frames == 0 else f1_score(tp, fp, fn)

    @property
    def agreement(self) -> float | None:
        """How often the oracle agreed with its live scorer (``None``: nothing compared)."""
        return None if self.compared == 0 else self.agree / self.compared

    @property
    def category(self) -> int | None:
        """The category the oracle reported most often in the phase."""
        return self.categories.most_common(1)[0][0] if self.categories else None

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "start": self.start,
            "end": self.end,
            "label": self.label,
            "frames": self.frames,
            "f1": self.f1,
            "tp": self.tp,
            "fp": self.fp,
            "fn": self.fn,
            "categories": {str(k): v for k, v in sorted(self.categories.items())},
            "models": list(self.models),
            "tactics": list(self.tactics),
            "collisions": self.collisions,
            "agreement": None if self.agreement is None else round(self.agreement, 4),
            "agreement_frames": self.compared,
            "f1_visible": self.f1_visible,
            "visible": None
            if self.visible[0] == 0
            else dict(zip(("frames", "tp", "fp", "fn", "hidden"), self.visible, strict=True)),
        }


def scenario_phases(scenario: Scenario, until: float | None = None) -> list[tuple[float, float]]:
    """Split ``[0, until]`` at every phenomenon's start, end of ramp and ``until``."""
    end = scenario.duration if until is None else until
    cuts = {0.0, float(end)}
    for event in scenario.phenomena:
        for t in (event.at, event.at + event.ramp, event.until):
            if t is not None and 0.0 < t < end:
                cuts.add(float(t))
    edges = sorted(cuts)
    return [(a, b) for a, b in itertools.pairwise(edges) if b - a > 1e-6]


def _label(phenomena: Sequence[tuple[str, Mapping[str, float]]]) -> str:
    return "+".join(name for name, _ in phenomena) or "clear"


def phase_spans(
    scenario: Scenario, end: float, *, landed: float | None = None
) -> list[tuple[float, float, str]]:
    """The table's rows ``(start, end, label)``: the scenario's phases up to ``end``.

    A UAV that touched down (``landed``, simulated s) before ``end`` flew its phases until
    then; the rest of the run is one last row, :data:`~anunnaki.sim.GROUND`. Labels name the
    phenomena in force (``clear`` without one).
    """
    flown = end if landed is None or landed >= end - 1e-6 else max(landed, 1e-3)
    timeline = Timeline(scenario)
    out = [
        (a, b, _label(timeline.phenomena((a + b) / 2))) for a, b in scenario_phases(scenario, flown)
    ]
    if flown < end - 1e-6:
        out.append((flown, float(end), GROUND))
    return out


def score_phases(
    spans: Sequence[tuple[float, float, str]],
    *,
    frames: Iterable[tuple[float, int, int, int, str]] = (),
    assessments: Iterable[tuple[float, int]] = (),
    collisions: Iterable[float] = (),
    decisions: Iterable[Any] = (),
    compared: Iterable[tuple[float, int, int]] = (),
    visible: Iterable[tuple[float, int, int, int, int]] = (),
) -> list[PhaseScore]:
    """Score a run per phase (:func:`phase_spans`); each item counts in the phase of its time.

    Args:
        spans: ``(start, end, label)`` per phase, in time order.
        frames: ``(t, tp, fp, fn, model)`` per scored frame.
        assessments: ``(t, category)`` per assessment of the oracle.
        collisions: Simulated times of collisions.
        decisions: Utu's decisions (``t``, ``kind``, ``tactic``).
        compared: ``(t, oracle category, scorer category)`` per frame both assessed.
        visible: ``(t, tp, fp, fn, hidden)`` per scored frame whose ground truth said which
            boxes are hidden, counted with those as ignore boxes.

    """
    out = [PhaseScore(a, b, label) for a, b, label in spans]
    starts = [p.start for p in out]

    def placed(items: Iterable[Any], time: Callable[[Any], float]) -> Iterator[Any]:
        """``(phase, item)`` for each item whose time falls in a phase."""
        for item in items:
            k = bisect.bisect_right(starts, time(item)) - 1
            if 0 <= k < len(out) and time(item) <= out[k].end + 1e-9:
                yield out[k], item

    for p, (_, tp, fp, fn, model) in placed(frames, lambda f: f[0]):
        p.frames += 1
        p.tp, p.fp, p.fn = p.tp + tp, p.fp + fp, p.fn + fn
        if model not in p.models:
            p.models.append(model)
    for p, (_, *counts) in placed(visible, lambda f: f[0]):
        p.visible = [p.visible[0] + 1, *(a + b for a, b in zip(p.visible[1:], counts, strict=True))]
    for p, (_, category) in placed(assessments, lambda a: a[0]):
        p.categories[category] += 1
    for p, _ in placed(collisions, float):
        p.collisions += 1
    for p, event in placed(tactic_events(list(decisions)), lambda e: e.t):
        p.tactics.append(
            event.tactic if event.outcome is None else f"{event.tactic} ({event.outcome})"
        )
    for p, (_, mine, theirs) in placed(compared, lambda c: c[0]):
        p.compared += 1
        p.agree += int(mine == theirs)
    return out


def _match(
    det: Detections, truth: tuple[float, np.ndarray, list[str], np.ndarray]
) -> tuple[int, int, int]:
    """The F1 rule (``anunnaki.lec.match_image``): class-aware, IoU ≥ 0.5, ignore boxes."""
    from anunnaki.lec import DetectionResult, match_image

    names = sorted(set(det.labels) | set(truth[2]))
    index = {n: k for k, n in enumerate(names)}
    pred = DetectionResult(
        np.asarray(det.boxes, dtype=np.float32).reshape(-1, 4),
        np.asarray([index[n] for n in det.labels], dtype=np.int64),
        np.asarray(det.scores, dtype=np.float32),
    )
    labels = np.asarray([index[n] for n in truth[2]], dtype=np.int64)
    _, is_tp, n_truth = match_image(pred, truth[1], labels, iou=0.5, ignore=truth[3])
    tp = int(is_tp.sum())
    return tp, len(is_tp) - tp, n_truth - tp


def _visible_truth(
    truth: tuple[float, np.ndarray, list[str], np.ndarray], hidden: np.ndarray
) -> tuple[float, np.ndarray, list[str], np.ndarray]:
    """*truth* with the *hidden* boxes moved to its ignore boxes."""
    t, boxes, labels, ignore = truth
    kept = [lab for lab, h in zip(labels, hidden, strict=True) if not h]
    return t, boxes[~hidden], kept, np.concatenate([ignore, boxes[hidden]])


class SimulatedSystem(Closing):
    """A simulated platform with its LEC node and ground-truth oracle on one bus.

    Args:
        bus: The bus Utu's nodes are on.
        scenario: The scenario (a :class:`Scenario`, a file or a mapping).
        models: The detector's model registry (a file or a :class:`ModelRegistry`); ``None``
            runs no detector (the platform then has only its other sensors).
        oracle: The oracle's options (``name`` defaults to ``ground_truth``; the others go to
            the oracle, e.g. ``window``); ``None`` runs no oracle.
        on_time: Called with the simulation time before each physics chunk.
        stop_without_utu: Seconds a Utu node the platform has seen may be gone before it
            stops (rover) or lands (UAV) by itself (``None``: never).
        scorer: A second oracle's options, run beside the first as its live scorer (e.g.
            ``{"name": "ground_truth", "window": 30}`` beside a learned ``enlil`` oracle);
            it publishes on ``topics.SCORER`` (node ``/scorer_<name>``), which Utu does
            not read, and the report compares the two (:func:`~anunnaki.sim.compare_assessors`).
        shadow: A shadow oracle's options (``name``, the oracle's own, and ``domain`` or
            ``model``): that model's oracle on every frame whichever model is active, on
            ``topics.SHADOW_ORACLE`` (see :class:`~anunnaki.managed.CameraChain`).

    The detector, the oracle and the scorer are the camera chain every kind shares
    (:class:`~anunnaki.managed.CameraChain`): an oracle that takes what it needs from the
    detector's registry (``enlil`` its oracles, ``ground_truth`` the clean F1) gets it there.

    """

    def __init__(
        self,
        bus: Any,
        scenario: Scenario | str | Path | Mapping[str, Any],
        *,
        models: Any = None,
        oracle: Mapping[str, Any] | None = None,
        on_time: Callable[[float], object] | None = None,
        stop_without_utu: float | None = 0.2,
        scorer: Mapping[str, Any] | None = None,
        shadow: Mapping[str, Any] | None = None,
    ) -> None:
        self.bus = bus
        self.executor = getattr(bus, "executor", None)
        self.on_time = on_time
        self._lock = threading.Lock()
        self._truth: dict[int, tuple[float, np.ndarray, list[str], np.ndarray]] = {}
        self._hidden: dict[int, np.ndarray] = {}  # per frame: which boxes a phenomenon hides
        self._visible: list[tuple[float, int, int, int, int]] = []  # t, tp, fp, fn, hidden
        self._early: dict[int, Detections] = {}  # detections ahead of their truth
        self._frames: list[tuple[float, int, int, int, str]] = []  # t, tp, fp, fn, model
        self._assessments: list[tuple[float, int]] = []
        self._seqs: dict[str, list[tuple[int, int]]] = {"oracle": [], "scorer": []}
        self._seq_t: dict[int, float] = {}  # each frame's simulated time, by its seq
        self._collisions: list[float] = []
        self._closing: list[Any] = []
        self._stopping = threading.Event()
        self.landed_stop = False  # the run ended at the UAV's touch-down (until_landed)
        if isinstance(scenario, Scenario):
            sc = scenario
        else:
            from anunnaki.sim import load_scenario, parse_scenario

            sc = (
                load_scenario(scenario)
                if isinstance(scenario, str | Path)
                else parse_scenario(dict(scenario))
            )
        self.scenario = sc
        self.platform: SimPlatform
        if sc.platform == "rover":
            from anunnaki.sim import RoverSim

            self.platform = RoverSim(bus, sc, frame_hook=self._frame_hook)
        else:
            from anunnaki.sim import UavSim

            self.platform = UavSim(bus, sc, frame_hook=self._frame_hook)
        self._closing.append(self.platform)
        try:
            if stop_without_utu is not None:  # a platform stops by itself without Utu
                platform = self.platform
                self._closing.append(
                    LivelinessGuard(
                        bus,
                        lambda why: platform.run_stop(f"Utu lost: {why}"),
                        timeout=stop_without_utu,
                    )
                )
            chain = CameraChain(
                bus,
                camera=f"{self.platform.prefix}/camera/image",
                models=models,
                oracle=oracle,
                scorer=scorer,
                classes=self.platform.scene.classes,
                default_oracle="ground_truth",
                shadow=shadow,
            )
            self._closing.append(chain)
            self.chain = chain
            self.registry: Any = chain.registry
            self.lec: Any = chain.lec
            self.oracle: Any = chain.oracle
            self.scorer: Any = chain.scorer
            self.shadow: Any = chain.shadow
            # a scorer comparing the model on each frame with and without the phenomena
            # (ground_truth, reference: paired) needs the frames as rendered before them
            self.platform.publish_clean = any(
                node is not None and node.wants_clean_frames
                for node in (self.oracle, self.scorer, self.shadow)
            )
            self.detections_topic = chain.detections_topic
            self._subs = [
                bus.subscribe(topics.GROUND_TRUTH, self._on_truth, queue=256),
                bus.subscribe(self.detections_topic, self._on_detections, queue=256),
                bus.subscribe(topics.ORACLE_OUTPUT, self._on_assessment, queue=256),
            ]
            if self.scorer is not None:
                self._subs.append(bus.subscribe(topics.SCORER, self._on_scorer, queue=256))
        except BaseException:
            self.close()
            raise

    # -- what the scorer hears ---------------------------------------------------------------
    def _on_truth(self, sample: Sample) -> None:
        body = body_of(sample.message)
        try:
            seq = int(body["seq"])
            boxes = np.asarray(body.get("boxes") or [], dtype=np.float64).reshape(-1, 4)
            labels = [str(v) for v in body.get("labels") or []]
            ignore = np.asarray(body.get("ignore") or [], dtype=np.float64).reshape(-1, 4)
            t = float(body.get("t", 0.0))
            hidden = body.get("hidden")
            hidden = None if hidden is None else np.asarray(hidden, dtype=bool).reshape(-1)
            if hidden is not None and len(hidden) != len(boxes):
                raise ValueError("one hidden flag per box")
        except (KeyError, TypeError, ValueError):
            log.warning("sim: a ground-truth message without seq/boxes/labels; skipped")
            return
        with self._lock:
            self._seq_t[seq] = t
            if hidden is not None:
                self._hidden[seq] = hidden
                while len(self._hidden) > 512:
                    del self._hidden[min(self._hidden)]
            early = self._early.pop(seq, None)
            if early is not None:  # its detections came first (another subscriber's thread)
                self._score(early, (t, boxes, labels, ignore))
                return
            self._truth[seq] = (t, boxes, labels, ignore)
            while len(self._truth) > 512:
                del self._truth[min(self._truth)]

    def _on_detections(self, sample: Sample) -> None:
        det = sample.message
        if not isinstance(det, Detections):
            return
        with self._lock:
            truth = self._truth.pop(det.frame_seq, None)
            if truth is not None:
                self._score(det, truth)
            else:  # the frame's ground truth is still on its way: score it when it comes
                self._early[det.frame_seq] = det
                while len(self._early) > 512:
                    del self._early[min(self._early)]

    def _score(
        self, det: Detections, truth: tuple[float, np.ndarray, list[str], np.ndarray]
    ) -> None:
        tp, fp, fn = _match(det, truth)
        self._frames.append((truth[0], tp, fp, fn, det.model_id))
        hidden = self._hidden.pop(det.frame_seq, None)
        if hidden is not None:
            vtp, vfp, vfn = _match(det, _visible_truth(truth, hidden))
            self._visible.append((truth[0], vtp, vfp, vfn, int(hidden.sum())))

    def _on_assessment(self, sample: Sample) -> None:
        message = sample.message
        if isinstance(message, Assessment):
            with self._lock:
                self._assessments.append((self.platform.t, message.category))
                if message.frame_seq is not None:
                    self._seqs["oracle"].append((message.frame_seq, message.category))

    def _on_scorer(self, sample: Sample) -> None:
        message = sample.message
        if isinstance(message, Assessment) and message.frame_seq is not None:
            with self._lock:
                self._seqs["scorer"].append((message.frame_seq, message.category))

    def scoring(self) -> dict[str, Any] | None:
        """The oracle against its live scorer (:func:`~anunnaki.sim.compare_assessors`).

        ``None`` without a scorer. Keys of :func:`~anunnaki.sim.compare_assessors` plus the
        two assessors' names.
        """
        if self.scorer is None or self.oracle is None:
            return None
        with self._lock:
            mine, theirs = list(self._seqs["oracle"]), list(self._seqs["scorer"])
        out = compare_assessors(mine, theirs, rate=float(self.scenario.camera.rate))
        return {"oracle": self.oracle.oracle.name, "scorer": self.scorer.oracle.name, **out}

    def _frame_hook(self, sim: SimPlatform, frame: Any, image: Any) -> None:
        if self.executor is not None:  # every node takes the frame, in order, before the next
            self.executor.spin_until_idle()

    # -- running -------------------------------------------------------------------------------
    def run(
        self,
        stop: threading.Event,
        *,
        speed: float = 1.0,
        until: float | None = None,
        every: float = 1.0,
        callback: Callable[[SimPlatform], None] | None = None,
        until_landed: bool = False,
    ) -> None:
        """Run the simulation until ``stop``, ``until`` or the scenario's end.

        Args:
            stop: Set it to end the run.
            speed: Simulated seconds per wall second (0: as fast as possible).
            until: End at this simulated time (default: the scenario's duration).
            every: Call ``callback`` every this many simulated seconds.
            callback: ``callback(platform)``, e.g. to print progress.
            until_landed: End at a flying platform's touch-down after its flight
                (:meth:`~anunnaki.sim.SimPlatform.touched_down`); then
                :attr:`landed_stop` is true.

        """
        self._stopping = stop
        end = self.scenario.duration if until is None else until
        collisions = 0
        next_call = self.platform.t + every
        done = threading.Event()  # ``stop``, or the touch-down with ``until_landed``

        def tick(sim: SimPlatform) -> None:
            nonlocal collisions, next_call
            if stop.is_set():
                done.set()
            elif until_landed and sim.touched_down():
                self.landed_stop = True
                done.set()
            if executor is not None:  # the present's messages all delivered and acted on
                executor.spin_until_idle()
            if self.on_time is not None:
                self.on_time(sim.t)
            now = int(getattr(sim, "collisions", 0))
            if now > collisions:
                with self._lock:
                    self._collisions.extend([sim.t] * (now - collisions))
                collisions = now
            if callback is not None and sim.t >= next_call - 1e-9:
                next_call += every
                callback(sim)

        executor = self.executor
        if executor is not None:
            executor.bind()  # this thread delivers every message of the run
        try:
            if self.on_time is not None:
                self.on_time(self.platform.t)
            self.platform.run(done, speed=speed, until=end, every=1.0 / 40.0, callback=tick)
        finally:
            if executor is not None:
                executor.spin_until_idle()
                executor.release()

    def close(self) -> None:
        """Stop listening and close the oracle, the LEC node and the platform (idempotent)."""
        self._stopping.set()
        for sub in getattr(self, "_subs", []):
            sub.close()
        self._subs = []
        while self._closing:
            obj = self._closing.pop()
            try:
                obj.close()
            except Exception:  # best effort at shutdown; the rest still close
                log.exception("sim: closing %r failed", obj)

    # -- scoring ---------------------------------------------------------------------------------
    def _compared(self) -> list[tuple[float, int, int]]:
        """``(t, oracle, scorer)`` per frame both assessed (the last word on each frame)."""
        with self._lock:
            mine, theirs = dict(sorted(self._seqs["oracle"])), dict(sorted(self._seqs["scorer"]))
            times = dict(self._seq_t)
        both = sorted(set(mine) & set(theirs) & set(times))
        return [(times[seq], mine[seq], theirs[seq]) for seq in both]

    def phases(
        self, decisions: Iterable[Any] = (), *, until: float | None = None
    ) -> list[PhaseScore]:
        """Score the run per phase; ``decisions`` are Utu's (``t``, ``kind``, ``tactic``).

        The phases end at a UAV's touch-down (:func:`phase_spans`).
        """
        end = self.platform.t if until is None else until
        flight = self.platform.flight()
        landed = None if flight is None else flight.get("landed")
        spans = phase_spans(self.scenario, max(end, 1e-3), landed=landed)
        with self._lock:
            frames = list(self._frames)
            visible = list(self._visible)
            assessments = list(self._assessments)
            collisions = list(self._collisions)
        return score_phases(
            spans,
            frames=frames,
            visible=visible,
            assessments=assessments,
            collisions=collisions,
            decisions=decisions,
            compared=self._compared(),
        )

    def report(self, decisions: Iterable[Any] = (), *, until: float | None = None) -> RunReport:
        """The run as data: every scored frame, assessment, tactic and the phase table.

        Write it with :meth:`RunReport.write` (``--report``), draw it with
        :func:`~anunnaki.sim.plot_report` (``--plot``).
        """
        decisions = list(decisions)
        end = self.platform.t if until is None else until
        phases = self.phases(decisions, until=until)
        with self._lock:
            frames = sorted(self._frames, key=lambda f: f[0])
            assessments = list(self._assessments)
            collisions = list(self._collisions)
        return RunReport(
            name=self.scenario.name,
            platform=self.scenario.platform,
            duration=float(end),
            frames=[FrameScore(float(t), tp, fp, fn, model) for t, tp, fp, fn, model in frames],
            assessments=[(float(t), int(c)) for t, c in assessments],
            tactics=tactic_events(decisions),
            collisions=collisions,
            phases=[p.as_dict() for p in phases],
            scoring=self.scoring(),
            flight=self.platform.flight(),
        )


def format_phases(phases: Sequence[PhaseScore]) -> str:
    """A plain-text table of :meth:`SimulatedSystem.phases` (one row per phase).

    F1 is ``–`` where the phase had no ground-truth object (its TP/FP/FN say what the
    detector did there); ``F1 visible``, there when a phenomenon of the run hides objects (a
    raindrop), counts the boxes at least half hidden as ignore boxes; the ``agree`` column,
    the oracle's agreement with its live scorer over the frames both assessed, is there when
    a scorer ran.
    """
    scored = any(p.compared for p in phases)
    masked = any(p.visible[0] for p in phases)
    header: tuple[str, ...] = ("phase", "conditions", "frames", "F1")
    header += ("F1 visible",) * masked + ("TP/FP/FN", "category")
    header += ("agree",) * scored + ("models", "tactics", "coll.")
    rows: list[tuple[str, ...]] = [header]
    for p in phases:
        f1 = "–" if p.f1 is None else f"{p.f1:.2f}"
        cats = ", ".join(f"{k}×{n}" for k, n in sorted(p.categories.items())) or "-"
        agree = "-" if p.agreement is None else f"{p.agreement:.0%} of {p.compared}"
        visible = "–" if p.f1_visible is None else f"{p.f1_visible:.2f}"
        rows.append(
            (
                f"{p.start:5.1f}–{p.end:5.1f} s",
                p.label,
                str(p.frames),
                f1,
                *((visible,) * masked),
                f"{p.tp}/{p.fp}/{p.fn}",
                cats,
                *((agree,) * scored),
                ", ".join(p.models) or "-",
                ", ".join(p.tactics) or "-",
                str(p.collisions),
            )
        )
    widths = [max(len(r[i]) for r in rows) for i in range(len(header))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def format_scoring(scoring: Mapping[str, Any]) -> str:
    """One paragraph on :meth:`SimulatedSystem.scoring`: agreement and delay."""
    agreement = scoring.get("agreement")
    text = (
        f"{scoring['oracle']} vs {scoring['scorer']} (live scorer): "
        + ("no frame assessed by both" if agreement is None else f"agree on {agreement:.1%}")
        + f" of {scoring['frames']} frames"
    )
    median = scoring.get("median_delay_frames")
    if scoring.get("changes"):
        text += f"; {scoring['changes']} category changes of the scorer"
        if median is not None:
            text += (
                f", the oracle's matching change {median:+g} frames"
                f" ({scoring['median_delay_s']:+g} s) from it (median; negative: oracle first)"
            )
        if scoring.get("unmatched"):
            text += f", {scoring['unmatched']} not matched"
    return text
