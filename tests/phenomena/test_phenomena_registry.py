"""Registry, entry-point plugins, compositions, parameter specs, and the optional extra."""

from __future__ import annotations

import logging
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from anunnaki.errors import AnunnakiError, MissingExtraError
from anunnaki.phenomena import (
    PHENOMENA,
    Composition,
    Fog,
    Image,
    ParamSpec,
    Phenomenon,
    PhenomenonError,
    Raindrop,
    compose,
    synthetic_scene,
)

BUILTINS = ["brightness", "fog", "hsl", "motion_blur", "noise", "rain", "raindrop", "snow"]


class Invert(Phenomenon):
    """A minimal third-party phenomenon for the registry tests."""

    name = "invert"
    stochastic = False
    params: tuple[ParamSpec, ...] = (
        ParamSpec("amount", 0.0, 1.0, "fraction", "Blend toward the negative.", 0.0),
    )

    def perturb(self, image: Image, params: dict[str, float], seed: int) -> Image:
        a = params["amount"]
        return np.rint((1 - a) * image + a * (255 - image.astype(np.float64))).astype(np.uint8)


# -- lookup --------------------------------------------------------------------------------


def test_builtins_are_available_sorted() -> None:
    names = PHENOMENA.names()  # installed plugins may add more
    assert names == sorted(names) and set(BUILTINS) <= set(names)
    assert PHENOMENA.copy(entry_points=False).names() == BUILTINS


def test_lookup_by_name_or_instance() -> None:
    assert isinstance(PHENOMENA.create("fog"), Fog)
    assert isinstance(PHENOMENA.create(" raindrop "), Raindrop)
    fog = Fog()
    assert PHENOMENA.create(fog) is fog
    both = PHENOMENA.create("fog+raindrop")
    assert isinstance(both, Composition)
    assert both.name == "fog+raindrop"


def test_unknown_name_lists_the_valid_names() -> None:
    with pytest.raises(PhenomenonError, match="unknown phenomenon 'smog'") as info:
        PHENOMENA.create("smog")
    for name in BUILTINS:
        assert name in str(info.value)
    with pytest.raises(PhenomenonError, match="unknown phenomenon 'smog'"):
        PHENOMENA.create("fog+smog")


@pytest.mark.parametrize("bad", [None, 3, Fog, ["fog"]])
def test_lookup_rejects_other_types(bad: object) -> None:
    with pytest.raises(PhenomenonError, match="name or a Phenomenon instance"):
        PHENOMENA.create(bad)  # type: ignore[arg-type]


def test_register_in_a_private_registry() -> None:
    registry = PHENOMENA.copy(entry_points=False)
    assert registry.register(Invert) is Invert
    assert registry.register(Invert) is Invert  # idempotent
    assert "invert" in registry.names()
    ph = registry.create("invert")
    assert "invert" in registry.names()
    assert registry.create("fog+invert").param_names[-1] == "invert.amount"  # combines too
    out = ph.apply(np.zeros((4, 4, 3), np.uint8), {"amount": 1.0}, seed=0)
    assert out.min() == 255
    assert "invert" not in PHENOMENA.names()  # the default registry is untouched


def test_the_slot_registers_by_decorator() -> None:
    @PHENOMENA.register
    class Grey(Invert):
        name = "grey_out"

    try:
        assert isinstance(PHENOMENA.create("grey_out"), Grey)
        assert isinstance(compose("grey_out", "fog").steps[0].phenomenon, Grey)
    finally:
        PHENOMENA.unregister("grey_out")
    assert "grey_out" not in PHENOMENA.names()


def test_name_clash_needs_replace() -> None:
    registry = PHENOMENA.copy(entry_points=False)

    class OtherFog(Invert):
        name = "fog"

    with pytest.raises(PhenomenonError, match="already registered as 'fog'"):
        registry.register(OtherFog)
    registry.register(OtherFog, replace=True)
    assert isinstance(registry.create("fog"), OtherFog)
    assert isinstance(PHENOMENA.create("fog"), Fog)  # the copy was private


def test_register_rejects_bad_classes() -> None:
    registry = PHENOMENA.copy(entry_points=False)

    class Abstract(Phenomenon):
        name = "abstract"
        params = (ParamSpec("a", 0, 1, "u", "d", 0),)

    class BadName(Invert):
        name = "has space"

    class NoParams(Invert):
        params = "not a tuple"  # type: ignore[assignment]

    class Dupes(Invert):
        params = (ParamSpec("a", 0, 1, "u", "d", 0), ParamSpec("a", 0, 1, "u", "d", 0))

    class BadTarget(Invert):
        strength_target: ClassVar = {"nope": 1.0}

    cases = [
        (Abstract, "abstract; implement perturb"),
        (BadName, "must be an identifier"),
        (NoParams, "tuple of ParamSpec"),
        (Dupes, "duplicate parameter names"),
        (BadTarget, "unknown parameters"),
        (int, "not a subclass"),
        (Invert(), "not a subclass"),
    ]
    for cls, message in cases:
        with pytest.raises(PhenomenonError, match=message):
            registry.register(cls)  # type: ignore[type-var]


