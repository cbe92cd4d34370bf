"""F1 on all boxes and on the visible ones: a hidden box is neither a miss nor a false alarm."""

from __future__ import annotations

from types import MappingProxyType

import numpy as np
import pytest
from test_lec_train import tiny_data

from anunnaki.datasets import Dataset
from anunnaki.lec import DetectionResult, DetectorError, evaluate_detector, evaluate_visible
from anunnaki.phenomena import Image, Mask, ParamSpec, Phenomenon


class LeftCurtain(Phenomenon):
    """Blacks out the left ``share`` of the frame (a test occluder)."""

    name = "left_curtain"
    stochastic = False
    params = (ParamSpec("share", 0.0, 1.0, "image width", "Covered share.", 0.0),)
    strength_target = MappingProxyType({"share": 0.5})

    def occlusion_mask(
        self, height: int, width: int, params: dict[str, float], seed: int
    ) -> Mask | None:
        mask = np.zeros((height, width), np.float32)
        mask[:, : round(params["share"] * width)] = 1.0
        return mask

    def perturb(self, image: Image, params: dict[str, float], seed: int) -> Image:
        out = image.copy()
        out[:, : round(params["share"] * image.shape[1])] = 0
        return out


class Finds:
    """A detector that returns given boxes per image (score 1), whatever it is shown."""

    model_id, domain, score_threshold = "finds", "default", 0.5

    def __init__(self, data: Dataset, keep: object) -> None:
        self.classes = data.classes
        self.per_image = [keep(r.boxes) for r in data.records]  # type: ignore[operator]
        self.seen = 0

    def detect(self, images):  # type: ignore[no-untyped-def]
        out = []
        for _ in images:
            boxes = np.asarray(self.per_image[self.seen], np.float32).reshape(-1, 4)
            out.append(DetectionResult(boxes, np.zeros(len(boxes), np.int64), np.ones(len(boxes))))
            self.seen += 1
        return out


def left(boxes: np.ndarray) -> np.ndarray:
    """Boxes whose centre is in the left half: those the curtain at 0.5 hides."""
    return np.asarray((boxes[:, 0] + boxes[:, 2]) / 2 < 32)


@pytest.fixture
def data() -> Dataset:
    d = tiny_data(12, seed=1)
    hidden = sum(int(left(r.boxes).sum()) for r in d.records)
    assert 0 < hidden < 12  # both kinds are there
    return d


def test_a_detector_of_the_visible_boxes_is_perfect_on_them_and_at_the_ceiling(
    data: Dataset,
) -> None:
    m = evaluate_visible(Finds(data, lambda b: b[~left(b)]), data, phenomenon=LeftCurtain())
    n_hidden = sum(int(left(r.boxes).sum()) for r in data.records)
    assert (m.boxes, m.hidden) == (12, n_hidden)
    assert m.all.fn == n_hidden and m.all.fp == 0
    # Visible boxes only: the hidden ones are ignore boxes, so no miss.
    assert m.visible is not None
    assert (m.visible.f1, m.visible.tp, m.visible.fp, m.visible.fn) == (1.0, 12 - n_hidden, 0, 0)
    assert m.ceiling == pytest.approx(m.all.f1)
    assert m.ceiling == pytest.approx(2 * (12 - n_hidden) / (2 * 12 - n_hidden))
    assert m.as_dict()["visible"]["f1"] == 1.0 and m.as_dict()["hidden_boxes"] == n_hidden


def test_a_detection_on_a_hidden_box_is_no_false_positive(data: Dataset) -> None:
    m = evaluate_visible(Finds(data, lambda b: b), data, phenomenon=LeftCurtain())
    assert m.all.f1 == 1.0
    assert m.visible is not None
    assert (m.visible.tp, m.visible.fp, m.visible.fn) == (12 - m.hidden, 0, 0)


def test_all_boxes_is_what_evaluate_detector_gives(data: Dataset) -> None:
    m = evaluate_visible(
        Finds(data, lambda b: b[~left(b)]), data, phenomenon=LeftCurtain(), strength=0.5
    )
    plain = evaluate_detector(
        Finds(data, lambda b: b[~left(b)]), data, phenomenon=LeftCurtain(), strength=0.5
    )
    assert m.all == plain


def test_a_phenomenon_without_a_mask_changes_nothing(data: Dataset) -> None:
    m = evaluate_visible(Finds(data, lambda b: b[~left(b)]), data, phenomenon="fog")
    assert m.visible is None and m.ceiling is None and m.hidden == 0
    assert m.all == evaluate_detector(Finds(data, lambda b: b[~left(b)]), data, phenomenon="fog")
    assert m.as_dict()["visible"] is None


def test_params_or_strength_not_both(data: Dataset) -> None:
    with pytest.raises(DetectorError, match="not both"):
        evaluate_visible(
            Finds(data, lambda b: b), data, phenomenon=LeftCurtain(), params={"share": 0.2},
            strength=0.3,
        )  # fmt: skip
