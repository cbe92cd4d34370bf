"""The one contract suite every phenomenon passes: built-ins, compositions and plugins alike.

To run it against a new phenomenon, add its name (or a factory) to ``CASES``.
"""

from __future__ import annotations

import functools
import math
import pickle
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from anunnaki.errors import AnunnakiError
from anunnaki.phenomena import PHENOMENA, Phenomenon, PhenomenonError, compose, synthetic_scene

CASES: dict[str, Callable[[], Phenomenon]] = {
    name: functools.partial(PHENOMENA.create, name) for name in PHENOMENA.names()
}
CASES["fog+raindrop"] = lambda: PHENOMENA.create("fog+raindrop")
CASES["raindrop*2+noise"] = lambda: compose("raindrop", "raindrop", "noise")
CASES["rain(pinned)+hsl"] = lambda: compose(("rain", {"slant": 20.0, "blur": 1}), "hsl")

BUILTINS = {"brightness", "fog", "hsl", "motion_blur", "noise", "rain", "raindrop", "snow"}


@pytest.fixture(params=sorted(CASES), ids=str)
def ph(request: pytest.FixtureRequest) -> Phenomenon:
    return CASES[request.param]()


def mad(a: np.ndarray, b: np.ndarray) -> float:
    """Mean absolute difference in grey levels."""
    return float(np.abs(a.astype(np.int16) - b.astype(np.int16)).mean())


def test_all_builtins_are_in_the_suite() -> None:
    assert set(CASES) >= BUILTINS


# -- metadata ------------------------------------------------------------------------------


def test_parameter_space_is_well_formed(ph: Phenomenon) -> None:
    assert ph.name and ph.params
    names = ph.param_names
    assert len(set(names)) == len(names)
    assert ph.bounds() == [(spec.low, spec.high) for spec in ph.params]
    for spec in ph.params:
        assert spec.unit and spec.description
        assert spec.low <= spec.default_identity <= spec.high
    assert any(spec.required for spec in ph.params), "need a required parameter"
    assert list(ph.identity_params()) == list(names)


# -- shape, dtype, determinism ---------------------------------------------------------------


@pytest.mark.parametrize("strength", [0.5, 1.0])
def test_shape_and_dtype_kept_and_input_untouched(
    ph: Phenomenon, scene64: np.ndarray, scene128: np.ndarray, strength: float
) -> None:
    for image in (scene64, scene128, scene128.copy()):
        before = image.copy()
        out = ph.apply(image, ph.strength_params(strength), seed=5)
        assert out.shape == image.shape
        assert out.dtype == np.uint8
        assert out.flags.writeable and out.flags.c_contiguous
        assert not np.shares_memory(out, image)
        np.testing.assert_array_equal(image, before)


def test_same_image_params_seed_give_same_bytes(ph: Phenomenon, scene128: np.ndarray) -> None:
    params = ph.strength_params(0.7)
    first = ph.apply(scene128, params, seed=11)
    again = ph.apply(scene128, params, seed=11)
    fresh = pickle.loads(pickle.dumps(ph)).apply(scene128.copy(), dict(params), seed=11)
    strided = ph.apply(np.ascontiguousarray(scene128[:, ::-1])[:, ::-1], params, seed=11)
    assert first.tobytes() == again.tobytes() == fresh.tobytes() == strided.tobytes()


def test_seed_matters_only_for_stochastic(ph: Phenomenon, scene64: np.ndarray) -> None:
    params = ph.strength_params(0.7)
    outputs = {ph.apply(scene64, params, seed=seed).tobytes() for seed in range(4)}
    if ph.stochastic:
        assert len(outputs) > 1
    else:
        assert len(outputs) == 1


# -- identity and strength -----------------------------------------------------------------


def test_identity_params_leave_the_image_unchanged(ph: Phenomenon, scene128: np.ndarray) -> None:
    assert ph.strength_params(0.0) == ph.identity_params()
    for seed in (0, 1):
        out = ph.apply(scene128, ph.identity_params(), seed=seed)
        assert mad(out, scene128) <= 1.0
        np.testing.assert_array_equal(out, scene128)  # exact for every built-in


def test_full_strength_changes_the_image(ph: Phenomenon, scene128: np.ndarray) -> None:
    assert mad(ph.apply(scene128, ph.strength_params(1.0), seed=0), scene128) > 1.0


@pytest.mark.parametrize("strength", [-0.1, 1.5, math.nan, math.inf, "0.5", True])
def test_bad_strength_is_rejected(ph: Phenomenon, strength: object) -> None:
    with pytest.raises(PhenomenonError, match=r"strength.*\[0, 1\]"):
        ph.strength_params(strength)  # type: ignore[arg-type]


# -- parameter validation ------------------------------------------------------------------


def _bounds_text(low: float, high: float) -> str:
    return f"[{low:g}, {high:g}]"


def test_out_of_bounds_values_are_rejected(ph: Phenomenon, scene64: np.ndarray) -> None:
    for spec in ph.params:
        width = spec.high - spec.low
        for bad in (spec.high + 0.1 * width, spec.low - 0.1 * width):
            params = {**ph.identity_params(), spec.name: bad}
            with pytest.raises(PhenomenonError) as info:
                ph.apply(scene64, params, seed=0)
            message = str(info.value)
            assert isinstance(info.value, AnunnakiError)
            assert ph.name in message
            assert repr(spec.name) in message
            assert f"{bad:g}" in message
            assert _bounds_text(spec.low, spec.high) in message
            assert spec.unit in message
            assert info.value.parameter == spec.name
            assert info.value.bounds == (spec.low, spec.high)