def test_a_perturb_returning_nonsense_is_caught(scene64: np.ndarray) -> None:
    class Shrink(Invert):
        name = "shrink"

        def perturb(self, image: Image, params: dict[str, float], seed: int) -> Image:
            return image[:2]

    with pytest.raises(PhenomenonError, match=r"shrink: perturb\(\) must return a uint8 array"):
        Shrink().apply(scene64, {"amount": 0.5}, seed=0)


# -- entry points --------------------------------------------------------------------------

PLUGIN = '''
"""A fake third-party plugin."""
import numpy as np
from anunnaki.phenomena import ParamSpec, Phenomenon


class Sepia(Phenomenon):
    name = "sepia"
    stochastic = False
    params = (ParamSpec("amount", 0.0, 1.0, "fraction", "Blend toward sepia.", 0.0),)
    strength_target = {"amount": 1.0}

    def perturb(self, image, params, seed):
        a = params["amount"]
        matrix = np.array([[0.393, 0.769, 0.189], [0.349, 0.686, 0.168], [0.272, 0.534, 0.131]])
        sepia = image.astype(np.float64) @ matrix.T
        out = (1 - a) * image + a * sepia
        return np.clip(np.rint(out), 0, 255).astype(np.uint8)


class FakeFog(Sepia):
    name = "fog"


NOT_A_PHENOMENON = 42
'''


ENTRY_POINTS = {
    "sepia": "fake_anunnaki_plugin:Sepia",
    "broken": "fake_no_such_module:Nope",
    "answer": "fake_anunnaki_plugin:NOT_A_PHENOMENON",
    "fog": "fake_anunnaki_plugin:FakeFog",
}


@pytest.fixture
def install_fake_plugin(install_distribution: Callable[..., Path]) -> Callable[[], Path]:
    """Installs a fake distribution whose entry points name one good and three bad plugins."""
    modules = {"fake_anunnaki_plugin": PLUGIN}
    entry_points = {str(PHENOMENA.group): ENTRY_POINTS}
    return lambda: install_distribution("fake-anunnaki-plugin", entry_points, modules=modules)


@pytest.fixture
def plugin_path(install_fake_plugin: Callable[[], Path]) -> Path:
    return install_fake_plugin()


def test_entry_point_plugins_are_found_by_name(
    plugin_path: Path, caplog: pytest.LogCaptureFixture, scene64: np.ndarray
) -> None:
    registry = PHENOMENA.copy()
    with caplog.at_level(logging.WARNING, logger="anunnaki.phenomena"):
        sepia = registry.create("sepia")
    assert type(sepia).__name__ == "Sepia"
    assert {*BUILTINS, "sepia"} <= set(registry.names())
    out = sepia.apply(scene64, sepia.strength_params(1.0), seed=0)
    assert out.shape == scene64.shape and not np.array_equal(out, scene64)
    # Plugins take part in compositions like built-ins.
    assert registry.create("sepia+fog").param_names[0] == "sepia.amount"
    # Broken ones are logged and skipped; a plugin cannot shadow a built-in.
    log = caplog.text
    assert "'broken'" in log and "fake_no_such_module" in log
    assert "'answer'" in log and "not a subclass" in log
    assert "'fog'" in log and "already taken" in log
    assert isinstance(registry.create("fog"), Fog)


def test_entry_points_load_lazily_on_first_lookup(
    install_fake_plugin: Callable[[], Path], caplog: pytest.LogCaptureFixture
) -> None:
    registry = PHENOMENA.copy()  # created before the plugin is installed
    install_fake_plugin()
    assert isinstance(registry.create("fog"), Fog)  # a built-in: no entry point is loaded
    assert "fake_anunnaki_plugin" not in sys.modules
    with caplog.at_level(logging.WARNING, logger="anunnaki.phenomena"):
        assert "sepia" in registry.names()
    assert "sepia" not in PHENOMENA.copy(entry_points=False).names()


# -- compositions --------------------------------------------------------------------------


def test_composition_prefixes_labels_and_pins(scene64: np.ndarray) -> None:
    comp = compose(("rain", {"slant": 20, "drop_length": 7.6}), "raindrop", Raindrop())
    assert comp.name == "rain+raindrop+raindrop"
    assert [s.label for s in comp.steps] == ["rain", "raindrop", "raindrop_2"]
    assert "rain.slant" not in comp.param_names
    assert "rain.intensity" in comp.param_names
    assert comp.steps[0].fixed == {"slant": 20.0, "drop_length": 8.0}  # integer rounded
    split = comp.split(comp.strength_params(0.5))
    assert split["rain"]["slant"] == 20.0
    assert split["raindrop_2"]["radius"] == pytest.approx(0.15)
    assert repr(comp).startswith("Composition((Rain(), {'slant': 20.0")


