"""Model files: safetensors + sidecar round trip; corrupt, changed or foreign files refused."""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from anunnaki.errors import AnunnakiError
from anunnaki.lec import (
    CenterNetDetector,
    Detector,
    DetectorError,
    DetectorLoadError,
    load_detector,
    read_card,
    save_detector,
    sha256_file,
)


@pytest.fixture(scope="module")
def untrained() -> CenterNetDetector:
    det = CenterNetDetector.create(
        ("pedestrian", "deer"), input_size=(64, 48), width=8, seed=3, model_id="tiny"
    )
    det.score_threshold = 0.0  # an untrained net scores about 0.1 everywhere
    det.metrics = {"val": {"f1": 0.5}}
    return det


@pytest.fixture
def saved(tmp_path: Path, untrained: CenterNetDetector) -> Path:
    path = tmp_path / "m.safetensors"
    save_detector(untrained, path)
    return path


def images(n: int = 2, size: tuple[int, int] = (48, 64)) -> np.ndarray:
    return np.random.default_rng(1).integers(0, 255, (n, *size, 3), dtype=np.uint8)


def test_round_trip(saved: Path, untrained: CenterNetDetector) -> None:
    card = read_card(saved)
    assert card.sha256 == sha256_file(saved) and card.weights == "m.safetensors"
    assert card.input_size == (64, 48) and card.architecture == "centernet"
    assert card.arch == {"width": 8, "head": 8, "stride": 4, "max_detections": 100}
    det = load_detector(saved)
    assert isinstance(det, Detector) and isinstance(det, CenterNetDetector)
    assert (det.model_id, det.classes, det.domain) == ("tiny", ("pedestrian", "deer"), "default")
    assert det.metrics == {"val": {"f1": 0.5}} and det.sha256 == card.sha256
    a, b = untrained.detect(images()), det.detect(images())
    assert len(a) == 2 and sum(len(r) for r in a) > 0
    for ra, rb in zip(a, b, strict=True):
        np.testing.assert_array_equal(ra.boxes, rb.boxes)
        np.testing.assert_array_equal(ra.scores, rb.scores)
    assert load_detector(saved.with_suffix(".json")).model_id == "tiny"  # either file works
    umask = os.umask(0)
    os.umask(umask)
    for f in (saved, saved.with_suffix(".json")):  # usual permissions, not mkstemp's 0600
        assert stat.S_IMODE(f.stat().st_mode) == 0o666 & ~umask


def test_save_is_repeatable(tmp_path: Path, untrained: CenterNetDetector) -> None:
    assert save_detector(untrained, tmp_path / "a.safetensors") == save_detector(
        untrained, tmp_path / "b"
    )
    assert (tmp_path / "b.json").is_file() and (tmp_path / "b.safetensors").is_file()


def test_changed_weights_refused(saved: Path) -> None:
    data = bytearray(saved.read_bytes())
    data[-1] ^= 0xFF
    saved.write_bytes(bytes(data))
    with pytest.raises(DetectorLoadError, match=r"m\.safetensors: sha256: sha256 mismatch") as info:
        load_detector(saved)
    assert info.value.path == str(saved) and "copy the model again" in str(info.value)


def test_corrupt_weights_with_matching_hash_refused(saved: Path) -> None:
    saved.write_bytes(b"\x08\x00\x00\x00\x00\x00\x00\x00{broken}")
    card = json.loads(saved.with_suffix(".json").read_text())
    card["sha256"] = sha256_file(saved)
    saved.with_suffix(".json").write_text(json.dumps(card))
    with pytest.raises(DetectorLoadError, match=r"m\.safetensors: not a valid safetensors file"):
        load_detector(saved)


def test_weights_of_another_model_refused(tmp_path: Path, saved: Path) -> None:
    other = CenterNetDetector.create(("a", "b", "c"), input_size=(64, 48), width=8)
    save_detector(other, tmp_path / "other.safetensors")
    (tmp_path / "other.safetensors").replace(saved)  # another net's weights, hash matching
    card = json.loads(saved.with_suffix(".json").read_text())
    card["sha256"] = sha256_file(saved)
    saved.with_suffix(".json").write_text(json.dumps(card))
    with pytest.raises(DetectorLoadError, match=r"m\.safetensors: heat\.2\.weight: tensor"):
        load_detector(saved)


