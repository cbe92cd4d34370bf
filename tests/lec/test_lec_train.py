"""Training: the session model reaches a measured floor; training and inference repeat exactly."""

from __future__ import annotations

import numpy as np
import pytest
from lec_helpers import Trained

from anunnaki.datasets import Dataset, load_split
from anunnaki.lec import (
    Augmenter,
    CenterNetDetector,
    DetectionResult,
    Detector,
    TrainConfig,
    evaluate_detector,
    load_detector,
    train_detector,
)
from anunnaki.phenomena import get_phenomenon

#: Measured: the session model (300 images, 12 epochs, ~35 s) scores test F1 0.656, 0.690
#: and 0.661 with seeds 0, 1, 2 on its own 225-image test split; the floor leaves a margin for
#: platform differences in rendering and BLAS.
F1_FLOOR = 0.55


def test_session_model_reaches_floor(trained: Trained) -> None:
    det = load_detector(trained.model)
    assert isinstance(det, CenterNetDetector)
    test = load_split(trained.data, "test")
    m = evaluate_detector(det, test)
    assert m.f1 >= F1_FLOOR, f"test F1 {m.f1:.3f} < {F1_FLOOR} ({m})"
    # The sidecar's figures are what evaluation gives.
    assert det.metrics["test"]["f1"] == pytest.approx(m.f1, abs=1e-9)
    assert 0.05 <= det.score_threshold <= 1.0
    assert det.training["epochs"] > 0 and det.training["train_images"] > 0


def test_inference_is_deterministic(trained: Trained) -> None:
    test = load_split(trained.data, "test")
    images = [test.image(i) for i in range(8)]
    a = load_detector(trained.model).detect(images)
    b = load_detector(trained.model)
    for ra, rb in zip(a, b.detect(images), strict=True):
        np.testing.assert_array_equal(ra.boxes, rb.boxes)
        np.testing.assert_array_equal(ra.labels, rb.labels)
        np.testing.assert_array_equal(ra.scores, rb.scores)
    one_by_one = [b.detect(im)[0] for im in images[:3]]
    for ra, rb in zip(a, one_by_one, strict=False):  # batch size does not change results
        np.testing.assert_allclose(ra.scores, rb.scores, atol=1e-5)


def test_a_phenomenon_lowers_f1(trained: Trained) -> None:
    det = load_detector(trained.model)
    test = load_split(trained.data, "test").subset(range(40))
    clean = evaluate_detector(det, test)
    dark = evaluate_detector(det, test, phenomenon="brightness", params={"gain": 0.05})
    assert dark.f1 < clean.f1


def tiny_data(n: int = 12, seed: int = 0) -> Dataset:
    rng = np.random.default_rng(seed)
    images, boxes, labels = [], [], []
    for _ in range(n):
        image = np.full((64, 64, 3), 90, np.uint8)
        x, y = (int(v) for v in rng.integers(4, 40, 2))
        image[y : y + 16, x : x + 12] = (220, 40, 40)
        images.append(image)
        boxes.append([[x, y, x + 12, y + 16]])
        labels.append([0])
    return Dataset.from_arrays(images, boxes, labels, ("pedestrian", "deer"))


def test_training_repeats_exactly_with_a_seed() -> None:
    data = tiny_data()
    cfg = TrainConfig(epochs=1, batch_size=4, width=8, seed=7, augment=("fog",))
    a = train_detector(data, data, config=cfg).detector.network.state_dict()
    b = train_detector(data, data, config=cfg).detector.network.state_dict()
    for k in a:
        assert np.array_equal(a[k].numpy(), b[k].numpy()), k
    c = train_detector(data, data, config=TrainConfig(epochs=1, batch_size=4, width=8, seed=8))
    assert not np.array_equal(
        a["heat.2.bias"].numpy(), c.detector.network.state_dict()["heat.2.bias"].numpy()
    )


def test_augmenter_samples_within_bounds() -> None:
    aug = Augmenter(["raindrop", "fog"], probability=1.0)
    rng = np.random.default_rng(0)
    drop = get_phenomenon("raindrop")
    xs = [aug.sample_params(drop, rng)["x"] for _ in range(200)]
    assert min(xs) < 0.2 and max(xs) > 0.8  # free parameters roam the image
    fog = get_phenomenon("fog")
    for _ in range(50):
        p = aug.sample_params(fog, rng)
        assert 1 <= p["density"] <= 10 and 0 <= p["intensity"] <= 0.3
    image = np.full((32, 32, 3), 100, np.uint8)
    assert not np.array_equal(aug(image, np.random.default_rng(1)), image)
    never = Augmenter(["fog"], probability=0.0)
    assert never(image, rng) is image


def test_any_detector_can_be_evaluated() -> None:
    """A third-party model is measured the same way through the Detector protocol."""
    data = tiny_data(6)
    truths = data.truths()

    class Oracle:
        model_id, classes, domain = "oracle", data.classes, "default"
        score_threshold = 0.5

        def __init__(self) -> None:
            self.seen = 0

        def detect(self, images):  # type: ignore[no-untyped-def]
            out = []
            for _ in images:
                boxes, labels = truths[self.seen]
                out.append(DetectionResult(boxes, labels, np.ones(len(labels))))
                self.seen += 1
            return out

    oracle = Oracle()
    assert isinstance(oracle, Detector)
    m = evaluate_detector(oracle, data, batch_size=4)
    assert (m.f1, m.tp, m.fp, m.fn) == (1.0, 6, 0, 0)
