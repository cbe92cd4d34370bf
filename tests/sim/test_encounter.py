"""The pedestrian encounter, with a detector double and with the trained default detector.

The double reports the frame's pedestrians (from the ground truth it is shown through
``observe_truth``) only when the frame's mean brightness reaches a threshold, as a detector
trained on daylight frames fails in the dark (paper Fig. 11, 15); the real detector is the
committed rover default model. The rover sees nothing but its detections.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from anunnaki.sim import Frame, run_pedestrian_encounter, to_detections


class DaylightDetector:
    """Sees pedestrians only when the frame's mean brightness is at least ``threshold``."""

    def __init__(self, threshold: float = 60.0) -> None:
        self.threshold = threshold
        self.truth: Frame | None = None
        self.calls = 0

    def observe_truth(self, frame: Frame) -> None:
        self.truth = frame

    def detect(self, images: list[np.ndarray]) -> list[SimpleNamespace]:
        out = []
        for image in images:
            self.calls += 1
            seen = self.truth is not None and float(image.mean()) >= self.threshold
            keep = self.truth.labels == 0 if seen and self.truth is not None else slice(0, 0)
            boxes = self.truth.boxes[keep] if self.truth is not None else np.zeros((0, 4))
            labels = self.truth.labels[keep] if self.truth is not None else np.zeros(0)
            out.append(SimpleNamespace(boxes=boxes, labels=labels, scores=np.full(len(boxes), 0.9)))
        return out


def test_rover_stops_on_clean_frames_and_not_in_the_dark() -> None:
    kw = {"distance": 6.0, "width": 96, "height": 72}
    clean = run_pedestrian_encounter(DaylightDetector(), None, **kw)
    assert clean.stopped and clean.collisions == 0 and clean.reason == "detector"
    assert clean.min_distance > 1.0 and clean.detected_frames > 0
    dark_detector = DaylightDetector()
    dark = run_pedestrian_encounter(dark_detector, "brightness", strength=1.0, **kw)
    assert dark_detector.calls == dark.frames > 0
    assert not dark.stopped and dark.collisions == 1 and dark.min_distance == 0.0
    assert dark.detected_frames == 0 and dark.reason is None


def test_detector_results_become_detections() -> None:
    result = SimpleNamespace(
        boxes=np.array([[1, 2, 3, 4]], dtype=np.float32), labels=np.array([1]), scores=None
    )
    det = to_detections(result, frame_seq=3, width=10, height=10)
    assert det.labels == ["deer"] and det.scores == [1.0] and det.boxes == [[1, 2, 3, 4]]


def test_the_trained_detector_stops_the_rover_but_not_in_dense_fog() -> None:
    """The real default LEC: it stops the rover on clean frames; a dense fog blinds it."""
    from pathlib import Path

    from anunnaki.lec import load_detector

    model = Path(__file__).parents[2] / "examples" / "models" / "rover-default.safetensors"
    detector = load_detector(model)
    kw = {"distance": 6.0, "width": 128, "height": 128}
    clean = run_pedestrian_encounter(detector, None, **kw)
    assert clean.stopped and clean.collisions == 0 and clean.reason == "detector", clean
    assert clean.min_distance > 0.5 and clean.detected_frames > 0
    fog = run_pedestrian_encounter(detector, "fog", params={"density": 8, "intensity": 0.3}, **kw)
    assert not fog.stopped and fog.collisions == 1 and fog.reason is None, fog
