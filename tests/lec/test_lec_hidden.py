"""Hidden boxes: a box a phenomenon covers becomes an ignore box, in training too."""

from __future__ import annotations

import numpy as np
import pytest
from test_lec_train import tiny_data

from anunnaki.datasets import Dataset
from anunnaki.lec import (
    Augmenter,
    DetectorError,
    TrainConfig,
    box_occlusion,
    hide_boxes,
    train_detector,
)
from anunnaki.phenomena import HIDDEN


def test_box_occlusion_is_the_mean_over_the_box() -> None:
    mask = np.zeros((20, 30), np.float32)
    mask[:, :10] = 1.0  # the left third is gone
    boxes = [[0, 0, 10, 10], [5, 0, 15, 10], [20, 5, 30, 15], [40, 40, 50, 50], [4, 4, 4.2, 4.2]]
    np.testing.assert_allclose(box_occlusion(boxes, mask), [1.0, 0.5, 0.0, 0.0, 1.0])
    with pytest.raises(DetectorError, match="height, width"):
        box_occlusion(boxes, np.zeros((2, 2, 3)))


def test_a_box_at_least_half_hidden_becomes_an_ignore_box() -> None:
    mask = np.zeros((20, 30), np.float32)
    mask[:, :10] = 1.0
    boxes = np.array([[0, 0, 10, 10], [5, 0, 15, 10], [6, 0, 16, 10], [20, 5, 30, 15]])
    labels = np.array([0, 1, 0, 1])
    ignore = np.array([[1, 1, 2, 2]])
    kept, kept_labels, ignored = hide_boxes(boxes, labels, ignore, mask)
    assert HIDDEN == 0.5
    np.testing.assert_array_equal(kept, boxes[2:])  # 40 % hidden: still a target
    np.testing.assert_array_equal(kept_labels, [0, 1])
    np.testing.assert_array_equal(ignored, [[1, 1, 2, 2], [0, 0, 10, 10], [5, 0, 15, 10]])
    stricter = hide_boxes(boxes, labels, ignore, mask, threshold=0.9)
    assert len(stricter[0]) == 3


def test_no_mask_changes_nothing() -> None:
    boxes = np.array([[0, 0, 10, 10]], np.float32)
    kept, labels, ignored = hide_boxes(boxes, [1], np.zeros((0, 4)), None)
    np.testing.assert_array_equal(kept, boxes)
    assert labels.tolist() == [1] and len(ignored) == 0


def test_the_augmenter_reports_the_mask_of_what_it_applied() -> None:
    image = np.random.default_rng(0).integers(0, 256, (32, 32, 3), dtype=np.uint8)
    aug = Augmenter(["raindrop"], probability=1.0)
    out, mask = aug.occluded(image, np.random.default_rng(4))
    np.testing.assert_array_equal(out, aug(image, np.random.default_rng(4)))  # same draws
    assert mask is not None and mask.shape == (32, 32) and mask.max() == 1.0
    assert not np.any(np.any(out != image, axis=2) & (mask == 0))
    assert Augmenter(["fog"], probability=1.0).occluded(image, np.random.default_rng(4))[1] is None
    assert Augmenter(["fog"], probability=0.0).occluded(image, np.random.default_rng(4)) == (
        image,
        None,
    )


def weights(data: Dataset, **options: object) -> dict[str, np.ndarray]:
    cfg = TrainConfig(epochs=1, batch_size=4, width=8, seed=5, zoom=0.0, **options)  # type: ignore[arg-type]
    net = train_detector(data, data, config=cfg).detector.network
    return {k: v.numpy().copy() for k, v in net.state_dict().items()}


def same(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> bool:
    return all(np.array_equal(a[k], b[k]) for k in a)


def test_training_on_a_hidden_box_is_training_with_an_ignore_box() -> None:
    """A perturbation that hides every box trains as if every box were an ignore box."""
    data = tiny_data(8)
    all_ignored = Dataset.from_arrays(
        [data.image(i) for i in range(len(data))],
        [np.zeros((0, 4))] * len(data),
        [np.zeros(0, np.int64)] * len(data),
        data.classes,
        ignore=[r.boxes for r in data.records],
        ignore_labels=[r.labels for r in data.records],
    )

    def hides_all(image: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        return image, np.ones(image.shape[:2], np.float32)

    def plain(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return image

    def no_mask(image: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, None]:
        return image, None

    hidden = weights(data, perturb=hides_all)
    assert same(hidden, weights(all_ignored, perturb=plain))
    # Not hidden: the boxes are targets, and a perturbation without a mask changes nothing.
    assert same(weights(data, perturb=plain), weights(data, perturb=no_mask))
    assert not same(hidden, weights(data, perturb=plain))
    # ignore=False: hidden boxes stay targets, as before masks existed.
    assert same(
        weights(data, perturb=hides_all, ignore=False), weights(data, perturb=plain, ignore=False)
    )
