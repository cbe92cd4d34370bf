"""Fixtures for the phenomena tests: small synthetic scenes drawn with numpy."""

from __future__ import annotations

import numpy as np
import pytest

from anunnaki.phenomena import synthetic_scene


def _frozen(image: np.ndarray) -> np.ndarray:
    """Session fixtures are shared: make them read-only so no test can alter them."""
    image.flags.writeable = False
    return image


@pytest.fixture(scope="session")
def scene64() -> np.ndarray:
    """A 64x64 road scene: sky and ground gradients, a road, coloured boxes."""
    return _frozen(synthetic_scene(64, 64))


@pytest.fixture(scope="session")
def scene128() -> np.ndarray:
    """A 128x96 (H x W) scene: not square, so swapped axes show up."""
    return _frozen(synthetic_scene(128, 96, seed=1))


@pytest.fixture(scope="session")
def texture64() -> np.ndarray:
    """64x64 uniform noise: every pixel differs from its neighbours."""
    return _frozen(np.random.default_rng(123).integers(0, 256, (64, 64, 3), dtype=np.uint8))
