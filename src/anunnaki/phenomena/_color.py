"""Lighting phenomena: HSL shifts (paper §4.1.2) and brightness/gamma (dim light).

The paper's rover study searched over hue, saturation and lightness contexts. We use
OpenCV's HLS conversion in float32 (hue in degrees, lightness and saturation in [0, 1]) so a
one-degree hue shift is exact rather than quantised to OpenCV's 2-degree ``uint8`` hue.
Saturation and lightness are *relative* changes in [-1, 1]: negative values scale toward 0
(``v * (1 + c)``), positive ones toward 1 (``v + (1 - v) * c``), so -1 means grey or black and
+1 fully saturated or white, and 0 is exactly the identity.
"""

from __future__ import annotations

from types import MappingProxyType

import numpy as np
import numpy.typing as npt

from anunnaki.phenomena._base import Image, ParamSpec, Phenomenon, require_cv2, to_uint8

__all__ = ["HSL", "Brightness"]


def _relative(channel: npt.NDArray[np.float32], change: float) -> npt.NDArray[np.float32]:
    if change < 0:
        return channel * np.float32(1.0 + change)
    return channel + (np.float32(1.0) - channel) * np.float32(change)


class HSL(Phenomenon):
    """Hue rotation and relative saturation/lightness change (the paper's HSL contexts)."""

    name = "hsl"
    stochastic = False
    params = (
        ParamSpec("hue", -180.0, 180.0, "degrees", "Rotation of the hue on the colour wheel.", 0.0),
        ParamSpec(
            "saturation",
            -1.0,
            1.0,
            "relative",
            "Saturation change: -1 grey, 0 unchanged, +1 fully saturated.",
            0.0,
        ),
        ParamSpec(
            "lightness",
            -1.0,
            1.0,
            "relative",
            "Lightness change: -1 black, 0 unchanged, +1 white.",
            0.0,
        ),
    )
    #: Full strength is poor lighting: darker and washed out.
    strength_target = MappingProxyType({"saturation": -0.6, "lightness": -0.8})

    def perturb(self, image: Image, params: dict[str, float], seed: int) -> Image:
        """Shift hue, scale saturation and lightness in float32 HLS space."""
        hue, saturation, lightness = params["hue"], params["saturation"], params["lightness"]
        if hue == 0.0 and saturation == 0.0 and lightness == 0.0:
            return image.copy()
        cv2 = require_cv2()
        hls = cv2.cvtColor(image.astype(np.float32) * np.float32(1 / 255), cv2.COLOR_RGB2HLS)
        if hue != 0.0:
            hls[..., 0] = np.mod(hls[..., 0] + np.float32(hue), np.float32(360.0))
        if lightness != 0.0:
            hls[..., 1] = _relative(hls[..., 1], lightness)
        if saturation != 0.0:
            hls[..., 2] = _relative(hls[..., 2], saturation)
        rgb = cv2.cvtColor(hls, cv2.COLOR_HLS2RGB)
        return to_uint8(rgb * np.float32(255.0))


class Brightness(Phenomenon):
    """Dim light or over-exposure: ``out = 255 * gain * (in / 255) ** gamma``, saturated."""

    name = "brightness"
    stochastic = False
    params = (
        ParamSpec(
            "gain",
            0.05,
            2.0,
            "factor",
            "Multiplies every channel; below 1 dims the scene, above 1 over-exposes it.",
            1.0,
        ),
        ParamSpec(
            "gamma",
            0.2,
            5.0,
            "exponent",
            "Gamma applied before the gain; above 1 darkens mid-tones, below 1 lifts them.",
            1.0,
            default=1.0,
        ),
    )
    #: Full strength is dusk: a tenth of the light.
    strength_target = MappingProxyType({"gain": 0.1})

    def perturb(self, image: Image, params: dict[str, float], seed: int) -> Image:
        """Apply a 256-entry look-up table built from gain and gamma."""
        gain, gamma = params["gain"], params["gamma"]
        if gain == 1.0 and gamma == 1.0:
            return image.copy()
        levels = np.arange(256, dtype=np.float64) / 255.0
        table = to_uint8(255.0 * gain * levels**gamma)
        return table[image]
