"""Occlusion masks: a phenomenon says how much of each pixel it replaced, as ``apply`` does it."""

from __future__ import annotations

from types import MappingProxyType

import numpy as np
import pytest

from anunnaki.phenomena import (
    HIDDEN,
    Image,
    Mask,
    ParamSpec,
    Phenomenon,
    PhenomenonError,
    Raindrop,
    compose,
)


class Blot(Phenomenon):
    """A test occluder: one black square at a place drawn from the seed."""

    name = "blot"
    params = (ParamSpec("size", 0.0, 0.5, "image width", "Side of the square.", 0.0),)
    strength_target = MappingProxyType({"size": 0.4})

    def _where(self, height: int, width: int, size: float, seed: int) -> tuple[int, int, int]:
        side = round(size * width)
        rng = np.random.default_rng(seed)
        return side, int(rng.integers(0, height - side + 1)), int(rng.integers(0, width - side + 1))

    def occlusion_mask(
        self, height: int, width: int, params: dict[str, float], seed: int
    ) -> Mask | None:
        side, top, left = self._where(height, width, params["size"], seed)
        mask = np.zeros((height, width), np.float32)
        mask[top : top + side, left : left + side] = 1.0
        return mask

    def perturb(self, image: Image, params: dict[str, float], seed: int) -> Image:
        side, top, left = self._where(*image.shape[:2], params["size"], seed)
        out = image.copy()
        out[top : top + side, left : left + side] = 0
        return out


class Tint(Phenomenon):
    """A third-party phenomenon that knows nothing of masks."""

    name = "tint"
    stochastic = False
    params = (ParamSpec("amount", 0.0, 1.0, "fraction", "Red tint.", 0.0),)

    def perturb(self, image: Image, params: dict[str, float], seed: int) -> Image:
        out = image.astype(np.float64)
        out[..., 0] += 100 * params["amount"]
        return np.clip(out, 0, 255).astype(np.uint8)


def changed(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.asarray(np.any(a != b, axis=2))


def test_hidden_threshold_is_half() -> None:
    assert HIDDEN == 0.5


def test_raindrop_mask_is_its_blend_weight(texture64: np.ndarray) -> None:
    params = {"x": 0.4, "y": 0.6, "radius": 0.2, "feather": 0.5}
    out = Raindrop().apply(texture64, params, seed=0)
    mask = Raindrop().occlusion(texture64.shape, params, seed=0)
    assert mask is not None
    rows, cols = np.mgrid[0:64, 0:64]
    distance = np.hypot(cols + 0.5 - 0.4 * 64, rows + 0.5 - 0.6 * 64)
    assert np.all(mask[distance <= 0.2 * 64] == 1.0)  # the disc is gone
    assert np.all(mask[distance > 0.2 * 64 * 1.5 + 1e-9] == 0.0)  # outside: untouched
    edge = (distance > 0.2 * 64) & (distance < 0.2 * 64 * 1.5)
    assert mask[edge].min() > 0.0 and mask[edge].max() < 1.0  # the soft edge blends
    # Every pixel the drop changed is one the mask covers, and vice versa on the disc.
    assert not np.any(changed(out, texture64) & (mask == 0.0))
    assert changed(out, texture64)[mask == 1.0].mean() > 0.9


def test_no_drop_no_mask_values() -> None:
    mask = Raindrop().occlusion((16, 16), {"x": 0.5, "y": 0.5, "radius": 0.0}, seed=0)
    assert mask is not None and not mask.any()


def test_same_seed_same_drops_in_a_composition(texture64: np.ndarray) -> None:
    """A composition asks each step with the seed it applies it with."""
    both = compose(Blot(), Blot())
    params = {"blot.size": 0.25, "blot_2.size": 0.25}
    for seed in (0, 1, 7):
        out = both.apply(texture64, params, seed=seed)
        mask = both.occlusion(texture64.shape, params, seed=seed)
        assert mask is not None
        np.testing.assert_array_equal(np.all(out == 0, axis=2), mask == 1.0)


def test_composition_combines_masks_as_union(texture64: np.ndarray) -> None:
    drops = compose("raindrop", "raindrop")
    params = {
        "raindrop.x": 0.3, "raindrop.y": 0.5, "raindrop.radius": 0.15,
        "raindrop_2.x": 0.45, "raindrop_2.y": 0.5, "raindrop_2.radius": 0.15,
    }  # fmt: skip
    mask = drops.occlusion((64, 64), params, seed=5)
    one = Raindrop().occlusion((64, 64), {"x": 0.3, "y": 0.5, "radius": 0.15}, seed=0)
    two = Raindrop().occlusion((64, 64), {"x": 0.45, "y": 0.5, "radius": 0.15}, seed=0)
    assert mask is not None and one is not None and two is not None
    np.testing.assert_allclose(mask, 1 - (1 - one) * (1 - two), atol=1e-6)
    assert np.all(mask >= np.maximum(one, two) - 1e-6)


def test_phenomena_without_a_mask_keep_working(texture64: np.ndarray) -> None:
    tint = Tint()
    assert tint.occlusion((64, 64), {"amount": 0.5}, seed=0) is None
    assert tint.apply(texture64, {"amount": 0.5}, seed=0).shape == texture64.shape
    assert (
        compose(Tint(), "fog").occlusion((64, 64), compose(Tint(), "fog").strength_params(1), 0)
        is None
    )
    mixed = compose(Tint(), "raindrop")
    params = {"tint.amount": 1.0, "raindrop.x": 0.5, "raindrop.y": 0.5, "raindrop.radius": 0.2}
    alone = Raindrop().occlusion((64, 64), {"x": 0.5, "y": 0.5, "radius": 0.2}, seed=0)
    np.testing.assert_array_equal(mixed.occlusion((64, 64), params, seed=2), alone)


def test_a_bad_mask_is_refused() -> None:
    class Bad(Tint):
        name = "bad"

        def occlusion_mask(
            self, height: int, width: int, params: dict[str, float], seed: int
        ) -> Mask | None:
            return np.zeros((height + 1, width), np.float32)

    with pytest.raises(PhenomenonError, match="occlusion_mask"):
        Bad().occlusion((8, 8), {"amount": 0.1}, seed=0)
