"""The ground-truth assessor's rule, and the simulator messages it reads."""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from anunnaki.lec import DetectionResult, ModelRegistry
from anunnaki.messages import Detections
from anunnaki.oracles import (
    GroundTruthAssessor,
    ObservesCleanFrames,
    OracleError,
    WindowMetrics,
    category_for_drop,
    context_from_phenomena,
    truth_from_message,
)

BOX = [10.0, 10.0, 30.0, 30.0]
FRAME = np.zeros((40, 40, 3), np.uint8)


def dets(seq: int, boxes: list[list[float]], labels: list[str], model: str = "m") -> Detections:
    return Detections(
        frame_seq=seq, model_id=model, width=40, height=40, boxes=boxes, labels=labels,
        scores=[0.9] * len(boxes),
    )  # fmt: skip


def feed(a: GroundTruthAssessor, seq: int, found: bool, model: str = "m") -> None:
    a.observe_ground_truth(seq, np.array([BOX]), ["car"])
    a.observe_detections(dets(seq, [BOX] if found else [], ["car"] if found else [], model))


@pytest.mark.parametrize(
    ("drop", "category"),
    [(0.0, 0), (0.05, 0), (0.0501, 1), (0.10, 1), (0.1001, 2), (1.0, 2)],
)
def test_the_papers_thresholds(drop: float, category: int) -> None:
    assert category_for_drop(drop) == category


def test_thresholds_are_configuration() -> None:
    assert category_for_drop(0.15, (0.2, 0.3)) == 0
    assert category_for_drop(0.25, (0.2, 0.3)) == 1
    assert category_for_drop(0.35, (0.2, 0.3)) == 2


@pytest.mark.parametrize(("missed", "category"), [(0, 0), (1, 0), (2, 1), (3, 1), (4, 2)])
def test_category_from_the_window_f1(missed: int, category: int) -> None:
    """20 frames of one object each; F1 = 2 tp / (2 tp + fn); clean F1 = 1.0."""
    a = GroundTruthAssessor(clean_f1=1.0, window=20)
    for seq in range(20):
        feed(a, seq, found=seq >= missed)
    result = a.assess(FRAME, seq=20, model_id="m")
    assert result is not None and result.category == category
    f1 = 2 * (20 - missed) / (2 * (20 - missed) + missed)
    assert a.metrics() == WindowMetrics("m", 20, 20 - missed, 0, missed, pytest.approx(f1))
    assert result.confidence == 1.0 and result.assessor == "ground_truth"
    assert (result.frame_seq, result.model_id, result.context) == (20, "m", {})


def test_relative_to_the_models_clean_f1() -> None:
    a = GroundTruthAssessor(clean_f1=0.9, window=10)
    for seq in range(10):  # F1 = 2*9 / (2*9 + 1) = 0.947 > 0.9: better than clean
        feed(a, seq, found=seq != 0)
    result = a.assess(FRAME, seq=10, model_id="m")
    assert result is not None and result.category == 0


def test_false_positives_count_too() -> None:
    a = GroundTruthAssessor(clean_f1=1.0, window=4, min_frames=1)
    a.observe_ground_truth(0, np.zeros((0, 4)), [])
    a.observe_detections(dets(0, [BOX], ["car"]))
    assert a.metrics() == WindowMetrics("m", 1, 0, 1, 0, 0.0)
    a.observe_ground_truth(1, np.zeros((0, 4)), [])
    a.observe_detections(dets(1, [], []))  # nothing to find, nothing found: F1 1 for it
    assert a.metrics() == WindowMetrics("m", 2, 0, 1, 0, 0.0)


def test_detections_on_ignore_boxes_count_neither_way() -> None:
    # Frame 0: a detection on an object the simulator saw but did not label (an ignore box)
    # is no false positive; frame 1: the same detection without the ignore box is one. The
    # detections may arrive first: the ignore boxes wait with the truth.
    far = [32.0, 2.0, 36.0, 12.0]
    a = GroundTruthAssessor(clean_f1=1.0, window=4, min_frames=1)
    a.observe_detections(dets(0, [BOX, far], ["car", "car"]))
    a.observe_ground_truth(0, np.array([BOX]), ["car"], ignore=np.array([far]))
    assert a.metrics() == WindowMetrics("m", 1, 1, 0, 0, 1.0)
    a.observe_ground_truth(1, np.array([BOX]), ["car"])
    a.observe_detections(dets(1, [BOX, far], ["car", "car"]))
    assert a.metrics() == WindowMetrics("m", 2, 2, 1, 0, 0.8)


