"""Simulated platforms in pybullet (headless): scenes, datasets, a rover and a UAV on the bus.

Scenes and datasets (the API the detector's datasets are built on)::

    from anunnaki.sim import ROVER_CLASSES, dataset_frames

    for frame in dataset_frames("rover", layout=3, seed=0, n=100, width=128, height=128):
        frame.image   # [H, W, 3] uint8 RGB
        frame.boxes   # [N, 4] float32 x1, y1, x2, y2 in pixels (from the segmentation mask)
        frame.labels  # [N] int64 indices into ROVER_CLASSES ("pedestrian", "deer")

``layout`` seeds the scene (object placement), ``seed`` the camera poses, lighting, object
poses and distractor colours; use disjoint layouts for train/validation/test.

Platforms publish on the bus like the scripted stand-in (guideline H1), on simulated time::

    from anunnaki.bus import open_bus
    from anunnaki.sim import RoverSim

    with open_bus("inproc") as bus, RoverSim(bus, "examples/rover/scenario.yaml") as rover:
        rover.step(5.0)                 # deterministic: physics at 240 Hz, sensors at rate
        print(rover.status())

``RoverSim`` stops for obstacles from the detector's ``Detections`` and the ultrasonic only
(:class:`StopRule`), never from ground truth; ``UavSim`` flies a package-delivery mission.
Scenario files (:func:`load_scenario`) ramp phenomena and inject faults over time.
:func:`run_pedestrian_encounter` tells whether a detector makes the rover stop in time.
:class:`anunnaki.managed.SimulatedSystem` is the whole loop's managed system — a platform
with its detector (the model manager's LEC node) and ground-truth oracle — scored per
scenario phase (it lives in ``anunnaki.managed``: the scenes here know nothing of detectors);
its runs are kept as data here (:class:`RunReport`, JSON) and :func:`plot_report` draws them
(windowed F1 by model, the oracle's category, the tactics). :func:`make_dataset` renders
labelled datasets from the scenes.

Every scene has its own pybullet client (``DIRECT``, tiny renderer, no shadows); several
live side by side in one process or in process pools. See ``docs/simulation.md``.
"""

from anunnaki.sim._dataset import make_dataset, platform_classes, scene_frames
from anunnaki.sim._encounter import EncounterResult, run_pedestrian_encounter, to_detections
from anunnaki.sim._groundtruth import (
    MIN_BOX_SIZE,
    MIN_IN_FRAME,
    MIN_LABEL_HEIGHT,
    MIN_VISIBLE,
    Annotation,
    Frame,
    annotate_mask,
    boxes_from_mask,
)
from anunnaki.sim._layout import ROVER_CLASSES, UAV_CLASSES, Placement, Platform, layout_placements
from anunnaki.sim._platform import SimPlatform
from anunnaki.sim._report import (
    GROUND,
    FrameScore,
    RunReport,
    TacticEvent,
    compare_assessors,
    draw_report,
    f1_score,
    load_report,
    plot_report,
    require_plot_extra,
    rolling_f1,
    save_run,
    tactic_events,
)
from anunnaki.sim._rover import CAMERA_FOV, CAMERA_HEIGHT, RoverMode, RoverSim, StopRule
from anunnaki.sim._scenario import (
    CameraConfig,
    FaultEvent,
    ObjectSpec,
    PhenomenonEvent,
    Scenario,
    Timeline,
    UavMission,
    UltrasonicConfig,
    Variation,
    draw_scenario,
    load_scenario,
    parse_scenario,
)
from anunnaki.sim._scene import Scene, dataset_frames
from anunnaki.sim._uav import CAMERA_DOWN, UAV_CAMERA_FOV, UavMode, UavSim
from anunnaki.sim._world import Camera, Light

PLATFORM_MODES: dict[str, tuple[str, ...]] = {"rover": RoverSim.modes, "uav": UavSim.modes}
"""The modes each simulated platform's ``set_mode`` accepts (``anunnaki check --platform``)."""

__all__ = [
    "CAMERA_DOWN",
    "CAMERA_FOV",
    "CAMERA_HEIGHT",
    "GROUND",
    "MIN_BOX_SIZE",
    "MIN_IN_FRAME",
    "MIN_LABEL_HEIGHT",
    "MIN_VISIBLE",
    "PLATFORM_MODES",
    "ROVER_CLASSES",
    "UAV_CAMERA_FOV",
    "UAV_CLASSES",
    "Annotation",
    "Camera",
    "CameraConfig",
    "EncounterResult",
    "FaultEvent",
    "Frame",
    "FrameScore",
    "Light",
    "ObjectSpec",
    "PhenomenonEvent",
    "Placement",
    "Platform",
    "RoverMode",
    "RoverSim",
    "RunReport",
    "Scenario",
    "Scene",
    "SimPlatform",
    "StopRule",
    "TacticEvent",
    "Timeline",
    "UavMission",
    "UavMode",
    "UavSim",
    "UltrasonicConfig",
    "Variation",
    "annotate_mask",
    "boxes_from_mask",
    "compare_assessors",
    "dataset_frames",
    "draw_report",
    "draw_scenario",
    "f1_score",
    "layout_placements",
    "load_report",
    "load_scenario",
    "make_dataset",
    "parse_scenario",
    "platform_classes",
    "plot_report",
    "require_plot_extra",
    "rolling_f1",
    "run_pedestrian_encounter",
    "save_run",
    "scene_frames",
    "tactic_events",
    "to_detections",
]
