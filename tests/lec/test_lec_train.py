"""Training: a model trained from scratch reaches a measured floor; training and inference
repeat exactly."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from lec_helpers import Trained, train_session_model

from anunnaki.datasets import Dataset, load_split
from anunnaki.lec import (
    Augmenter,
    CenterNetDetector,
    DetectionResult,
    Detector,
    DetectorError,
    TrainConfig,
    evaluate_detector,
    load_detector,
    train_detector,
)
from anunnaki.lec._centernet import centernet_loss, encode_targets
from anunnaki.lec._train import _zoom
from anunnaki.phenomena import PHENOMENA

#: Measured with ignore boxes (the rover's minimum labelled height, ignore-aware loss and F1):
#: the model trained from scratch here (300 training images of 96 x 96 with 435 boxes and 892
#: ignore boxes, 10 epochs) scores test F1 0.805, 0.791 and 0.816 with training seeds 0, 1, 2
#: on its own 75-image test split (120 boxes); rendering took 6 s and training 17-19 s on the
#: 2-core VM at load average 2 (22-25 s in all, where the earlier 128 x 128, 12-epoch model
#: took 38-45 s and 65-76 s under heavier load). The floor leaves a margin of 0.1 under the
#: lowest seed for platform differences in rendering and BLAS.
F1_FLOOR = 0.69


@pytest.mark.training
# 25 s on a quiet 2-core VM; 456 s was seen at load 5-9 (issue #34): the suite's 120 s would
# fail it on a shared machine, so it gets what the training fixture had.
@pytest.mark.timeout(900)
def test_a_model_trained_from_scratch_reaches_the_floor(tmp_path: Path) -> None:
    """The one test of the suite that trains a detector from scratch (render, train, save)."""
    pytest.importorskip("pybullet")
    trained, _seconds = train_session_model(tmp_path)  # pytest --durations shows the time
    det = load_detector(trained.model)
    assert isinstance(det, CenterNetDetector)
    test = load_split(trained.data, "test")
    m = evaluate_detector(det, test)
    assert m.f1 >= F1_FLOOR, f"test F1 {m.f1:.3f} < {F1_FLOOR} ({m})"
    # The sidecar's figures are what evaluation gives.
    assert det.metrics["test"]["f1"] == pytest.approx(m.f1, abs=1e-9)
    assert 0.05 <= det.score_threshold <= 1.0
    assert det.training["epochs"] > 0 and det.training["train_images"] > 0


def test_the_shipped_model_finds_the_rovers_objects(trained: Trained) -> None:
    """The fixture's model (the shipped one) on 40 frames it never saw: what the tests below
    lean on, a real F1 (0.895 here, 51 of 59 boxes; 0.92 on its full test split)."""
    det = load_detector(trained.model)
    m = evaluate_detector(det, load_split(trained.data, "test"))
    assert m.f1 == pytest.approx(trained.metrics["test"]["f1"], abs=1e-9)
    assert m.f1 >= F1_FLOOR and m.tp >= 20, m


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
    drop = PHENOMENA.create("raindrop")
    xs = [aug.sample_params(drop, rng)["x"] for _ in range(200)]
    assert min(xs) < 0.2 and max(xs) > 0.8  # free parameters roam the image
    fog = PHENOMENA.create("fog")
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
                boxes, labels, _ = truths[self.seen]
                out.append(DetectionResult(boxes, labels, np.ones(len(labels))))
                self.seen += 1
            return out

    oracle = Oracle()
    assert isinstance(oracle, Detector)
    m = evaluate_detector(oracle, data, batch_size=4)
    assert (m.f1, m.tp, m.fp, m.fn) == (1.0, 6, 0, 0)


# -- ignore boxes in training --------------------------------------------------------------


def test_targets_mask_the_background_loss_inside_ignore_boxes() -> None:
    boxes = np.array([[8, 8, 24, 40]], np.float32)  # a labelled object, centre cell (4, 6)
    ignore = np.array([[40, 4, 60, 28], [14, 20, 18, 24]], np.float32)
    plain = encode_targets(boxes, np.array([0]), num_classes=2, out_hw=(16, 16), stride=4)
    heat, box_t, weight = encode_targets(
        boxes, np.array([0]), num_classes=2, out_hw=(16, 16), stride=4, ignore=ignore
    )
    # Cells whose centre is inside the first ignore box (x 10-15, y 1-7 at stride 4) are -1
    # in every class; the rest of the heat map is as without ignore boxes.
    skip = np.zeros((16, 16), bool)
    skip[1:7, 10:15] = True
    skip[5, 3:5] = True  # the second covers cells x 3-4 of row 5 (centres on its edges) ...
    assert (heat[:, skip] == -1).all()
    assert heat[0, 6, 4] == 1.0  # ... but not the labelled object's centre, next to it
    np.testing.assert_array_equal(heat[:, ~skip], plain[0][:, ~skip])
    np.testing.assert_array_equal(box_t, plain[1])
    np.testing.assert_array_equal(weight, plain[2])
    # A confident prediction inside the ignore box costs nothing; outside it, it does.
    logits = np.full((1, 2, 16, 16), -6.0, np.float32)
    logits[0, :, 6, 4] = 6.0  # the object, found
    with_ignore = torch_loss(logits, heat, box_t, weight)
    logits[0, 1, 3, 12] = 6.0  # a detection on the ignored object
    assert torch_loss(logits, heat, box_t, weight) == pytest.approx(with_ignore, rel=1e-6)
    assert torch_loss(logits, *plain) > with_ignore + 1.0


def torch_loss(
    logits: np.ndarray, heat: np.ndarray, box_t: np.ndarray, weight: np.ndarray
) -> float:
    import torch

    ltrb = torch.zeros((1, 4, 16, 16))
    _, parts = centernet_loss(
        (torch.from_numpy(logits), ltrb),
        torch.from_numpy(heat[None]),
        torch.from_numpy(box_t[None]),
        torch.from_numpy(weight[None]),
    )
    return parts["heat"]


def test_zoom_moves_ignore_boxes_and_ignores_what_it_pushes_out() -> None:
    image = np.zeros((64, 64, 3), np.uint8)
    boxes = np.array([[0, 0, 10, 10], [30, 30, 40, 40]], np.float32)
    labels = np.array([0, 1])
    ignore = np.array([[50, 50, 60, 60]], np.float32)
    rng = np.random.default_rng(0)
    for _ in range(20):
        _, nb, nl, ni = _zoom(image, boxes, labels, rng, 0.4, ignore=ignore)
        assert len(nb) + len(ni) >= 2  # an object is a label or ignored, unless fully out
        assert (ni[:, 2] > ni[:, 0]).all() and (ni[:, :2] >= 0).all() and (ni[:, 2:] <= 64).all()
        assert len(nb) == len(nl)


def test_training_with_ignore_boxes_runs_and_records_it() -> None:
    data = tiny_data(8)
    ignored = Dataset.from_arrays(
        [data.image(i) for i in range(len(data))],
        [r.boxes for r in data.records],
        [r.labels for r in data.records],
        data.classes,
        ignore=[[[0, 0, 6, 6]]] * len(data),
        ignore_labels=[[1]] * len(data),
    )
    cfg = TrainConfig(epochs=1, batch_size=4, width=8, seed=3)
    a = train_detector(ignored, ignored, config=cfg)
    b = train_detector(
        ignored, ignored, config=TrainConfig(epochs=1, batch_size=4, width=8, seed=3, ignore=False)
    )
    assert a.detector.training["ignore"] is True and a.detector.training["ignore_boxes"] == 8
    assert b.detector.training["ignore_boxes"] == 0
    # Same seed, same data: only the masked background loss differs.
    assert a.history[0]["heat"] != b.history[0]["heat"]


def test_fine_tuning_starts_from_the_given_weights() -> None:
    data = tiny_data(8)
    base = train_detector(data, data, config=TrainConfig(epochs=1, batch_size=4, width=8))
    tuned = train_detector(
        data,
        data,
        config=TrainConfig(epochs=1, batch_size=4, width=16, lr=1e-9, init=base.detector),
    )
    assert tuned.detector.network.width == 8  # taken from the initial model
    assert tuned.detector.training["init"] == base.detector.model_id
    a = base.detector.network.state_dict()["s2.0.weight"].numpy()
    b = tuned.detector.network.state_dict()["s2.0.weight"].numpy()
    np.testing.assert_allclose(a, b, atol=1e-6)  # lr ~ 0: the weights barely move
    other = Dataset.from_arrays([data.image(0)], [[]], [[]], ("cat", "dog"))
    with pytest.raises(DetectorError, match="classes"):
        train_detector(other, other, config=TrainConfig(epochs=1, init=base.detector))


def test_the_progress_hook_reports_every_step() -> None:
    data = tiny_data(10)  # batches of 4: 3 steps an epoch (4 + 4 + 2)
    calls: list[tuple[int, int, dict[str, float]]] = []
    result = train_detector(
        data,
        data,
        config=TrainConfig(epochs=2, batch_size=4, width=8, seed=1),
        on_step=lambda step, total, info: calls.append((step, total, dict(info))),
    )
    assert [(step, total) for step, total, _ in calls] == [(k, 6) for k in range(1, 7)]
    assert [info["epoch"] for *_, info in calls] == [1, 1, 1, 2, 2, 2]
    assert all(np.isfinite(info["loss"]) and info["loss"] > 0 for *_, info in calls)
    # The running loss at an epoch's last step is the epoch's mean loss in the history.
    assert calls[2][2]["loss"] == pytest.approx(result.history[0]["loss"])
    assert calls[5][2]["loss"] == pytest.approx(result.history[1]["loss"])


def test_the_epoch_hook_reports_loss_and_val_f1_without_changing_the_training() -> None:
    data = tiny_data(10)
    config = TrainConfig(epochs=2, batch_size=4, width=8, seed=1)
    epochs: list[dict[str, float]] = []
    result = train_detector(data, data, config=config, on_epoch=epochs.append)
    assert [(e["epoch"], e["epochs"]) for e in epochs] == [(1, 2), (2, 2)]
    for info, record in zip(epochs, result.history, strict=True):
        assert info["loss"] == record["loss"] and info["seconds"] > 0
        assert 0.0 <= info["val_f1"] <= 1.0
    # After the last epoch the val F1 is the one the threshold choice measures.
    assert epochs[-1]["val_f1"] == pytest.approx(result.val.f1)
    # Measuring val in eval mode between epochs leaves the weights as they were.
    plain = train_detector(data, data, config=config)
    for name, tensor in plain.detector.network.state_dict().items():
        assert torch.equal(tensor, result.detector.network.state_dict()[name]), name


def test_default_epochs_fit_the_training_budget() -> None:
    """14 epochs: the rover default model's, 247 s for 2000 images (docs/detector.md)."""
    from anunnaki.cli._detector import DEFAULT_EPOCHS

    assert TrainConfig().epochs == DEFAULT_EPOCHS == 14
