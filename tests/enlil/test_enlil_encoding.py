"""The camera's encoding in assessments and oracle training (issue 34, item 8).

The UAV's camera sends JPEG at quality 90; under the demo's fog the JPEG takes away what the
fog left of small objects, so uav-fog lost 9.3 % F1 through the camera where the PNG views
its oracle was trained and labelled on gave 3.1 %. An assessment and an oracle for such a
camera measure and learn through the same encoding, the clean reference too.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest
from enlil_helpers import ColourDetector, tiny_data

from anunnaki.enlil import (
    ContextSet,
    ContextSpec,
    EnlilError,
    OracleTrainConfig,
    evaluate_context,
    fixed_batch,
    held_out_frames,
    merge_context_sets,
    read_archive,
    train_oracle,
)
from anunnaki.enlil._oracle_train import perturbed_frames
from anunnaki.enlil._run import Job, clean_f1, run_search
from anunnaki.lec import DetectionResult, evaluate_detector
from anunnaki.messages import Image
from anunnaki.phenomena import PHENOMENA, CameraEncoding, PhenomenonError

FOG = {"density": 4.0, "intensity": 0.2}


class Seen(ColourDetector):
    """The colour detector that keeps every image it is given."""

    def __init__(self) -> None:
        self.images: list[npt.NDArray[np.uint8]] = []

    def detect(self, images: Sequence[npt.NDArray[np.uint8]]) -> list[DetectionResult]:
        self.images += [np.asarray(i).copy() for i in images]
        return super().detect(images)


def test_the_encoding_is_the_cameras_own_round_trip() -> None:
    image = tiny_data(1).image(0)
    jpeg = CameraEncoding.parse("jpeg:90")
    assert jpeg == CameraEncoding(90) == CameraEncoding.parse("JPEG") and str(jpeg) == "jpeg:90"
    sent = Image.from_array(image, encoding="jpeg", quality=90).to_array()
    assert jpeg is not None and np.array_equal(jpeg.apply(image), sent)
    assert not np.array_equal(sent, image)  # lossy: what the detector gets is not the render
    assert CameraEncoding.parse("none") is None and CameraEncoding.parse("") is None


@pytest.mark.parametrize(
    ("spec", "match"),
    [("png", "PNG is lossless"), ("jpg:90", "jpeg:QUALITY"), ("jpeg:5", "10-100")],
)
def test_a_bad_encoding_names_what_is_accepted(spec: str, match: str) -> None:
    with pytest.raises(PhenomenonError, match=match):
        CameraEncoding.parse(spec)


def test_the_detector_gets_the_phenomenon_then_the_encoding() -> None:
    data, det, jpeg = tiny_data(4), Seen(), CameraEncoding(40)
    fog = PHENOMENA.create("fog")
    evaluate_detector(det, data, phenomenon=fog, params=FOG, seed=5, encoding=jpeg)
    for i, seen in enumerate(det.images):
        assert np.array_equal(seen, jpeg.apply(fog.apply(data.image(i), FOG, seed=5 + i)))
    det.images.clear()
    evaluate_detector(det, data, encoding=jpeg)  # clean frames go through it too
    assert all(np.array_equal(s, jpeg.apply(data.image(i))) for i, s in enumerate(det.images))


def test_a_search_through_the_encoding_records_it(tmp_path: Path) -> None:
    data = tiny_data(6)
    job = Job(Seen(), data, "fog", batch_images=6, seed=2, encoding="jpeg")
    assert job.encoding == "jpeg:90"  # one spelling, in the archive and the cache key
    out = run_search(job, tmp_path / "a", search="random", budget=4, seed=0, batch=4)
    assert out.archive.meta.encoding == "jpeg:90"
    assert read_archive(tmp_path / "a").meta.as_dict()["encoding"] == "jpeg:90"
    jpeg = CameraEncoding(90)
    assert clean_f1(job) == evaluate_detector(ColourDetector(), data, encoding=jpeg).f1
    plain = Job(job.model, data, "fog", batch_images=6, seed=2)
    assert plain.key() != job.key()  # the clean F1 differs: no shared cache entry
    with pytest.raises(EnlilError, match="encoding"):  # another camera: no resume
        run_search(plain, tmp_path / "a", search="random", budget=8, seed=0, batch=4)
    with pytest.raises(PhenomenonError, match="unknown camera encoding"):
        Job(ColourDetector(), data, "fog", encoding="webp")


def test_a_context_through_the_encoding_is_measured_on_what_the_camera_sends() -> None:
    data, jpeg = tiny_data(6), CameraEncoding(30)
    fog = PHENOMENA.create("fog")
    unit = [0.5, 0.9]
    clean = evaluate_detector(ColourDetector(), data, encoding=jpeg).f1
    got = evaluate_context(ColourDetector(), data, fog, unit, clean_f1=clean, seed=1, encoding=jpeg)
    params = fog.from_vector(
        np.asarray(fog.bounds())[:, 0] + np.asarray(unit) * np.ptp(fog.bounds(), axis=1)
    )
    want = evaluate_detector(
        ColourDetector(), data, phenomenon=fog, params=params, seed=1, encoding=jpeg
    ).f1
    assert got.f1 == pytest.approx(want)


def _set(encoding: str, phenomenon: str = "fog") -> ContextSet:
    rng = np.random.default_rng(0)
    params = rng.random((6, 2))
    cats = np.asarray([0, 1, 2, 0, 1, 2])
    return ContextSet(phenomenon, ("density", "intensity"), params, cats, f"archive:{encoding}",
                      cats * 0.06, encoding)  # fmt: skip


def test_training_frames_go_through_the_encoding_clean_ones_too() -> None:
    data, jpeg = tiny_data(5), CameraEncoding(50)
    plain = perturbed_frames(data, [_set("jpeg:50")], 12, clean_fraction=0.4, seed=3)
    sent = perturbed_frames(data, [_set("jpeg:50")], 12, clean_fraction=0.4, seed=3, encoding=jpeg)
    assert (plain.category == sent.category).all() and (plain.phenomenon == 0).any()
    for a, b in zip(plain.frames, sent.frames, strict=True):
        assert np.array_equal(jpeg.apply(a), b)


def test_contexts_and_frames_must_share_the_encoding() -> None:
    with pytest.raises(EnlilError, match="was measured through the camera encoding"):
        merge_context_sets([_set("jpeg:90"), _set("", "brightness")])
    data = tiny_data(6)
    with pytest.raises(EnlilError, match=r"'jpeg:90'.*'none'.*oracle train --encoding"):
        train_oracle(data, data, [_set("jpeg:90")], model_id="colour",
                     config=OracleTrainConfig(frames=8, val_frames=8, epochs=1))  # fmt: skip


def test_held_out_frames_and_their_labels_go_through_the_encoding() -> None:
    """``oracle evaluate --encoding``: the held-out contexts are measured, and their frames
    predicted on, as the camera sends them."""
    data, jpeg, spec = tiny_data(12), CameraEncoding(30), ContextSpec("random", 3)
    plain = held_out_frames(ColourDetector(), data, "fog", spec, per_context=2, batch_images=6,
                            seed=1)  # fmt: skip
    sent = held_out_frames(ColourDetector(), data, "fog", spec, per_context=2, batch_images=6,
                           seed=1, encoding=jpeg)  # fmt: skip
    assert len(sent.frames) == len(plain.frames) == 6
    for a, b in zip(plain.frames, sent.frames, strict=True):
        assert np.array_equal(jpeg.apply(a), b)
    batch = fixed_batch(data, n=6, seed=1)
    assert sent.clean_f1 == evaluate_detector(ColourDetector(), batch, encoding=jpeg).f1
