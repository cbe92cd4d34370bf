"""What each phenomenon does: measured on small synthetic images."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from anunnaki.phenomena import (
    HSL,
    Brightness,
    Fog,
    MotionBlur,
    Noise,
    Rain,
    Raindrop,
    Snow,
    compose,
    motion_kernel,
    reuse_fog_noise,
)


def grey(image: np.ndarray) -> np.ndarray:
    return np.asarray(image.astype(np.float64) @ np.array([0.299, 0.587, 0.114]))


# -- raindrop ------------------------------------------------------------------------------


def pixel_distance(shape: tuple[int, ...], x: float, y: float) -> np.ndarray:
    """Distance of each pixel centre from the drop centre, in pixels."""
    height, width = shape[:2]
    rows, cols = np.mgrid[0:height, 0:width]
    return np.asarray(np.hypot(cols + 0.5 - x * width, rows + 0.5 - y * height))


@pytest.mark.parametrize(
    ("x", "y", "radius", "feather"),
    [
        (0.5, 0.5, 0.2, 0.25),
        (0.3, 0.7, 0.1, 0.0),
        (0.0, 0.0, 0.3, 1.0),
        (1.0, 0.2, 0.05, 0.5),
        (0.51, 0.49, 0.5, 0.3),
        (0.5, 0.5, 0.004, 0.0),  # smaller than a pixel
    ],
)
def test_raindrop_touches_nothing_outside_radius_plus_feather(
    texture64: np.ndarray, x: float, y: float, radius: float, feather: float
) -> None:
    params = {"x": x, "y": y, "radius": radius, "feather": feather}
    out = Raindrop().apply(texture64, params, seed=0)
    width = texture64.shape[1]
    distance = pixel_distance(texture64.shape, x, y)
    outside = distance > radius * width * (1 + feather) + 1e-9
    np.testing.assert_array_equal(out[outside], texture64[outside])
    inside = distance <= radius * width
    if inside.sum() >= 4:  # the refracted, blurred view differs from what it covers
        changed = np.any(out != texture64, axis=2)
        assert changed[inside].mean() > 0.9


def test_several_raindrops_only_touch_their_discs(texture64: np.ndarray) -> None:
    drops = compose("raindrop", "raindrop", "raindrop")
    assert drops.param_names[4:6] == ("raindrop_2.x", "raindrop_2.y")
    centres = [(0.2, 0.3, 0.1), (0.7, 0.6, 0.15), (0.5, 0.9, 0.05)]
    params = {}
    for label, (x, y, r) in zip(("raindrop", "raindrop_2", "raindrop_3"), centres, strict=True):
        params.update({f"{label}.x": x, f"{label}.y": y, f"{label}.radius": r})
    out = drops.apply(texture64, params, seed=0)
    outside = np.ones(texture64.shape[:2], bool)
    for x, y, r in centres:
        outside &= pixel_distance(texture64.shape, x, y) > r * 64 * 1.25 + 1e-9
    np.testing.assert_array_equal(out[outside], texture64[outside])
    assert np.any(out[~outside] != texture64[~outside])


def test_raindrop_shows_an_inverted_view(scene128: np.ndarray) -> None:
    """A drop on the horizon shows sky (bright, blue) in its lower half, like a lens."""
    out = Raindrop().apply(scene128, {"x": 0.5, "y": 0.45, "radius": 0.2}, seed=0)
    cy, cx, r = int(0.45 * 128), 48, int(0.2 * 96)
    lower = out[cy + r // 3 : cy + 2 * r // 3, cx - r // 3 : cx + r // 3]
    upper = out[cy - 2 * r // 3 : cy - r // 3, cx - r // 3 : cx + r // 3]
    assert lower[..., 2].mean() > upper[..., 2].mean() + 30  # blue sky now below


# -- fog -----------------------------------------------------------------------------------


@pytest.mark.parametrize("intensity", [0.15, 0.4, 1.0])
def test_fog_contrast_falls_with_every_layer(scene128: np.ndarray, intensity: float) -> None:
    fog = Fog()
    stds, gradients = [float(grey(scene128).std())], []
    for density in range(1, 11):
        out = grey(fog.apply(scene128, {"density": density, "intensity": intensity}, seed=4))
        stds.append(float(out.std()))
        gradients.append(float(np.abs(np.diff(out, axis=1)).mean()))
    # Strictly falling until the scene is gone (uniform fog colour, contrast 0).
    assert all(a > b or a < 1e-6 for a, b in itertools.pairwise(stds)), stds
    assert all(a >= b for a, b in itertools.pairwise(gradients)), gradients


def test_fog_density_rounds_and_layers_accumulate(scene64: np.ndarray) -> None:
    fog = Fog()
    assert fog.validate({"density": 3.4, "intensity": 0.2})["density"] == 3.0
    assert fog.validate({"density": 3.5, "intensity": 0.2})["density"] == 4.0
    three = fog.apply(scene64, {"density": 3.4, "intensity": 0.3}, seed=8)
    np.testing.assert_array_equal(three, fog.apply(scene64, {"density": 3, "intensity": 0.3}, 8))
    # Density n+1 is density n plus one layer: thicker fog, same pattern underneath.
    colour = np.array([214, 218, 224])
    dist = [
        np.abs(fog.apply(scene64, {"density": n, "intensity": 0.3}, 8).astype(float) - colour)
        for n in (3, 4)
    ]
    assert np.all(dist[1] <= dist[0] + 0.5)


def test_fog_noise_is_drawn_once_per_seed_and_layer_when_reused(scene64: np.ndarray) -> None:
    fog = Fog()
    with reuse_fog_noise() as store:
        thin = fog.apply(scene64, {"density": 4, "intensity": 0.2}, seed=11)
        assert sorted(store) == [(11, i, 64, 64) for i in range(4)]
        kept = store[11, 0, 64, 64]
        thick = fog.apply(scene64, {"density": 6, "intensity": 0.7}, seed=11)
        assert len(store) == 6 and store[11, 0, 64, 64] is kept  # drawn once, not per context
        with pytest.raises(ValueError, match="read-only"):
            kept[0, 0] = 0.0
    # nothing is kept outside the block, and the pixels are the same without it (the thick
    # fog's first four layers came from the store, drawn for the thin one)
    for params, reused in (
        ({"density": 4, "intensity": 0.2}, thin),
        ({"density": 6, "intensity": 0.7}, thick),
    ):
        np.testing.assert_array_equal(reused, fog.apply(scene64, params, 11))


def test_fog_ten_opaque_layers_hide_the_scene(scene64: np.ndarray) -> None:
    out = Fog().apply(scene64, {"density": 10, "intensity": 1.0}, seed=0)
    assert grey(out).std() < 1.0


# -- lighting ------------------------------------------------------------------------------


def test_brightness_gain_half_halves_the_mean(scene128: np.ndarray) -> None:
    out = Brightness().apply(scene128, {"gain": 0.5}, seed=0)
    assert abs(out.mean() - scene128.mean() / 2) <= 2


def test_brightness_gamma_darkens_mid_tones() -> None:
    mid = np.full((8, 8, 3), 128, np.uint8)
    out = Brightness().apply(mid, {"gain": 1.0, "gamma": 2.0}, seed=0)
    assert out[0, 0, 0] == round(255 * (128 / 255) ** 2)
    bright = Brightness().apply(mid, {"gain": 2.0}, seed=0)
    assert bright[0, 0, 0] == 255  # saturates, no wrap-around


def test_hsl_lightness_minus_one_is_black(scene128: np.ndarray) -> None:
    out = HSL().apply(scene128, {"hue": 0, "saturation": 0, "lightness": -1.0}, seed=0)
    assert out.max() <= 1
    white = HSL().apply(scene128, {"hue": 0, "saturation": 0, "lightness": 1.0}, seed=0)
    assert white.min() >= 254


def test_hsl_hue_rotates_and_saturation_greys() -> None:
    red = np.zeros((4, 4, 3), np.uint8)
    red[...] = (200, 30, 30)
    green = HSL().apply(red, {"hue": 120, "saturation": 0, "lightness": 0}, seed=0)
    np.testing.assert_allclose(green[0, 0], (30, 200, 30), atol=1)
    assert np.array_equal(
        HSL().apply(red, {"hue": 180, "saturation": 0, "lightness": 0}, seed=0),
        HSL().apply(red, {"hue": -180, "saturation": 0, "lightness": 0}, seed=0),
    )
    flat = HSL().apply(red, {"hue": 0, "saturation": -1.0, "lightness": 0}, seed=0)
    assert np.ptp(flat[0, 0].astype(int)) <= 1
    vivid = HSL().apply(red, {"hue": 0, "saturation": 1.0, "lightness": 0}, seed=0)
    assert vivid[0, 0, 0] > 200 and vivid[0, 0, 1] < 30


# -- motion blur ---------------------------------------------------------------------------


@pytest.mark.parametrize("angle", [0.0, 30.0, 45.0, 90.0, 135.0, 160.0])
def test_motion_blur_spreads_a_point_along_the_angle(angle: float) -> None:
    image = np.zeros((65, 65, 3), np.uint8)
    image[32, 32] = 255
    out = MotionBlur().apply(image, {"length": 15, "angle": angle}, seed=0)
    weight = out[..., 0].astype(np.float64)
    assert weight.sum() > 0
    rows, cols = np.nonzero(weight)
    w = weight[rows, cols]
    # Coordinates with y up; principal axis of the spread.
    x, y = cols - 32.0, 32.0 - rows
    cov = np.cov(np.vstack([x, y]), aweights=w)
    eigenvalues, eigenvectors = np.linalg.eigh(cov)
    major = eigenvectors[:, np.argmax(eigenvalues)]
    measured = math.degrees(math.atan2(major[1], major[0])) % 180.0
    assert min(abs(measured - angle), 180 - abs(measured - angle)) < 3.0
    # A uniform streak of length L has variance L**2 / 12 along it; it is ~1 px thick.
    assert math.sqrt(12 * eigenvalues.max()) == pytest.approx(15, abs=1.5)
    assert eigenvalues.min() < 1.0


def test_motion_kernel_is_an_exact_box_when_axis_aligned() -> None:
    kernel = motion_kernel(3.0, 0.0)
    row = kernel[kernel.shape[0] // 2]
    np.testing.assert_allclose(row[row > 0], [1 / 3] * 3, rtol=1e-6)
    assert kernel.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(motion_kernel(5.0, 90.0), motion_kernel(5.0, 0.0).T, atol=1e-7)
    assert not kernel.flags.writeable


# -- noise ---------------------------------------------------------------------------------


def test_noise_sigma_is_in_units_of_255() -> None:
    mid = np.full((128, 128, 3), 128, np.uint8)
    out = Noise().apply(mid, {"sigma": 0.05}, seed=1)
    assert (out.astype(float) - 128).std() == pytest.approx(0.05 * 255, rel=0.05)
    assert abs((out.astype(float) - 128).mean()) < 0.5


def test_salt_and_pepper_share() -> None:
    mid = np.full((128, 128, 3), 128, np.uint8)
    out = Noise().apply(mid, {"sigma": 0.0, "salt_pepper": 0.1}, seed=2)
    salt = np.all(out == 255, axis=2).mean()
    pepper = np.all(out == 0, axis=2).mean()
    assert salt == pytest.approx(0.05, abs=0.01)
    assert pepper == pytest.approx(0.05, abs=0.01)


# -- rain and snow -------------------------------------------------------------------------


def test_rain_brightness_applies_without_streaks(scene64: np.ndarray) -> None:
    out = Rain().apply(scene64, {"intensity": 0.0, "brightness": 0.5}, seed=0)
    assert abs(out.mean() - scene64.mean() / 2) <= 1


def test_rain_intensity_sets_the_streak_count() -> None:
    black = np.zeros((64, 64, 3), np.uint8)
    lit = []
    for intensity in (0.1, 0.3, 0.6, 1.0):
        params = {"intensity": intensity, "brightness": 1.0, "blur": 1}
        lit.append(int(np.any(Rain().apply(black, params, seed=3) > 0, axis=2).sum()))
    assert lit == sorted(lit) and lit[0] > 0


@pytest.mark.parametrize("slant", [-30.0, 0.0, 30.0])
def test_rain_slant_is_the_streak_angle(slant: float) -> None:
    black = np.zeros((64, 64, 3), np.uint8)
    params = {  # 2 * 64 * intensity = 1 streak
        "intensity": 1 / 128,
        "slant": slant,
        "drop_length": 30,
        "blur": 1,
        "brightness": 1.0,
    }
    found = False
    for seed in range(20):  # pick a seed whose streak is fully in the frame
        rows, cols = np.nonzero(Rain().apply(black, params, seed=seed)[..., 0])
        if len(rows) < 25:
            continue
        found = True
        slope = np.polyfit(rows, cols, 1)[0]  # x change per row going down
        assert math.degrees(math.atan(slope)) == pytest.approx(slant, abs=4.0)
        break
    assert found


def test_snow_matches_albumentations_random_snow(scene64: np.ndarray) -> None:
    import os

    os.environ.setdefault("NO_ALBUMENTATIONS_UPDATE", "1")
    import albumentations as A

    transform = A.RandomSnow(
        snow_point_range=(0.4, 0.4), brightness_coeff=2.0, method="bleach", p=1.0
    )
    expected = transform(image=np.ascontiguousarray(scene64))["image"]
    out = Snow().apply(scene64, {"snow_point": 0.4, "brightness_coeff": 2.0}, seed=0)
    np.testing.assert_array_equal(out, expected)
    assert grey(out).mean() > grey(scene64).mean()