def test_window_slides_and_confidence_grows() -> None:
    a = GroundTruthAssessor(clean_f1=1.0, window=10, min_frames=4)
    confidences = []
    for seq in range(30):
        feed(a, seq, found=seq < 10 or seq >= 20)  # missed 10..19
        result = a.assess(FRAME, seq=seq, model_id="m")
        confidences.append(None if result is None else result.confidence)
        if seq == 19:
            assert result is not None and result.category == 2
    assert (
        confidences[:3] == [None] * 3 and confidences[3] == 0.4 and confidences[9:12] == [1.0] * 3
    )
    final = a.assess(FRAME, seq=30, model_id="m")
    assert final is not None and final.category == 0  # the misses slid out


def test_too_few_objects_show_no_drop() -> None:
    """With min_objects, a window of a handful of objects is not believed (low confidence)."""
    a = GroundTruthAssessor(clean_f1=1.0, window=10, min_frames=1, min_objects=8)
    for seq in range(10):  # ten frames: objects in four, one of them missed, six empty
        if seq < 4:
            feed(a, seq, found=seq != 2)
        else:
            a.observe_ground_truth(seq, np.zeros((0, 4)), [])
            a.observe_detections(dets(seq, [], []))
    few = a.assess(FRAME, seq=9, model_id="m")
    assert few is not None and few.category == 0 and few.confidence == pytest.approx(4 / 8)
    plain = GroundTruthAssessor(clean_f1=1.0, window=10, min_frames=1)
    for seq in range(4):
        feed(plain, seq, found=seq != 2)
    believed = plain.assess(FRAME, seq=3, model_id="m")
    assert believed is not None and believed.category == 2  # F1 0.857: a 14 % drop
    for seq in range(10, 20):  # enough objects: the misses count again
        feed(a, seq, found=seq % 2 == 0)
    many = a.assess(FRAME, seq=19, model_id="m")
    assert many is not None and many.category == 2 and many.confidence == 1.0


def test_sparse_withhold_says_nothing_without_evidence() -> None:
    """A live scorer (``sparse: withhold``) says nothing for a window of too few objects,
    rather than "no impact" (the UAV demo's scorer counted 255 frames on the ground, with no
    one in view, as agreeing with the oracle); with enough objects it assesses as before."""
    a = GroundTruthAssessor(clean_f1=1.0, window=10, min_frames=1, min_objects=8, sparse="withhold")
    for seq in range(10):  # objects in four frames, one of them missed, six empty
        if seq < 4:
            feed(a, seq, found=seq != 2)
        else:
            a.observe_ground_truth(seq, np.zeros((0, 4)), [])
            a.observe_detections(dets(seq, [], []))
    assert a.assess(FRAME, seq=9, model_id="m") is None
    for seq in range(10, 20):
        feed(a, seq, found=seq % 2 == 0)
    many = a.assess(FRAME, seq=19, model_id="m")
    assert many is not None and many.category == 2 and many.confidence == 1.0


class Seen:
    """A detector that finds the object in a frame whose first pixel is 1 (a clean render)."""

    classes = ("car",)
    domain = "default"

    def __init__(self, model_id: str) -> None:
        self.model_id = model_id
        self.frames = 0

    def detect(self, images: Any) -> list[DetectionResult]:
        self.frames += len(images)
        found = [int(image[0, 0, 0] == 1) for image in images]
        return [DetectionResult(np.array([BOX] * n), [0] * n, [0.9] * n) for n in found]


def clean_frame(found: bool) -> np.ndarray:
    frame = np.zeros((40, 40, 3), np.uint8)
    frame[0, 0, 0] = int(found)
    return frame


def paired(**options: Any) -> tuple[GroundTruthAssessor, dict[str, Seen]]:
    loaded: dict[str, Seen] = {}

    def load(model_id: str) -> Seen:
        loaded[model_id] = Seen(model_id)
        return loaded[model_id]

    return GroundTruthAssessor(reference="paired", models=load, **options), loaded