@pytest.mark.parametrize("given", ["copy.safetensors", "copy.json", "copy"])
def test_a_copied_sidecar_does_not_load_the_weights_it_names(
    tmp_path: Path, saved: Path, given: str
) -> None:
    """Issue 34 item 2: copy.safetensors (corrupt) with m.json copied next to it as copy.json
    loaded m.safetensors, the file the sidecar names, and measured that model instead."""
    (tmp_path / "copy.safetensors").write_bytes(b"\xff" * 64)  # corrupt: not even a header
    (tmp_path / "copy.json").write_bytes(saved.with_suffix(".json").read_bytes())
    with pytest.raises(DetectorLoadError) as info:
        load_detector(tmp_path / given)
    text = str(info.value)
    assert text.startswith(f"{tmp_path / 'copy.json'}: weights: the sidecar names the weights "
                           "'m.safetensors', not 'copy.safetensors'")  # fmt: skip
    assert "nothing was loaded" in text and "give m.safetensors" in text


@pytest.mark.parametrize(
    ("damage", "pattern"),
    [
        (lambda b: b[:20], r"not a valid safetensors file"),  # cut short
        (lambda b: b"\xff" * 8 + b[8:], r"not a valid safetensors file"),  # header length
        (lambda b: b[:8] + b"#" + b[9:], r"not a valid safetensors file"),  # header JSON
        (lambda b: b"", r"not a valid safetensors file"),
    ],
)
def test_a_corrupt_weights_file_gets_an_error_naming_it(  # type: ignore[no-untyped-def]
    saved: Path, damage, pattern: str
) -> None:
    """Corrupt weights whose sidecar states their hash: a clear error, no traceback."""
    saved.write_bytes(damage(saved.read_bytes()))
    card = json.loads(saved.with_suffix(".json").read_text())
    card["sha256"] = sha256_file(saved)
    saved.with_suffix(".json").write_text(json.dumps(card))
    with pytest.raises(DetectorLoadError, match=pattern) as info:
        load_detector(saved)
    assert info.value.path == str(saved)


@pytest.mark.parametrize(
    ("edit", "pattern"),
    [
        (lambda c: c.update(architecture="yolo"), r"architecture: unknown architecture 'yolo'"),
        (lambda c: c.update(format="pickle"), r"format: not an anunnaki detector sidecar"),
        (lambda c: c.update(format_version=9), r"format_version: sidecar format_version 9"),
        (lambda c: c.update(score_threshold=2), r"score_threshold: Input should be less"),
        (lambda c: c.update(weights="../m.safetensors"), r"weights: weights '\.\./m"),
        (lambda c: c.update(extra=1), r"extra: Extra inputs are not permitted"),
        (lambda c: c["arch"].update(width=-1), r"arch\.width: arch\.width must be an integer"),
    ],
)
def test_bad_sidecar_refused(saved: Path, edit, pattern: str) -> None:  # type: ignore[no-untyped-def]
    sidecar = saved.with_suffix(".json")
    card = json.loads(sidecar.read_text())
    edit(card)
    sidecar.write_text(json.dumps(card))
    with pytest.raises(DetectorLoadError, match=pattern) as info:
        load_detector(saved)
    assert "m.json" in str(info.value)


def test_missing_files_refused(saved: Path) -> None:
    saved.with_suffix(".json").write_text("{not json")
    with pytest.raises(DetectorLoadError, match=r"m\.json:1: sidecar is not valid JSON"):
        load_detector(saved)
    saved.with_suffix(".json").unlink()
    with pytest.raises(DetectorLoadError, match=r"m\.json: model sidecar not found.*copy both"):
        load_detector(saved)


