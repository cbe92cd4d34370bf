"""Rain streaks and snow, rendered by albumentations 2.0.x with exact parameters.

We call the kernels behind ``albumentations.RandomRain`` and ``RandomSnow``
(``albumentations.augmentations.pixel.functional.add_rain`` / ``add_snow_bleach``) with values
we choose, instead of letting the transforms sample them: the transforms draw from Python's
``random`` module, and ``RandomRain`` only offers four fixed streak counts. So every value is
exact and every random number comes from ``numpy.random.default_rng(seed)``.

Two deliberate differences from ``RandomRain``:

* ``slant`` is a true angle from the vertical (the streak's end is ``drop_length *
  tan(slant)`` pixels to the side); albumentations 2.0.8 adds the slant in degrees as a pixel
  offset whatever the streak length.
* streak start points cover the whole frame including the top rows and the side the wind
  blows from, so a slanted rain is as dense at the edges as in the middle; and the
  brightness factor applies even with zero streaks (albumentations skips it then).
"""

from __future__ import annotations

import math
from types import MappingProxyType

import numpy as np

from anunnaki.phenomena._base import (
    Image,
    ParamSpec,
    Phenomenon,
    require_albumentations_functional,
    to_uint8,
)

__all__ = ["Rain", "Snow"]

#: Colour of the streaks (albumentations' default), RGB.
DROP_COLOUR = (200, 200, 200)


class Rain(Phenomenon):
    """Rain streaks (albumentations ``add_rain``) with an exact streak count from ``intensity``."""

    name = "rain"
    params = (
        ParamSpec(
            "intensity",
            0.0,
            1.0,
            "fraction",
            "Streak count as a fraction of 2 * image height (albumentations 'torrential'; "
            "'heavy' is 0.5, 'default' 1/6, 'drizzle' 1/8).",
            0.0,
        ),
        ParamSpec(
            "slant",
            -45.0,
            45.0,
            "degrees",
            "Angle of the streaks from the vertical; positive leans right going down.",
            0.0,
            default=0.0,
        ),
        ParamSpec(
            "drop_length", 1.0, 100.0, "px", "Length of a streak.", 10.0, default=10.0, integer=True
        ),
        ParamSpec(
            "drop_width", 1.0, 5.0, "px", "Width of a streak.", 1.0, default=1.0, integer=True
        ),
        ParamSpec(
            "blur",
            1.0,
            15.0,
            "px",
            "Box-blur size of the streak layer (1 = sharp streaks).",
            3.0,
            default=3.0,
            integer=True,
        ),
        ParamSpec(
            "brightness",
            0.3,
            1.0,
            "factor",
            "Multiplies the whole frame: rainy scenes are darker.",
            1.0,
            default=0.7,
        ),
    )
    #: Full strength: torrential rain, 30 % darker.
    strength_target = MappingProxyType({"intensity": 1.0, "brightness": 0.7})

    def perturb(self, image: Image, params: dict[str, float], seed: int) -> Image:
        """Draw ``round(2 * height * intensity)`` streaks, blur them, add them, then dim."""
        height, width = image.shape[:2]
        count = math.floor(2 * height * params["intensity"] + 0.5)
        brightness = params["brightness"]
        if count == 0 and brightness == 1.0:
            return image.copy()
        out = image.copy()
        if count > 0:
            functional = require_albumentations_functional()
            length = int(params["drop_length"])
            offset = length * math.tan(math.radians(params["slant"]))
            rng = np.random.default_rng(seed)
            xs = rng.integers(
                math.floor(min(0.0, -offset)), math.ceil(max(width, width - offset)), count
            )
            ys = rng.integers(1 - length, height, count)
            drops = np.stack([xs, ys], axis=1).astype(np.int32)
            out = np.asarray(
                functional.add_rain(
                    out,
                    offset,
                    length,
                    int(params["drop_width"]),
                    DROP_COLOUR,
                    int(params["blur"]),
                    1.0,
                    drops,
                ),
                dtype=np.uint8,
            )
        if brightness != 1.0:
            out = to_uint8(out.astype(np.float32) * np.float32(brightness))
        return out


class Snow(Phenomenon):
    """Snow by bleaching (albumentations ``RandomSnow(method="bleach")`` with exact values).

    Pixels whose HLS lightness is below ``255 * (snow_point / 2 + 1/3)`` have it multiplied
    by ``brightness_coeff``: a higher snow point whitens more of the scene. Deterministic.
    """

    name = "snow"
    stochastic = False
    params = (
        ParamSpec(
            "snow_point",
            0.0,
            1.0,
            "fraction",
            "Lightness threshold below which pixels are bleached; higher means more snow.",
            0.0,
        ),
        ParamSpec(
            "brightness_coeff",
            1.0,
            4.0,
            "factor",
            "Lightness multiplier for bleached pixels; 1 is no snow.",
            1.0,
            default=2.5,
        ),
    )
    #: Full strength: most of the scene whitened.
    strength_target = MappingProxyType({"snow_point": 0.6, "brightness_coeff": 2.5})

    def perturb(self, image: Image, params: dict[str, float], seed: int) -> Image:
        """Bleach dark pixels in HLS lightness."""
        if params["brightness_coeff"] == 1.0:
            return image.copy()
        functional = require_albumentations_functional()
        return np.asarray(
            functional.add_snow_bleach(image, params["snow_point"], params["brightness_coeff"]),
            dtype=np.uint8,
        )
