"""Camera-side phenomena: sensor noise and motion blur.

Noise is three lines of numpy with the seeded generator, cheaper and more exact than
albumentations' ``GaussNoise``/``SaltAndPepper`` (which sample their own ranges). Motion blur
uses our own kernel because albumentations' ``MotionBlur`` only has odd kernel sizes of at
least 3 and rounds the line to whole pixels: here the kernel is the area coverage of a
``length`` x 1 px rectangle at ``angle`` (8x8 supersampling), so a horizontal length-3 blur
is exactly ``[1/3, 1/3, 1/3]`` and the effect changes continuously with both parameters.
"""

from __future__ import annotations

import math
from functools import lru_cache
from types import MappingProxyType

import numpy as np
import numpy.typing as npt

from anunnaki.phenomena._base import Image, ParamSpec, Phenomenon, require_cv2, to_uint8

__all__ = ["MotionBlur", "Noise", "motion_kernel"]

_SUPERSAMPLING = 8


class Noise(Phenomenon):
    """Additive Gaussian sensor noise, optionally with salt-and-pepper (dead/hot) pixels."""

    name = "noise"
    params = (
        ParamSpec(
            "sigma",
            0.0,
            0.5,
            "fraction of 255",
            "Standard deviation of the Gaussian noise, independent per pixel and channel.",
            0.0,
        ),
        ParamSpec(
            "salt_pepper",
            0.0,
            0.5,
            "fraction of pixels",
            "Share of pixels set to white or black (half each), after the Gaussian noise.",
            0.0,
            default=0.0,
        ),
    )
    #: Full strength: heavy low-light sensor noise.
    strength_target = MappingProxyType({"sigma": 0.2, "salt_pepper": 0.02})

    def perturb(self, image: Image, params: dict[str, float], seed: int) -> Image:
        """Add ``N(0, (255 * sigma)²)`` per channel, then set salt and pepper pixels."""
        sigma, amount = params["sigma"], params["salt_pepper"]
        if sigma == 0.0 and amount == 0.0:
            return image.copy()
        rng = np.random.default_rng(seed)
        if sigma > 0.0:
            noise = rng.standard_normal(image.shape, dtype=np.float32)
            out = to_uint8(image + noise * np.float32(255.0 * sigma))
        else:
            out = image.copy()
        if amount > 0.0:
            u = rng.random(image.shape[:2])
            out[u < amount / 2] = 255
            out[(u >= amount / 2) & (u < amount)] = 0
        return out


@lru_cache(maxsize=256)
def motion_kernel(length: float, angle: float) -> npt.NDArray[np.float32]:
    """Return the normalised motion-blur kernel for a streak of *length* px at *angle* degrees.

    The kernel is square with an odd side; its weights are the area of each kernel pixel
    covered by a ``length`` x 1 px rectangle centred on the middle pixel, rotated
    counter-clockwise by *angle* from the +x axis with y pointing **up** (so 90° is vertical
    and 45° runs from bottom-left to top-right). The result is cached and read-only.
    """
    half = math.ceil(length / 2 + 1)
    size = 2 * half + 1
    t = (np.arange(size * _SUPERSAMPLING) + 0.5) / _SUPERSAMPLING - 0.5 - half
    dx = t[None, :]
    up = -t[:, None]
    theta = math.radians(angle)
    along = dx * math.cos(theta) + up * math.sin(theta)
    across = -dx * math.sin(theta) + up * math.cos(theta)
    inside = (np.abs(along) <= length / 2) & (np.abs(across) <= 0.5)
    coverage = inside.reshape(size, _SUPERSAMPLING, size, _SUPERSAMPLING).mean(axis=(1, 3))
    kernel: npt.NDArray[np.float32] = (coverage / coverage.sum()).astype(np.float32)
    kernel.flags.writeable = False
    return kernel


class MotionBlur(Phenomenon):
    """Linear motion blur of a given length and direction (camera shake, fast motion)."""

    name = "motion_blur"
    stochastic = False
    params = (
        ParamSpec(
            "length",
            0.0,
            31.0,
            "px",
            "Length of the blur streak; 1 or less is no blur.",
            0.0,
        ),
        ParamSpec(
            "angle",
            0.0,
            180.0,
            "degrees",
            "Direction counter-clockwise from horizontal (90 = vertical).",
            0.0,
            default=0.0,
        ),
    )
    #: Full strength: a 25 px horizontal smear.
    strength_target = MappingProxyType({"length": 25.0})

    def perturb(self, image: Image, params: dict[str, float], seed: int) -> Image:
        """Convolve with :func:`motion_kernel` (reflecting at the border)."""
        length = params["length"]
        if length <= 1.0:
            return image.copy()
        cv2 = require_cv2()
        kernel = motion_kernel(length, params["angle"])
        return np.asarray(
            cv2.filter2D(image, -1, kernel, borderType=cv2.BORDER_REFLECT_101), dtype=np.uint8
        )