def test_foreign_detector_cannot_be_saved(tmp_path: Path) -> None:
    class Foreign:
        model_id, classes, domain = "x", ("a",), "default"

        def detect(self, images):  # type: ignore[no-untyped-def]
            return []

    assert isinstance(Foreign(), Detector)
    with pytest.raises(DetectorError, match="Foreign cannot be saved by anunnaki"):
        save_detector(Foreign(), tmp_path / "f")  # type: ignore[arg-type]


def test_detect_accepts_every_form_and_sizes(untrained: CenterNetDetector) -> None:
    batch = images(3)
    as_batch = untrained.detect(batch)
    as_list = untrained.detect(list(batch))
    single = untrained.detect(batch[0])
    assert len(as_batch) == len(as_list) == 3 and len(single) == 1
    np.testing.assert_allclose(as_batch[0].boxes, single[0].boxes, atol=1e-3)  # batch size
    big = np.repeat(np.repeat(batch[0], 2, axis=0), 2, axis=1)  # 128 x 96: resized, boxes x2
    res = untrained.detect([big])[0]
    assert res.boxes[:, 2].max() <= 128 and res.boxes[:, 3].max() <= 96
    assert untrained.detect([]) == []
    r = as_batch[0]
    assert r.boxes.dtype == np.float32 and r.labels.dtype == np.int64
    assert ((r.scores >= 0) & (r.scores <= 1)).all() and set(r.labels) <= {0, 1}


def test_detect_refuses_bad_images(untrained: CenterNetDetector) -> None:
    with pytest.raises(DetectorError, match=r"image 0: expected dtype uint8, got float32.*255"):
        untrained.detect(np.zeros((8, 8, 3), np.float32))
    with pytest.raises(DetectorError, match=r"image 1: expected shape \(H, W, 3\) RGB"):
        untrained.detect([np.zeros((8, 8, 3), np.uint8), np.zeros((8, 8), np.uint8)])
    with pytest.raises(AnunnakiError):
        untrained.detect(np.zeros((8,), np.uint8))


def test_a_third_party_architecture_loads_through_the_registry(saved: Path) -> None:
    """A sidecar naming a registered architecture is built by that plugin's from_card."""
    from anunnaki.lec import ARCHITECTURES, DetectionResult, ModelCard

    built: list[tuple[str, int]] = []

    class Fixed:
        classes = ("pedestrian", "deer")
        domain = "default"

        def __init__(self, card: ModelCard) -> None:
            self.model_id = card.model_id

        def detect(self, images: Any) -> list[DetectionResult]:
            box = np.array([[1, 1, 5, 5]], np.float32)
            return [DetectionResult(box, np.array([0]), np.array([0.9], np.float32))]

    class FixedArchitecture:
        name = "fixed"

        def load(self, file: Path, options: Any) -> Fixed:
            raise NotImplementedError

        def from_card(self, card: ModelCard, tensors: dict[str, Any], path: Path) -> Fixed:
            built.append((card.architecture, len(tensors)))
            return Fixed(card)

    class LoadOnly:
        name = "load_only"

        def load(self, file: Path, options: Any) -> Fixed:
            raise NotImplementedError

    sidecar = saved.with_suffix(".json")
    card = json.loads(sidecar.read_text())
    card["architecture"] = "fixed"
    sidecar.write_text(json.dumps(card))
    with pytest.raises(DetectorLoadError, match=r"unknown architecture 'fixed'; known: centernet"):
        load_detector(saved)
    with pytest.raises(AnunnakiError, match="not a class"):
        ARCHITECTURES.register(lambda card, tensors, path: None, name="builder")
    ARCHITECTURES.register(FixedArchitecture)
    ARCHITECTURES.register(LoadOnly)
    try:
        det = load_detector(saved)
        assert isinstance(det, Detector) and det.model_id == "tiny"
        assert built and built[0][0] == "fixed" and built[0][1] > 0  # the weights were read
        assert len(det.detect(images())) == 1
        card["architecture"] = "load_only"
        sidecar.write_text(json.dumps(card))
        with pytest.raises(DetectorLoadError, match="does not build from anunnaki model files"):
            load_detector(saved)
    finally:
        ARCHITECTURES.unregister("fixed")
        ARCHITECTURES.unregister("load_only")