def test_paired_reference_is_the_same_frames_rendered_clean() -> None:
    """The UAV demo's case: uav-fog scores 0.894 on its test split (the registry's clean F1)
    and 0.95 on the flight's frames without fog. 20 frames of one object each, the model
    finds every one on the clean renders and misses 4 in the fog: F1 0.889. Against the
    registry the drop is 0.6 % ("no impact"); against the same frames clean it is 11 %."""
    registry = GroundTruthAssessor(clean_f1=0.894, window=20)
    scorer, loaded = paired(clean_f1=0.894, window=20)
    for seq in range(20):
        scorer.observe_clean_frame(seq, clean_frame(found=True))
        for a in (registry, scorer):
            feed(a, seq, found=seq >= 4)
    before = registry.assess(FRAME, seq=20, model_id="m")
    after = scorer.assess(FRAME, seq=20, model_id="m")
    assert before is not None and before.category == 0
    assert after is not None and after.category == 2
    window = scorer.metrics()
    assert window is not None and window.clean_f1 == 1.0
    assert window.f1 == pytest.approx(2 * 16 / (2 * 16 + 4))
    assert list(loaded) == ["m"] and loaded["m"].frames == 20  # loaded once, run per frame


def test_paired_reference_forgives_what_the_model_misses_anyway() -> None:
    """A miss on the clean render too is not the phenomenon's doing: the same 4 misses in
    both, no drop (against a clean F1 of 1.0 it would be 11 %, compromised)."""
    scorer, _ = paired(clean_f1=1.0, window=20)
    for seq in range(20):
        scorer.observe_clean_frame(seq, clean_frame(found=seq >= 4))
        feed(scorer, seq, found=seq >= 4)
    result = scorer.assess(FRAME, seq=20, model_id="m")
    assert result is not None and result.category == 0
    window = scorer.metrics()
    assert window is not None and window.clean_f1 == window.f1


def test_paired_frames_wait_for_their_clean_render_in_any_order() -> None:
    """A frame is scored once its truth, detections and clean render are all in, whichever
    comes last; each model is run on the clean renders of its own frames."""
    scorer, loaded = paired(window=10, min_frames=1)
    feed(scorer, 0, found=False, model="a")
    assert scorer.metrics() is None  # no clean render yet
    scorer.observe_clean_frame(0, clean_frame(found=True))
    assert scorer.metrics() == WindowMetrics("a", 1, 0, 0, 1, 0.0, 1.0)
    scorer.observe_clean_frame(1, clean_frame(found=False))  # the render first
    scorer.observe_ground_truth(1, np.array([BOX]), ["car"])
    scorer.observe_detections(dets(1, [BOX], ["car"], model="b"))  # a swap
    assert scorer.metrics() == WindowMetrics("b", 1, 1, 0, 0, 1.0, 0.0)
    assert sorted(loaded) == ["a", "b"]
    result = scorer.assess(FRAME, seq=1, model_id="b")  # found nothing even clean: no drop
    assert result is not None and result.category == 0


def test_a_frame_without_phenomena_is_not_run_again() -> None:
    """As a simulated run delivers a frame (its clean render, the camera frame, the truth,
    the detections): when the camera frame is its clean render pixel for pixel, the
    detections the model published for it are its clean run, and the model is not run a
    second time; a frame the phenomena changed is run on its clean render as before."""
    scorer, loaded = paired(window=10, min_frames=1)
    for seq, perturbed in enumerate([False, True, False]):
        clean = clean_frame(found=True)
        camera = clean_frame(found=not perturbed)  # the phenomena hid the object
        scorer.observe_clean_frame(seq, clean)
        scorer.assess(camera, seq=seq, model_id="m")
        feed(scorer, seq, found=not perturbed)
    window = scorer.metrics()
    assert window == WindowMetrics("m", 3, 2, 0, 1, 0.8, 1.0)
    assert loaded["m"].frames == 1  # the perturbed frame's clean render only


def test_a_paired_scorer_asks_for_clean_frames() -> None:
    scorer, _ = paired()
    assert isinstance(scorer, ObservesCleanFrames) and scorer.clean_frames is True
    plain = GroundTruthAssessor(clean_f1=1.0)
    assert plain.clean_frames is False  # the node sends it none
    plain.observe_clean_frame(0, clean_frame(found=True))  # and would ignore them
    feed(plain, 0, found=True)
    assert plain.metrics() == WindowMetrics("m", 1, 1, 0, 0, 1.0)