def test_composition_equals_sequential_application_with_spawned_seeds(
    scene64: np.ndarray,
) -> None:
    comp = compose("noise", "fog", "noise")
    params = comp.strength_params(0.6)
    children = np.random.SeedSequence(42).spawn(3)
    seeds = [int(c.generate_state(1, dtype=np.uint64)[0]) for c in children]
    expected = scene64
    for step, seed in zip(comp.steps, seeds, strict=True):
        expected = step.phenomenon.apply(expected, comp.split(params)[step.label], seed)
    np.testing.assert_array_equal(comp.apply(scene64, params, seed=42), expected)
    assert len(set(seeds)) == 3  # the two noise steps draw different noise


def test_name_with_plus_equals_compose(scene64: np.ndarray) -> None:
    by_name = PHENOMENA.create("fog+raindrop")
    by_call = compose("fog", "raindrop")
    params = by_call.strength_params(0.8)
    np.testing.assert_array_equal(
        by_name.apply(scene64, params, seed=3), by_call.apply(scene64, params, seed=3)
    )


def test_nested_composition_gets_a_valid_label() -> None:
    outer = compose(compose("fog", "noise"), "hsl")
    assert outer.param_names[0] == "fog_noise.fog.density"


@pytest.mark.parametrize(
    ("steps", "message"),
    [
        ((), "at least one step"),
        ((("fog", {"density": 11}),), r"'density' = 11 is out of bounds.*\[1, 10\] layers"),
        ((("fog", {"thickness": 1}),), "unknown parameter 'thickness'"),
        ((("fog", {"density": 2}, "extra"),), "pair"),
        (("fog", "smog"), "unknown phenomenon 'smog'"),
    ],
)
def test_composition_rejects_bad_steps(steps: tuple[object, ...], message: str) -> None:
    with pytest.raises(PhenomenonError, match=message):
        compose(*steps)  # type: ignore[arg-type]


# -- parameter specs and errors ------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"name": "1x"}, "invalid parameter name"),
        ({"low": 1.0, "high": 1.0}, "empty"),
        ({"default_identity": 2.0}, "default_identity = 2 is outside"),
        ({"default": -1.0}, "default = -1 is outside"),
        ({"high": float("nan")}, "not a finite number"),
        ({"integer": True, "high": 1.5}, "integer bounds"),
    ],
)
def test_param_spec_validates_itself(kwargs: dict[str, object], message: str) -> None:
    base: dict[str, object] = {
        "name": "a",
        "low": 0.0,
        "high": 1.0,
        "unit": "u",
        "description": "d",
        "default_identity": 0.0,
    }
    with pytest.raises(PhenomenonError, match=message):
        ParamSpec(**{**base, **kwargs})  # type: ignore[arg-type]


def test_error_carries_context() -> None:
    with pytest.raises(PhenomenonError) as info:
        Fog().validate({"density": 12, "intensity": 0.5})
    error = info.value
    assert isinstance(error, AnunnakiError) and isinstance(error, ValueError)
    assert str(error) == (
        "fog: parameter 'density' = 12 is out of bounds; expected density in [1, 10] layers"
    )
    assert (error.phenomenon, error.parameter, error.value) == ("fog", "density", 12)
    assert (error.bounds, error.unit) == ((1.0, 10.0), "layers")


def test_float_image_error_says_how_to_convert() -> None:
    with pytest.raises(PhenomenonError, match=r"hint: convert float images"):
        Fog().apply(np.zeros((8, 8, 3), np.float32), {"density": 1, "intensity": 0}, seed=0)


def test_synthetic_scene_is_deterministic() -> None:
    a, b = synthetic_scene(40, 60, seed=2), synthetic_scene(40, 60, seed=2)
    assert a.shape == (40, 60, 3) and a.dtype == np.uint8
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, synthetic_scene(40, 60, seed=3))
    with pytest.raises(PhenomenonError, match="at least 8x8"):
        synthetic_scene(4, 60)


# -- the phenomena extra ----------------------------------------------------------------------


def test_importing_phenomena_does_not_import_cv2_or_albumentations() -> None:
    code = (
        "import sys, anunnaki.phenomena as p; p.PHENOMENA.create('fog+rain'); "
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('cv2', 'albumentations')); "
        "assert not bad, bad"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)


def test_missing_opencv_names_the_extra(
    monkeypatch: pytest.MonkeyPatch, scene64: np.ndarray
) -> None:
    monkeypatch.setitem(sys.modules, "cv2", None)
    with pytest.raises(MissingExtraError, match=r"opencv-python-headless.*anunnaki\[phenomena\]"):
        Fog().apply(scene64, {"density": 2, "intensity": 0.5}, seed=0)
    # Phenomena that need only numpy keep working.
    PHENOMENA.create("brightness").apply(scene64, {"gain": 0.5}, seed=0)


def test_missing_albumentations_names_the_extra(
    monkeypatch: pytest.MonkeyPatch, scene64: np.ndarray
) -> None:
    for module in (
        "albumentations",
        "albumentations.augmentations",
        "albumentations.augmentations.pixel",
        "albumentations.augmentations.pixel.functional",
    ):
        monkeypatch.setitem(sys.modules, module, None)
    with pytest.raises(MissingExtraError, match=r"albumentations.*anunnaki\[phenomena\]"):
        PHENOMENA.create("snow").apply(scene64, {"snow_point": 0.5}, seed=0)
