"""A small synthetic road scene for tests, figures, benchmarks and quick looks."""

from __future__ import annotations

import numpy as np

from anunnaki.phenomena._base import Image, PhenomenonError, to_uint8

__all__ = ["synthetic_scene"]

_BOX_COLOURS = ((200, 40, 40), (230, 200, 40), (40, 60, 180), (30, 30, 30))


def synthetic_scene(height: int = 128, width: int = 128, *, seed: int = 0) -> Image:
    """Draw a sky gradient, a ground plane with a road, and coloured boxes (the "objects").

    Args:
        height: Image height in pixels (at least 8).
        width: Image width in pixels (at least 8).
        seed: Moves the boxes; the same seed gives the same picture.

    Returns:
        ``(height, width, 3)`` ``uint8`` RGB array.

    """
    if height < 8 or width < 8:
        raise PhenomenonError(f"scene must be at least 8x8 px, got {height}x{width}")
    rng = np.random.default_rng(seed)
    rows = np.linspace(0.0, 1.0, height)[:, None, None]
    cols = np.linspace(0.0, 1.0, width)[None, :, None]
    sky = np.array([70, 130, 200]) + rows * np.array([120, 85, 35]) * 2.0
    ground = np.array([96, 120, 64]) - rows * np.array([40, 40, 24]) + cols * np.array([20, 10, 0])
    horizon = int(0.45 * height)
    image = np.where(np.arange(height)[:, None, None] < horizon, sky, ground)
    image = np.broadcast_to(image, (height, width, 3)).astype(np.float64).copy()
    # A road: a grey trapezoid from the horizon to the bottom edge, with a dashed centre line.
    for row in range(horizon, height):
        depth = (row - horizon) / max(1, height - 1 - horizon)
        half = 0.04 * width + depth * 0.30 * width
        lo, hi = int(width / 2 - half), int(np.ceil(width / 2 + half))
        image[row, max(0, lo) : min(width, hi)] = (112, 112, 118)
        if (row // max(1, height // 16)) % 2 == 0:
            mark = max(1, int(0.012 * width * (1 + depth)))
            image[row, width // 2 - mark // 2 : width // 2 - mark // 2 + mark] = (235, 235, 235)
    # Boxes standing on the ground, larger when nearer.
    for colour in _BOX_COLOURS:
        bottom = int(horizon + rng.uniform(0.15, 0.95) * (height - horizon))
        size = max(3, int((0.06 + 0.16 * (bottom - horizon) / (height - horizon)) * width))
        left = int(rng.uniform(0.0, 1.0) * (width - size))
        top = max(0, bottom - size)
        image[top:bottom, left : left + size] = colour
        image[top : top + max(1, size // 6), left : left + size] *= 1.15  # lit top face
    return to_uint8(image)
