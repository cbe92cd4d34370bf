"""A pedestrian encounter: does the rover, driven by a detector, stop in time.

The rover drives a straight route towards a pedestrian standing on it, ``distance`` metres
ahead, with its ultrasonic switched off (a dropout for the whole run) so that only the
camera path can stop it: frame → optional phenomenon → ``detector.detect([image])`` →
``Detections`` → the rover's :class:`~anunnaki.sim.StopRule`. Under a phenomenon that
compromises the detector, the same rover that stops on clean frames drives into the
pedestrian: the hazard Anunnaki exists to prevent (paper §4.1.4, Fig. 15).

The detector is any object with ``detect(images) -> list`` of per-image results with
``.boxes`` (``[N, 4]`` pixels ``x1, y1, x2, y2``), ``.labels`` (class indices into
:data:`~anunnaki.sim.ROVER_CLASSES`, or names) and ``.scores``. A test double may also
define ``observe_truth(frame)``: it is called with the clean frame's ground truth before
``detect`` (a real detector has no such method and never sees ground truth).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from anunnaki import topics
from anunnaki.bus import open_bus
from anunnaki.messages import Detections
from anunnaki.sim._groundtruth import Frame
from anunnaki.sim._layout import ROVER_CLASSES
from anunnaki.sim._rover import RoverSim, StopRule

__all__ = ["EncounterResult", "run_pedestrian_encounter", "to_detections"]


@dataclass(frozen=True)
class EncounterResult:
    """How a pedestrian encounter ended.

    Attributes:
        stopped: The rover came to rest before the pedestrian, warning, without touching.
        collisions: Bumper contacts with the pedestrian.
        min_distance: Closest distance between the rover's and the pedestrian's shapes (m).
        reason: What stopped the rover (``"detector"``, ``"ultrasonic"``) or ``None``.
        frames: Camera frames rendered.
        detected_frames: Frames in which the detector reported a pedestrian.
        t: Simulated seconds the encounter lasted.

    """

    stopped: bool
    collisions: int
    min_distance: float
    reason: str | None = None
    frames: int = 0
    detected_frames: int = 0
    t: float = 0.0


def _as_list(values: Any) -> list[Any]:
    if values is None:
        return []
    if hasattr(values, "detach"):  # a torch tensor
        values = values.detach().cpu().numpy()
    return list(np.asarray(values).tolist())


def to_detections(
    result: Any,
    *,
    frame_seq: int,
    width: int,
    height: int,
    classes: Sequence[str] = ROVER_CLASSES,
    model_id: str = "detector",
) -> Detections:
    """Turn one detector result (``.boxes``, ``.labels``, ``.scores``) into ``Detections``."""
    boxes = [[float(v) for v in b] for b in _as_list(getattr(result, "boxes", None))]
    labels_raw = _as_list(getattr(result, "labels", None))
    labels = [
        classes[int(v)] if not isinstance(v, str) and 0 <= int(v) < len(classes) else str(v)
        for v in labels_raw
    ]
    scores_raw = getattr(result, "scores", None)
    scores = [float(v) for v in _as_list(scores_raw)] if scores_raw is not None else []
    if not scores:
        scores = [1.0] * len(boxes)
    scores = [min(max(s, 0.0), 1.0) for s in scores]
    return Detections(
        frame_seq=frame_seq,
        model_id=str(getattr(result, "model_id", model_id)),
        width=width,
        height=height,
        boxes=boxes,
        labels=labels,
        scores=scores,
    )


def run_pedestrian_encounter(
    detector: Any,
    phenomenon: str | None = None,
    *,
    strength: float = 1.0,
    params: Mapping[str, float] | None = None,
    distance: float = 8.0,
    lateral: float = 0.0,
    speed: float = 0.8,
    layout: int = 0,
    seed: int = 0,
    width: int = 128,
    height: int = 128,
    camera_rate: float = 10.0,
    ultrasonic: bool = False,
    stop_rule: StopRule | None = None,
    max_time: float | None = None,
) -> EncounterResult:
    """Drive the rover at a pedestrian ``distance`` m ahead and report whether it stopped.

    Args:
        detector: ``detect(images) -> [result]`` (see the module docstring).
        phenomenon: A phenomenon applied to every frame (name), or ``None`` for clean frames.
        strength: Its strength in [0, 1] (``strength_params``), unless ``params`` are given.
        params: Explicit phenomenon parameters.
        distance: Initial distance from the rover's camera to the pedestrian (m).
        lateral: The pedestrian's offset from the route (m).
        speed: The rover's cruise speed (m/s).
        layout: Seeds the ground texture.
        seed: Scenario seed (phenomena noise).
        width: Camera width (pixels).
        height: Camera height (pixels).
        camera_rate: Camera (and detector) rate (Hz).
        ultrasonic: Keep the ultrasonic on (default off: only the camera path can stop it).
        stop_rule: The rover's stop rule.
        max_time: Give up after this long (default: time to reach the pedestrian + 6 s).

    Returns:
        An :class:`EncounterResult`.

    """
    scenario = _encounter_scenario(
        phenomenon,
        strength=strength,
        params=params,
        distance=distance,
        lateral=lateral,
        speed=speed,
        layout=layout,
        seed=seed,
        camera={"rate": camera_rate, "width": width, "height": height, "encoding": "jpeg"},
        ultrasonic=ultrasonic,
    )
    hook = _DetectorHook(detector, width, height)
    limit = max_time if max_time is not None else distance / max(speed, 0.05) + 6.0
    with open_bus("inproc") as bus:
        sim = RoverSim(
            bus,
            scenario,
            stop_rule=stop_rule,
            clear_layout=True,
            clock_rate=1.0,
            status_rate=1.0,
            frame_hook=hook,
            publish_ground_truth=False,
        )
        try:
            result = _drive(sim, distance=distance, limit=limit)
        finally:
            sim.close()
    return dataclasses.replace(result, detected_frames=hook.detected)


def _encounter_scenario(
    phenomenon: str | None,
    *,
    strength: float,
    params: Mapping[str, float] | None,
    distance: float,
    lateral: float,
    speed: float,
    layout: int,
    seed: int,
    camera: dict[str, Any],
    ultrasonic: bool,
) -> dict[str, Any]:
    """The scenario of :func:`run_pedestrian_encounter` (its arguments, as a scenario)."""
    phenomena: list[dict[str, Any]] = []
    if phenomenon is not None:
        event: dict[str, Any] = {"at": 0.0, "phenomenon": phenomenon}
        if params is not None:
            event["params"] = dict(params)
        else:
            event["strength"] = strength
        phenomena.append(event)
    return {
        "platform": "rover",
        "layout": layout,
        "seed": seed,
        "camera": camera,
        "route": [(0.0, 0.0), (distance + 20.0, 0.0)],
        "cruise_speed": speed,
        "objects": [{"kind": "pedestrian", "x": distance + 0.55, "y": lateral, "yaw": math.pi / 2}],
        "phenomena": phenomena,
        "faults": []
        if ultrasonic
        else [{"at": 0.0, "fault": "dropout", "sensor": "ultrasonic", "duration": 1e9}],
    }


class _DetectorHook:
    """The rover's frame hook: the detector's view of each frame, handed to the stop rule."""

    def __init__(self, detector: Any, width: int, height: int) -> None:
        self.detector = detector
        self.width = width
        self.height = height
        self.detected = 0  # frames in which the detector reported a pedestrian

    def __call__(self, sim: Any, frame: Frame, image: np.ndarray) -> None:
        observe = getattr(self.detector, "observe_truth", None)
        if callable(observe):
            observe(frame)
        results = self.detector.detect([image])
        det = to_detections(results[0], frame_seq=frame.seq, width=self.width, height=self.height)
        if "pedestrian" in det.labels:
            self.detected += 1
        sim.observe_detections(det)
        sim.bus.publish(topics.DETECTIONS, det)


def _drive(sim: RoverSim, *, distance: float, limit: float) -> EncounterResult:
    """Step ``sim`` until it rests 1 s warning, hits or passes the pedestrian, or ``limit``."""
    (pedestrian,) = list(sim.scene.objects)
    min_distance = math.inf
    rest = 0.0
    reason: str | None = None
    dt = 0.05
    while sim.t < limit:
        sim.step(dt)
        min_distance = min(min_distance, sim.distance_to(pedestrian))
        if sim.obstacle is not None:
            reason = sim.obstacle
        if sim.collisions or sim.position[0] > distance + 3.0:
            break
        rest = rest + dt if abs(sim.speed) < 0.02 and sim.warning else 0.0
        if rest >= 1.0:
            break
    return EncounterResult(
        stopped=sim.collisions == 0 and rest >= 1.0,
        collisions=sim.collisions,
        min_distance=float(max(min_distance, 0.0)),
        reason=reason,
        frames=sim.frames,
        t=sim.t,
    )