def test_missing_required_parameter_is_rejected(ph: Phenomenon) -> None:
    for spec in ph.params:
        params = ph.identity_params()
        del params[spec.name]
        if not spec.required:
            assert ph.validate(params)[spec.name] == spec.default
            continue
        with pytest.raises(PhenomenonError, match="missing parameter") as info:
            ph.validate(params)
        assert repr(spec.name) in str(info.value)
        assert _bounds_text(spec.low, spec.high) in str(info.value)


def test_unknown_parameter_is_rejected_listing_valid_ones(ph: Phenomenon) -> None:
    with pytest.raises(PhenomenonError, match="unknown parameter 'bogus'") as info:
        ph.validate({**ph.identity_params(), "bogus": 1.0})
    for spec in ph.params:
        assert f"{spec.name} in {_bounds_text(spec.low, spec.high)}" in str(info.value)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, "0.5", None, True, [1.0]])
def test_non_finite_or_non_numeric_values_are_rejected(ph: Phenomenon, bad: object) -> None:
    spec = ph.params[0]
    with pytest.raises(PhenomenonError) as info:
        ph.validate({**ph.identity_params(), spec.name: bad})
    assert repr(spec.name) in str(info.value)
    assert _bounds_text(spec.low, spec.high) in str(info.value)


def test_params_must_be_a_mapping(ph: Phenomenon) -> None:
    with pytest.raises(PhenomenonError, match="mapping"):
        ph.validate([("x", 1.0)])  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "image",
    [
        np.zeros((16, 16, 3), np.float32),
        np.zeros((16, 16), np.uint8),
        np.zeros((16, 16, 4), np.uint8),
        np.zeros((16, 16, 1), np.uint8),
        np.zeros((0, 16, 3), np.uint8),
        np.zeros((16, 16, 3), np.uint16),
        [[[0, 0, 0]]],
    ],
    ids=["float32", "grey", "rgba", "one-channel", "empty", "uint16", "list"],
)
def test_wrong_images_are_rejected(ph: Phenomenon, image: object) -> None:
    with pytest.raises(PhenomenonError, match=r"\(H, W, 3\).*uint8"):
        ph.apply(image, ph.identity_params(), seed=0)  # type: ignore[arg-type]


@pytest.mark.parametrize("seed", [-1, 1.5, "3", None, True])
def test_bad_seeds_are_rejected(ph: Phenomenon, scene64: np.ndarray, seed: object) -> None:
    with pytest.raises(PhenomenonError, match="seed"):
        ph.apply(scene64, ph.identity_params(), seed=seed)  # type: ignore[arg-type]


def test_numpy_integer_seed_is_accepted(ph: Phenomenon, scene64: np.ndarray) -> None:
    params = ph.strength_params(0.5)
    a = ph.apply(scene64, params, seed=np.int64(9))  # type: ignore[arg-type]
    np.testing.assert_array_equal(a, ph.apply(scene64, params, seed=9))


# -- the vector view -----------------------------------------------------------------------


def test_vector_round_trip(ph: Phenomenon) -> None:
    for params in (ph.identity_params(), ph.strength_params(0.37), ph.strength_params(1.0)):
        vector = ph.to_vector(params)
        assert vector.dtype == np.float64
        assert vector.shape == (len(ph.params),)
        assert ph.from_vector(vector) == params
        assert ph.from_vector(list(vector)) == params
    with pytest.raises(PhenomenonError, match="shape"):
        ph.from_vector(np.zeros(len(ph.params) + 1))
    with pytest.raises(PhenomenonError, match="shape"):
        ph.from_vector(np.zeros((1, len(ph.params))))


@settings(
    max_examples=12,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(data=st.data())
def test_random_parameters_within_bounds_never_crash(ph: Phenomenon, data: st.DataObject) -> None:
    image = synthetic_scene(48, 64)
    vector = [
        data.draw(st.floats(spec.low, spec.high, allow_nan=False), label=spec.name)
        for spec in ph.params
    ]
    seed = data.draw(st.integers(0, 2**63), label="seed")
    params = ph.from_vector(vector)
    out = ph.apply(image, params, seed=seed)
    assert out.shape == image.shape and out.dtype == np.uint8
    assert ph.from_vector(ph.to_vector(params)) == params
    for spec in ph.params:
        if not spec.integer:
            assert params[spec.name] == pytest.approx(vector[ph.param_names.index(spec.name)])
        else:
            assert float(params[spec.name]).is_integer()


# -- occlusion masks -------------------------------------------------------------------------


@pytest.mark.parametrize("strength", [0.0, 0.5, 1.0])
def test_occlusion_is_none_or_a_mask_of_the_frame(ph: Phenomenon, strength: float) -> None:
    params = ph.strength_params(strength)
    mask = ph.occlusion((48, 40), params, seed=3)
    if mask is None:
        return
    assert mask.shape == (48, 40) and mask.dtype == np.float32
    assert float(mask.min()) >= 0.0 and float(mask.max()) <= 1.0
    np.testing.assert_array_equal(mask, ph.occlusion((48, 40, 3), params, seed=3))
    if strength == 0.0:  # the identity hides nothing
        assert not mask.any()


def test_occlusion_validates_like_apply(ph: Phenomenon) -> None:
    params = ph.strength_params(0.5)
    with pytest.raises(PhenomenonError, match="seed"):
        ph.occlusion((8, 8), params, seed=-1)
    with pytest.raises(PhenomenonError, match="height, width"):
        ph.occlusion((0, 8), params, seed=0)
    with pytest.raises(PhenomenonError, match="unknown parameter"):
        ph.occlusion((8, 8), {**params, "nope": 1.0}, seed=0)