def test_a_model_change_starts_a_fresh_window() -> None:
    a = GroundTruthAssessor(clean_f1={"old": 1.0, "new": 1.0}, window=10, min_frames=3)
    for seq in range(10):
        feed(a, seq, found=False, model="old")
    old = a.assess(FRAME, seq=9, model_id="old")
    assert old is not None and old.category == 2
    assert a.assess(FRAME, seq=9, model_id="new") is None  # the window is about "old"
    for seq in range(10, 13):
        feed(a, seq, found=True, model="new")
    new = a.assess(FRAME, seq=12, model_id="new")
    assert new is not None and new.category == 0 and new.confidence == pytest.approx(0.3)
    assert a.assess(FRAME, seq=12, model_id="old") is None


def test_matched_by_sequence_number_in_any_arrival_order() -> None:
    a = GroundTruthAssessor(clean_f1=1.0, window=5, min_frames=1)
    a.observe_detections(dets(2, [BOX], ["car"]))  # detections first
    a.observe_ground_truth(1, np.array([BOX]), ["car"])
    a.observe_ground_truth(2, np.array([BOX]), ["car"])
    assert a.metrics() == WindowMetrics("m", 1, 1, 0, 0, 1.0)
    a.observe_detections(dets(1, [], []))
    assert a.metrics() == WindowMetrics("m", 2, 1, 0, 1, pytest.approx(2 / 3))


def test_matching_is_class_aware_and_needs_iou() -> None:
    a = GroundTruthAssessor(clean_f1=1.0, window=5, min_frames=1)
    a.observe_ground_truth(0, np.array([BOX]), ["person"])
    a.observe_detections(dets(0, [BOX], ["car"]))  # the right box, the wrong class
    assert a.metrics() == WindowMetrics("m", 1, 0, 1, 1, 0.0)
    b = GroundTruthAssessor(clean_f1=1.0, window=5, min_frames=1)
    b.observe_ground_truth(0, np.array([BOX]), None)  # class names unknown: agnostic
    b.observe_detections(dets(0, [BOX], ["car"]))
    assert b.metrics() == WindowMetrics("m", 1, 1, 0, 0, 1.0)
    c = GroundTruthAssessor(clean_f1=1.0, window=5, min_frames=1)
    c.observe_ground_truth(0, np.array([BOX]), ["car"])
    c.observe_detections(dets(0, [[20.0, 10.0, 40.0, 30.0]], ["car"]))  # IoU 1/3
    assert c.metrics() == WindowMetrics("m", 1, 0, 1, 1, 0.0)
    d = GroundTruthAssessor(clean_f1=1.0, window=5, min_frames=1, iou=0.3)
    d.observe_ground_truth(0, np.array([BOX]), ["car"])
    d.observe_detections(dets(0, [[20.0, 10.0, 40.0, 30.0]], ["car"]))
    assert d.metrics() == WindowMetrics("m", 1, 1, 0, 0, 1.0)


def test_score_threshold_drops_weak_detections() -> None:
    a = GroundTruthAssessor(clean_f1=1.0, window=5, min_frames=1, score_threshold=0.95)
    feed(a, 0, found=True)  # scored 0.9
    assert a.metrics() == WindowMetrics("m", 1, 0, 0, 1, 0.0)


