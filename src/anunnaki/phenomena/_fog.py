"""Layered fog (paper §4.2.1: fog_density = number of layers, fog_intensity = layer opacity).

Each layer is a smooth noise field (two octaves of cubic-interpolated random grids, drawn
from the seed) that modulates the layer's opacity between ``0.6 * intensity`` and
``intensity``; the layer blends the image toward a light grey fog colour:
``out = out + alpha * (fog_colour - out)``, computed in one pass as
``fog_colour + (image - fog_colour) * prod(1 - alpha_i)``. Every layer moves every pixel
toward the fog colour, so more layers at a fixed intensity always mean less contrast.

Layer *i* has its own seed, ``SeedSequence(seed).spawn(10)[i]``, so the fog for density *n*
is the fog for density *n - 1* plus one layer: a searcher or a scenario that raises the
density thickens the same fog instead of drawing a new one. The noise grid has a fixed
number of cells, so the fog looks the same at any image size.

The noise fields are small matrix products (``(H, k) @ (k, k) @ (k, W)``, k ≤ 13), computed
on one BLAS thread: numpy's OpenBLAS splits each over its two threads on two cores, and
with the other core busy (another process's work) the calling thread waited for its
helper at every product: 21–32 ms of CPU for a ten-layer fog on a 320 × 240 frame, against
2.3–2.8 ms on one thread, with the same pixels (OpenBLAS splits the output among its
threads, not the sums, so every element is the same sum either way).

Albumentations' ``RandomFog`` draws circles around the image centre with one coefficient and
has no notion of layers, so this is our own code.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from functools import lru_cache
from types import MappingProxyType

import numpy as np
import numpy.typing as npt

from anunnaki._blas import blas_limit
from anunnaki.phenomena._base import Image, ParamSpec, Phenomenon, require_cv2

__all__ = ["Fog", "reuse_fog_noise"]

MAX_LAYERS = 10
#: RGB colour the fog tends to (light, slightly blue grey).
FOG_COLOUR = (214.0, 218.0, 224.0)


@lru_cache(maxsize=64)
def _cubic_upsampler(size: int, cells: int) -> npt.NDArray[np.float32]:
    """Return the ``(size, cells + 1)`` matrix of OpenCV's bicubic upsampling weights.

    ``R_y @ grid @ R_x.T`` equals ``cv2.resize(grid, (W, H), interpolation=INTER_CUBIC)``
    (to float32 precision) at a fiftieth of the cost for these tiny grids.
    """
    cv2 = require_cv2()
    eye = np.eye(cells + 1, dtype=np.float32)
    matrix = np.asarray(
        cv2.resize(eye, (cells + 1, size), interpolation=cv2.INTER_CUBIC), dtype=np.float32
    )
    matrix.flags.writeable = False
    return matrix


def _smooth_noise(
    rng: np.random.Generator, height: int, width: int, cells: int
) -> npt.NDArray[np.float32]:
    """Return a ``(height, width)`` float32 field in [0, 1], smooth at ``cells`` per side."""
    field = np.zeros((height, width), dtype=np.float32)
    for octave_cells, weight in ((cells, 0.65), (2 * cells, 0.35)):
        grid = rng.random((octave_cells + 1, octave_cells + 1), dtype=np.float32)
        rows = _cubic_upsampler(height, octave_cells)
        cols = _cubic_upsampler(width, octave_cells)
        field += np.float32(weight) * (rows @ grid @ cols.T)
    return np.clip(field, 0.0, 1.0)


NoiseStore = dict[tuple[int, int, int, int], npt.NDArray[np.float32]]
_REUSE: ContextVar[NoiseStore | None] = ContextVar("anunnaki_fog_noise", default=None)


@contextmanager
def reuse_fog_noise(store: NoiseStore | None = None) -> Iterator[NoiseStore]:
    """Within the block, a fog draws each noise layer once per (seed, layer, size) and keeps it.

    A fog's layers depend only on the seed and the image size, not on ``density`` or
    ``intensity``; drawing them is half of a fog's cost. Enlil measures every context on the
    same images with the same seeds, so its workers keep the layers for the whole search
    (pass the same *store* to each block; at most ``images x 10`` fields of ``H x W``
    float32). Outside such a block nothing is kept: a live camera gets new seeds each frame.
    The pixels are the same either way.
    """
    kept: NoiseStore = {} if store is None else store
    token = _REUSE.set(kept)
    try:
        yield kept
    finally:
        _REUSE.reset(token)


def _layer_noise(seed: int, index: int, height: int, width: int) -> npt.NDArray[np.float32]:
    """Layer *index*'s noise field for *seed* (kept inside :func:`reuse_fog_noise`)."""
    store, key = _REUSE.get(), (seed, index, height, width)
    if store is not None and key in store:
        return store[key]
    child = np.random.SeedSequence(seed).spawn(MAX_LAYERS)[index]
    field = _smooth_noise(np.random.default_rng(child), height, width, cells=3 + index % 4)
    if store is not None:
        field.flags.writeable = False
        store[key] = field
    return field


class Fog(Phenomenon):
    """Layers of semi-transparent fog of a given number and opacity."""

    name = "fog"
    params = (
        ParamSpec(
            "density",
            1.0,
            float(MAX_LAYERS),
            "layers",
            "Number of fog layers (the paper's fog_density, its depth); rounded.",
            1.0,
            integer=True,
        ),
        ParamSpec(
            "intensity",
            0.0,
            1.0,
            "opacity",
            "Peak opacity of each layer (the paper's fog_intensity); 0 is no fog.",
            0.0,
        ),
    )
    #: Full strength: ten layers at 30 % opacity, the scene all but gone.
    strength_target = MappingProxyType({"density": float(MAX_LAYERS), "intensity": 0.3})

    def perturb(self, image: Image, params: dict[str, float], seed: int) -> Image:
        """Blend ``density`` smooth noise layers of opacity up to ``intensity`` over the image."""
        layers, intensity = int(params["density"]), params["intensity"]
        if intensity == 0.0:
            return image.copy()
        require_cv2()  # the noise upsampling weights come from OpenCV's bicubic resize
        height, width = image.shape[:2]
        # Blending toward one colour layer by layer, out += alpha_i * (colour - out), leaves
        # out = colour + (image - colour) * prod(1 - alpha_i): one pass over the colour image.
        clear = np.ones((height, width), dtype=np.float32)
        with blas_limit(1, extra="phenomena"):  # small products: one BLAS thread (module docstring)
            for index in range(min(layers, MAX_LAYERS)):
                noise = _layer_noise(int(seed), index, height, width)
                clear *= np.float32(1.0 - 0.6 * intensity) - np.float32(0.4 * intensity) * noise
        colour = np.array(FOG_COLOUR, dtype=np.float32)
        out = image.astype(np.float32)
        out -= colour
        out *= clear[..., None]
        out += colour  # a convex combination of image and colour: no clipping needed
        return np.rint(out, out=out).astype(np.uint8)
