"""The one contract suite every detector architecture passes (plugin slot anunnaki.detectors).

Each registered architecture is loaded the way the model manager loads it — through its
``load(file, options)`` — from a small model written by its case below: ``centernet`` (a tiny
untrained network saved as an anunnaki model file) and the tests' ``fixed_boxes`` plugin. To
run the suite against a new architecture, add a case to ``CASES``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fixed_boxes_plugin import FixedBoxes, write_model

from anunnaki.lec import ARCHITECTURES, DetectionResult, Detector, architecture_files


def _centernet(folder: Path) -> tuple[Path, dict[str, Any]]:
    from anunnaki.lec import CenterNetDetector, save_detector

    det = CenterNetDetector.create(
        ("pedestrian", "deer"), input_size=(32, 32), width=8, model_id="tiny"
    )
    det.score_threshold = 0.0  # untrained: keep every candidate, so boxes are checked too
    path = folder / "tiny.safetensors"
    save_detector(det, path)
    return path, {}


def _fixed_boxes(folder: Path) -> tuple[Path, dict[str, Any]]:
    rows = [(4, 4, 20, 30, "pedestrian", 0.9), (10, 2, 60, 50, "deer", 0.4)]
    model, names = write_model(folder, boxes=rows)
    return model, {"classes": names.name}


#: How to write a small model of each architecture: ``folder -> (file, options)``.
CASES: dict[str, Callable[[Path], tuple[Path, dict[str, Any]]]] = {
    "centernet": _centernet,
    "fixed_boxes": _fixed_boxes,
}


@pytest.fixture(scope="module", autouse=True)
def plugin() -> Iterator[None]:
    ARCHITECTURES.register(FixedBoxes)
    try:
        yield
    finally:
        ARCHITECTURES.unregister("fixed_boxes")


@pytest.fixture(params=sorted(CASES), ids=str)
def loaded(request: pytest.FixtureRequest, tmp_path: Path) -> tuple[Detector, list[Path]]:
    architecture = ARCHITECTURES.create(request.param)
    file, options = CASES[request.param](tmp_path)
    det = architecture.load(file, options)
    return det, architecture_files(architecture, file, options)


def frames() -> list[np.ndarray]:
    rng = np.random.default_rng(0)
    out = [rng.integers(0, 256, (h, w, 3), dtype=np.uint8) for h, w in ((32, 32), (48, 64))]
    for f in out:
        f.flags.writeable = False  # a detector must not write into a frame
    return out


def test_every_registered_architecture_is_in_the_suite() -> None:
    assert set(ARCHITECTURES.names()) <= set(CASES), "add a case for each new architecture"


def test_is_a_detector(loaded: tuple[Detector, list[Path]]) -> None:
    det, files = loaded
    assert isinstance(det, Detector)
    assert isinstance(det.model_id, str) and det.model_id
    assert isinstance(det.domain, str) and det.domain.isidentifier()
    assert isinstance(det.classes, tuple) and det.classes
    assert all(isinstance(c, str) and c for c in det.classes)
    assert len(set(det.classes)) == len(det.classes), "class names must be unique"
    assert files and all(f.is_file() for f in files)  # what the registry pins exists


def check(result: DetectionResult, image: np.ndarray, classes: tuple[str, ...]) -> None:
    assert isinstance(result, DetectionResult)
    n = len(result)
    assert result.boxes.dtype == np.float32 and result.boxes.shape == (n, 4)
    assert result.labels.dtype == np.int64 and result.labels.shape == (n,)
    assert result.scores.dtype == np.float32 and result.scores.shape == (n,)
    assert ((result.labels >= 0) & (result.labels < len(classes))).all()
    assert ((result.scores >= 0) & (result.scores <= 1)).all()
    h, w = image.shape[:2]
    b = result.boxes
    assert ((b[:, 0] >= 0) & (b[:, 2] <= w) & (b[:, 1] >= 0) & (b[:, 3] <= h)).all()
    assert ((b[:, 2] >= b[:, 0]) & (b[:, 3] >= b[:, 1])).all()


def test_results_have_the_documented_shapes_and_dtypes(
    loaded: tuple[Detector, list[Path]],
) -> None:
    det, _ = loaded
    images = frames()
    results = det.detect(images)
    assert len(results) == len(images)
    for result, image in zip(results, images, strict=True):
        check(result, image, det.classes)
    assert sum(len(r) for r in results) > 0, "the case's model should find something"


def test_every_input_form(loaded: tuple[Detector, list[Path]]) -> None:
    det, _ = loaded
    image = frames()[0]
    (one,) = det.detect(image)  # one (H, W, 3) image: a list of one
    batch = det.detect(np.stack([image, image]))  # a (B, H, W, 3) batch
    assert len(batch) == 2
    for r in batch:  # batching may change float rounding, not the detections
        np.testing.assert_allclose(r.boxes, one.boxes, atol=1e-3)
        np.testing.assert_allclose(r.scores, one.scores, atol=1e-5)
        np.testing.assert_array_equal(r.labels, one.labels)


def test_an_empty_batch_gives_no_results(loaded: tuple[Detector, list[Path]]) -> None:
    det, _ = loaded
    assert det.detect([]) == []
    assert det.detect(np.zeros((0, 32, 32, 3), np.uint8)) == []


def test_deterministic(loaded: tuple[Detector, list[Path]]) -> None:
    det, _ = loaded
    first, second = det.detect(frames()), det.detect(frames())
    for a, b in zip(first, second, strict=True):
        np.testing.assert_array_equal(a.boxes, b.boxes)
        np.testing.assert_array_equal(a.labels, b.labels)
        np.testing.assert_array_equal(a.scores, b.scores)