def test_clean_f1_sources(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    registry = ModelRegistry(
        [{"id": "m", "domain": "default", "file": tmp_path / "m", "metrics": {"f1": 0.8}}]
    )
    assert GroundTruthAssessor(clean_f1=registry.clean_f1).clean_f1("m") == 0.8
    given = GroundTruthAssessor.options_from_models(registry)  # a launch's camera chain
    assert given == {"clean_f1": registry.clean_f1, "models": registry}
    assert GroundTruthAssessor(clean_f1={"m": 0.7}).clean_f1("m") == 0.7
    assert GroundTruthAssessor(clean_f1=0.6).clean_f1("x") == 0.6
    for bad in (None, 0.0, math.nan, True, {"other": 0.5}, lambda m: None):
        assert GroundTruthAssessor(clean_f1=bad).clean_f1("m") is None  # type: ignore[arg-type]
    a = GroundTruthAssessor(window=3)
    for seq in range(3):
        feed(a, seq, found=True)
    with caplog.at_level(logging.WARNING, logger="anunnaki.oracles"):
        assert a.assess(FRAME, seq=3, model_id="m") is None
        assert a.assess(FRAME, seq=4, model_id="m") is None
    assert caplog.text.count("no clean F1 for model 'm'") == 1


def test_context_is_the_phenomena_ground_truth() -> None:
    a = GroundTruthAssessor(clean_f1=1.0, window=2, min_frames=1)
    feed(a, 0, found=True)
    a.observe_context(context_from_phenomena({"phenomenon": "fog", "params": {"density": 4}}))
    result = a.assess(FRAME, seq=0, model_id="m")
    assert result is not None
    assert result.context == {"phenomenon": "fog", "params": {"density": 4}}


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"window": 0}, "window must be"),
        ({"window": 5, "min_frames": 6}, "min_frames must be"),
        ({"thresholds": (0.1, 0.05)}, "thresholds must be"),
        ({"iou": 0.0}, "iou must be"),
        ({"min_objects": -1}, "min_objects must be"),
        ({"sparse": "drop"}, "sparse must be 'nominal'"),
        ({"reference": "test"}, "reference must be 'clean_f1'"),
        ({"reference": "paired"}, "reference 'paired' runs the assessed model"),
    ],
)
def test_bad_options_are_refused(options: dict[str, Any], message: str) -> None:
    with pytest.raises(OracleError, match=message):
        GroundTruthAssessor(**options)


def test_mismatched_truth_is_refused() -> None:
    with pytest.raises(OracleError, match="2 boxes but 1 labels"):
        GroundTruthAssessor().observe_ground_truth(0, np.array([BOX, BOX]), ["car"])


# -- simulator messages -------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("message", "context"),
    [
        ({"phenomenon": "fog", "params": {"density": 4}},
         {"phenomenon": "fog", "params": {"density": 4}}),
        ({"name": "raindrop", "params": {"x": 0.5, "bad": [1]}},
         {"phenomenon": "raindrop", "params": {"x": 0.5}}),
        ({"phenomena": [{"name": "fog", "params": {"density": 2}}, "raindrop"]},
         {"phenomenon": "fog+raindrop", "params": {"fog": {"density": 2}, "raindrop": {}}}),
        ({"active": ["hsl"], "strength": 0.4},
         {"phenomenon": "hsl", "params": {}, "strength": 0.4}),
        ({"phenomenon": None}, {"phenomenon": "clear", "params": {}}),
        ({"phenomena": []}, {"phenomenon": "clear", "params": {}}),
        ({"phenomenon": "clear"}, {"phenomenon": "clear", "params": {}}),
        ({"phenomena": ["none", ""]}, {"phenomenon": "clear", "params": {}}),
        ({}, {"phenomenon": "clear", "params": {}}),
    ],
)  # fmt: skip
def test_context_from_phenomena(message: dict[str, Any], context: dict[str, Any]) -> None:
    assert context_from_phenomena(message) == context


def test_truth_from_message() -> None:
    seq, boxes, names = truth_from_message({"seq": 3, "boxes": [BOX], "labels": ["car"]})
    assert seq == 3 and boxes.shape == (1, 4) and names == ["car"]
    _, _, names = truth_from_message({"seq": 3, "boxes": [BOX, BOX], "labels": [1, 0]},
                                     ("person", "car"))  # fmt: skip
    assert names == ["car", "person"]
    _, _, names = truth_from_message(
        {"seq": 3, "boxes": [BOX], "labels": [0], "classes": ["deer"]}, ("person",)
    )
    assert names == ["deer"]  # the message's own classes first
    assert truth_from_message({"seq": 3, "boxes": [BOX], "labels": [0]})[2] is None
    assert truth_from_message({"seq": 3, "boxes": [BOX], "labels": [5]}, ("a",))[2] is None
    _, empty, names = truth_from_message({"seq": 0, "boxes": [], "labels": []})
    assert empty.shape == (0, 4) and names == []
    for bad, message in [
        ({"boxes": [], "labels": []}, "needs 'seq'"),
        ({"seq": True, "boxes": [], "labels": []}, "needs 'seq'"),
        ({"seq": 1, "boxes": [[1, 2, 3]], "labels": ["a"]}, r"\[N, 4\]"),
        ({"seq": 1, "boxes": [BOX], "labels": []}, "one label per box"),
        ({"seq": 1, "boxes": [BOX], "labels": [1.5]}, "names or indices"),
    ]:
        with pytest.raises(ValueError, match=message):
            truth_from_message(bad)
