"""The F1 rule against hand-made cases, and the threshold choice."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from anunnaki.lec import (
    DetectionResult,
    DetectorError,
    Metrics,
    box_iou,
    choose_threshold,
    f1_at_iou,
)
from anunnaki.lec._metrics import box_ioa, match_image

T = (np.array([[0, 0, 10, 10]], np.float32), np.array([0]))  # one truth of class 0


def det(*rows: tuple[float, float, float, float, int, float]) -> DetectionResult:
    """Detections from (x1, y1, x2, y2, label, score) rows."""
    if not rows:
        return DetectionResult.empty()
    a = np.array(rows, np.float64)
    return DetectionResult(a[:, :4], a[:, 4].astype(np.int64), a[:, 5])


def test_perfect() -> None:
    m = f1_at_iou([det((0, 0, 10, 10, 0, 0.9))], [T], score_threshold=0.5)
    assert m == Metrics(1.0, 1.0, 1.0, 1, 0, 0)


def test_missed() -> None:
    m = f1_at_iou([det()], [T], score_threshold=0.5)
    assert (m.tp, m.fp, m.fn) == (0, 0, 1)
    assert (m.precision, m.recall, m.f1) == (0.0, 0.0, 0.0)


def test_below_threshold_is_missed() -> None:
    m = f1_at_iou([det((0, 0, 10, 10, 0, 0.3))], [T], score_threshold=0.5)
    assert (m.tp, m.fp, m.fn) == (0, 0, 1)


def test_false_positive() -> None:
    m = f1_at_iou([det((0, 0, 10, 10, 0, 0.9), (50, 50, 60, 60, 0, 0.8))], [T], score_threshold=0.5)
    assert (m.tp, m.fp, m.fn) == (1, 1, 0)
    assert m.precision == 0.5 and m.recall == 1.0 and m.f1 == pytest.approx(2 / 3)


def test_wrong_class_is_fp_and_fn() -> None:
    m = f1_at_iou([det((0, 0, 10, 10, 1, 0.9))], [T], score_threshold=0.5)
    assert (m.tp, m.fp, m.fn) == (0, 1, 1)


def test_iou_exactly_half_matches_just_below_does_not() -> None:
    at = det((0, 0, 10, 5, 0, 0.9))  # IoU = 50 / 100 = 0.5 exactly
    below = det((0, 0, 10, 4.99, 0, 0.9))
    assert box_iou(at.boxes, T[0])[0, 0] == 0.5
    assert f1_at_iou([at], [T], score_threshold=0.0).tp == 1
    assert f1_at_iou([below], [T], score_threshold=0.0).tp == 0
    above = det((0, 0, 10, 5.01, 0, 0.9))
    assert f1_at_iou([above], [T], score_threshold=0.0).tp == 1
    assert f1_at_iou([above], [T], score_threshold=0.0, iou=0.75).tp == 0


def test_each_truth_matched_once_highest_score_first() -> None:
    # Two detections on one truth: the higher score is the TP, the other a duplicate FP.
    preds = det((1, 1, 10, 10, 0, 0.6), (0, 0, 10, 10, 0, 0.9))
    m = f1_at_iou([preds], [T], score_threshold=0.0)
    assert (m.tp, m.fp, m.fn) == (1, 1, 0)


def test_greedy_takes_best_iou_among_unmatched_truths() -> None:
    truths = (np.array([[0, 0, 10, 10], [4, 0, 14, 10]], np.float32), np.array([0, 0]))
    preds = det((4, 0, 14, 10, 0, 0.9), (0, 0, 10, 10, 0, 0.8))
    m = f1_at_iou([preds], [truths], score_threshold=0.0)
    assert (m.tp, m.fp, m.fn) == (2, 0, 0)


def test_counts_sum_over_images_and_empty_cases() -> None:
    empty_truth = (np.zeros((0, 4)), np.zeros(0))
    m = f1_at_iou([det(), det((0, 0, 10, 10, 0, 0.9))], [empty_truth, T], score_threshold=0.5)
    assert m == Metrics(1.0, 1.0, 1.0, 1, 0, 0)
    nothing = f1_at_iou([det()], [empty_truth], score_threshold=0.5)
    assert (nothing.precision, nothing.recall, nothing.f1) == (1.0, 1.0, 1.0)


def test_length_mismatch_is_refused() -> None:
    with pytest.raises(DetectorError, match="one per image"):
        f1_at_iou([det()], [T, T], score_threshold=0.5)
    with pytest.raises(DetectorError, match="1 boxes but 2 labels"):
        f1_at_iou([det()], [(T[0], np.array([0, 1]))], score_threshold=0.5)


def test_detection_result_validates() -> None:
    with pytest.raises(DetectorError, match="one label and one score per box"):
        DetectionResult(np.zeros((2, 4)), np.zeros(1), np.zeros(2))
    r = DetectionResult([[0, 0, 1, 1]], [1], [0.5])
    assert r.boxes.dtype == np.float32 and r.labels.dtype == np.int64 and len(r) == 1


def test_choose_threshold_maximises_f1() -> None:
    # Scores 0.9 (TP), 0.7 (FP), 0.5 (TP), 0.2 (FP); two truths.
    truths = (np.array([[0, 0, 10, 10], [20, 20, 30, 30]], np.float32), np.array([0, 0]))
    preds = det(
        (0, 0, 10, 10, 0, 0.9),
        (50, 50, 60, 60, 0, 0.7),
        (20, 20, 30, 30, 0, 0.5),
        (70, 70, 80, 80, 0, 0.2),
    )
    thr = choose_threshold([preds], [truths])
    # Keeping >= 0.5 gives tp 2, fp 1 (F1 0.8); >= 0.9 gives 0.667; all gives 0.667.
    assert 0.2 < thr <= 0.5
    assert thr == pytest.approx(0.35)
    assert f1_at_iou([preds], [truths], score_threshold=thr).f1 == pytest.approx(0.8)


def test_choose_threshold_edge_cases() -> None:
    assert choose_threshold([det()], [T]) == 0.5
    empty = (np.zeros((0, 4)), np.zeros(0))
    thr = choose_threshold([det((0, 0, 1, 1, 0, 0.4))], [empty])
    assert thr > 0.4  # nothing to find: keep nothing
    # Ties go to the higher threshold: one TP at 0.9 and nothing else scores the same F1
    # as adding a TP + FP pair... here adding only an FP lowers F1, so 0.9 is kept alone.
    thr = choose_threshold([det((0, 0, 10, 10, 0, 0.9), (50, 50, 60, 60, 0, 0.8))], [T])
    assert 0.8 < thr <= 0.9


# -- ignore boxes (objects seen but not labelled) ----------------------------------------------

IGN = np.array([[20, 20, 30, 40]], np.float32)  # an ignore box, 10 x 20 px
TI = (*T, IGN)  # one truth of class 0 and one ignore box


def test_a_detection_mostly_inside_an_ignore_box_counts_neither_way() -> None:
    inside = det((0, 0, 10, 10, 0, 0.9), (21, 22, 29, 38, 1, 0.8))  # any class
    assert f1_at_iou([inside], [TI], score_threshold=0.5) == Metrics(1.0, 1.0, 1.0, 1, 0, 0)
    # The same detection without the ignore box is a false positive.
    m = f1_at_iou([inside], [T], score_threshold=0.5)
    assert (m.tp, m.fp, m.fn) == (1, 1, 0)


def test_half_inside_is_ignored_just_under_half_is_a_false_positive() -> None:
    half = det((25, 20, 35, 40, 0, 0.9))  # 5 x 20 of its 10 x 20 inside: IoA 0.5
    under = det((25.01, 20, 35.01, 40, 0, 0.9))
    assert box_ioa(half.boxes, IGN)[0, 0] == 0.5
    assert (f1_at_iou([half], [TI], score_threshold=0.0).fp) == 0
    assert (f1_at_iou([under], [TI], score_threshold=0.0).fp) == 1
    # Intersection over the *prediction*: a huge box covering the ignore box is not ignored.
    big = det((0, 0, 100, 100, 0, 0.9))
    assert box_iou(big.boxes, IGN)[0, 0] < 0.5 and f1_at_iou([big], [TI], score_threshold=0).fp


def test_truths_are_matched_before_ignore_boxes() -> None:
    # A truth lying inside an ignore box is still found; a duplicate on it is then ignored
    # (it is mostly inside the ignore box), a duplicate elsewhere is not.
    truth = (np.array([[20, 20, 30, 40]], np.float32), np.array([0]), IGN)
    preds = det((20, 20, 30, 40, 0, 0.9), (21, 21, 30, 40, 0, 0.8), (60, 60, 70, 70, 0, 0.7))
    m = f1_at_iou([preds], [truth], score_threshold=0.0)
    assert (m.tp, m.fp, m.fn) == (1, 1, 0)
    scores, is_tp, n = match_image(preds, truth[0], truth[1], iou=0.5, ignore=IGN)
    assert scores.tolist() == pytest.approx([0.9, 0.7]) and is_tp.tolist() == [True, False]
    assert n == 1


def test_ignored_objects_are_never_missed() -> None:
    only_ignore = (np.zeros((0, 4)), np.zeros(0), IGN)
    m = f1_at_iou([det()], [only_ignore], score_threshold=0.5)
    assert (m.tp, m.fp, m.fn) == (0, 0, 0) and m.f1 == 1.0


def test_a_truth_needs_two_or_three_parts() -> None:
    with pytest.raises(DetectorError, match=r"\(boxes, labels\) or \(boxes, labels, ignore\)"):
        f1_at_iou([det()], [(T[0],)], score_threshold=0.5)  # type: ignore[list-item]


def test_choose_threshold_is_not_pulled_by_ignored_detections() -> None:
    # Two confident detections on an unlabelled object between two true positives: counted
    # as false positives they make the threshold drop the weaker true positive; ignored,
    # it keeps both.
    truths = (np.array([[0, 0, 10, 10], [40, 0, 50, 10]], np.float32), np.array([0, 0]))
    preds = det(
        (0, 0, 10, 10, 0, 0.9),
        (21, 22, 29, 38, 0, 0.7),
        (22, 21, 28, 39, 1, 0.6),
        (40, 0, 50, 10, 0, 0.5),
    )
    assert choose_threshold([preds], [truths]) == pytest.approx(0.8)
    thr = choose_threshold([preds], [(*truths, IGN)])
    assert thr == pytest.approx(0.25)
    assert f1_at_iou([preds], [(*truths, IGN)], score_threshold=thr).f1 == 1.0


boxes_st = st.lists(
    st.tuples(
        st.floats(0, 50), st.floats(0, 50), st.floats(1, 30), st.floats(1, 30),
        st.integers(0, 1), st.floats(0, 1),
    ),
    max_size=6,
)  # fmt: skip


@settings(max_examples=60, deadline=None)
@given(pred_rows=boxes_st, truth_rows=boxes_st, thr=st.floats(0, 1))
def test_counts_are_consistent(pred_rows: list, truth_rows: list, thr: float) -> None:
    preds = det(*[(x, y, x + w, y + h, c, s) for x, y, w, h, c, s in pred_rows])
    truth = (
        np.array([(x, y, x + w, y + h) for x, y, w, h, _, _ in truth_rows], np.float32),
        np.array([c for *_, c, _ in truth_rows], np.int64),
    )
    m = f1_at_iou([preds], [truth], score_threshold=thr)
    kept = int((preds.scores >= thr).sum())
    assert m.tp + m.fp == kept and m.tp + m.fn == len(truth_rows)
    assert 0.0 <= m.f1 <= 1.0
    best = choose_threshold([preds], [truth])
    best_f1 = f1_at_iou([preds], [truth], score_threshold=best).f1
    assert best_f1 >= m.f1 - 1e-12  # no threshold beats the chosen one


@settings(max_examples=60, deadline=None)
@given(pred_rows=boxes_st, truth_rows=boxes_st, ignore_rows=boxes_st, thr=st.floats(0, 1))
def test_ignore_boxes_only_ever_remove_false_positives(
    pred_rows: list, truth_rows: list, ignore_rows: list, thr: float
) -> None:
    preds = det(*[(x, y, x + w, y + h, c, s) for x, y, w, h, c, s in pred_rows])
    boxes = np.array([(x, y, x + w, y + h) for x, y, w, h, _, _ in truth_rows], np.float32)
    labels = np.array([c for *_, c, _ in truth_rows], np.int64)
    ignore = np.array([(x, y, x + w, y + h) for x, y, w, h, _, _ in ignore_rows], np.float32)
    plain = f1_at_iou([preds], [(boxes, labels)], score_threshold=thr)
    with_ignore = f1_at_iou([preds], [(boxes, labels, ignore)], score_threshold=thr)
    assert (with_ignore.tp, with_ignore.fn) == (plain.tp, plain.fn)
    assert with_ignore.fp <= plain.fp
    assert with_ignore.f1 >= plain.f1 - 1e-12
    empty = f1_at_iou([preds], [(boxes, labels, np.zeros((0, 4)))], score_threshold=thr)
    assert empty == plain
    best = choose_threshold([preds], [(boxes, labels, ignore)])
    best_f1 = f1_at_iou([preds], [(boxes, labels, ignore)], score_threshold=best).f1
    assert best_f1 >= with_ignore.f1 - 1e-12


def test_evaluate_detector_matches_classes_by_name_not_index() -> None:
    from anunnaki.datasets import Dataset
    from anunnaki.lec import DetectionResult, DetectorError, evaluate_detector

    image = np.zeros((32, 32, 3), np.uint8)
    data = Dataset.from_arrays(
        [image], [np.array([[2, 2, 12, 12]], np.float32)], [np.array([1])], ("deer", "pedestrian")
    )

    class Det:
        model_id, domain, score_threshold = "d", "default", 0.5

        def __init__(self, classes: tuple[str, ...]) -> None:
            self.classes = classes

        def detect(self, images: Any) -> list[DetectionResult]:
            box = np.array([[2, 2, 12, 12]], np.float32)  # a pedestrian, by its own index 0
            label = self.classes.index("pedestrian")
            return [DetectionResult(box, np.array([label]), np.array([0.9], np.float32))]

    assert evaluate_detector(Det(("pedestrian", "deer")), data).f1 == 1.0  # reordered: mapped
    assert evaluate_detector(Det(("deer", "pedestrian")), data).f1 == 1.0
    with pytest.raises(DetectorError, match=r"\['pedestrian', 'car'\] are not the dataset's"):
        evaluate_detector(Det(("pedestrian", "car")), data)
