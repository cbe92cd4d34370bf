"""One context's F1, drop and category on a fixed batch; normalised ↔ phenomenon vectors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from enlil_helpers import ColourDetector, tiny_data

from anunnaki.enlil import (
    EnlilError,
    evaluate_context,
    fixed_batch,
    normalise,
    relative_drop,
    to_phenomenon_vector,
)
from anunnaki.lec import evaluate_detector
from anunnaki.phenomena import PHENOMENA


def test_vectors_round_trip_through_the_bounds() -> None:
    fog = PHENOMENA.create("fog")
    unit = np.linspace(0.0, 1.0, len(fog.param_names))
    raw = to_phenomenon_vector("fog", unit)
    low, high = np.asarray(fog.bounds()).T
    assert np.allclose(raw, low + unit * (high - low))
    assert np.allclose(normalise("fog", raw), unit)
    comp = PHENOMENA.create("rain+brightness")
    assert to_phenomenon_vector(comp, np.zeros(len(comp.param_names))).shape == (
        len(comp.param_names),
    )


def test_bad_vectors_are_refused_with_the_fix() -> None:
    with pytest.raises(EnlilError, match=r"in \[0, 1\]"):
        to_phenomenon_vector("brightness", [1.5, 0.5])
    with pytest.raises(EnlilError, match="shape"):
        to_phenomenon_vector("fog", [0.5])


def test_fixed_batch_is_a_function_of_the_seed() -> None:
    data = tiny_data(20)
    a, b = fixed_batch(data, n=5, seed=3), fixed_batch(data, n=5, seed=3)
    assert len(a) == 5
    assert all(np.array_equal(a.image(i), b.image(i)) for i in range(5))
    assert len(fixed_batch(data, n=50)) == 20
    with pytest.raises(EnlilError, match="positive"):
        fixed_batch(data, n=0)


def test_fixed_batch_reads_each_image_from_disk_once(tmp_path: Path) -> None:
    tiny_data(10).to_coco(tmp_path / "val.json")
    batch = fixed_batch(tmp_path, "val", n=4, seed=1)
    first = [batch.image(i).copy() for i in range(4)]
    pngs = list(tmp_path.rglob("*.png"))
    assert len(pngs) == 10
    for png in pngs:  # every context after the first reads memory
        png.unlink()
    assert all(np.array_equal(batch.image(i), first[i]) for i in range(4))
    assert len(fixed_batch(tiny_data(3), n=5)) == 3


def test_darkness_is_category_two_and_identity_is_zero() -> None:
    det, batch = ColourDetector(), tiny_data(8)
    clean = evaluate_detector(det, batch).f1
    assert clean == 1.0
    bright = PHENOMENA.create("brightness")
    dark = evaluate_context(det, batch, bright, [0.0, 0.5], clean_f1=clean, seed=0)
    assert dark.f1 < 0.5 and dark.category == 2 and dark.drop == pytest.approx(1 - dark.f1)
    ident = normalise(bright, bright.to_vector(bright.identity_params()))
    same = evaluate_context(det, batch, "brightness", ident, clean_f1=clean, seed=0)
    assert (same.f1, same.drop, same.category) == (1.0, 0.0, 0)
    assert np.allclose(same.params, ident)


def test_relative_drop() -> None:
    assert relative_drop(0.8, 0.6) == pytest.approx(0.25)
    assert relative_drop(0.8, 0.9) == 0.0
    assert relative_drop(0.0, 0.0) == 0.0
