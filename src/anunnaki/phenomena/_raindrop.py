"""A raindrop on the lens (paper §4.1.2, Fig. 12(b): raindrop_x, raindrop_y, raindrop_radius).

Albumentations has no lens raindrop, so this is ours. A water drop sitting on the lens acts as
a small fish-eye lens: it shows an inverted, wide-angle view of the scene around it, out of
focus, with a darker rim. We render exactly that:

* inside the drop, each pixel samples the scene mirrored through the drop centre at
  ``MAGNIFICATION`` times its distance (more toward the rim, like a real lens), with a
  Gaussian blur that grows with the radius;
* a smooth-step edge of width ``feather * radius`` blends the drop into the scene;
* every pixel whose centre lies farther than ``radius + feather * radius`` from the drop
  centre is bit-identical to the input (the contract suite checks this exactly).

One drop has a fixed-length parameter vector (x, y, radius, feather); several drops are a
composition: ``compose("raindrop", "raindrop", "raindrop")``.

The drop hides the scene behind it: :meth:`Raindrop.occlusion_mask` is the blend weight
(1 on the disc, the smooth-step on the edge), from the same geometry as the image.
"""

from __future__ import annotations

import math
from types import MappingProxyType

import numpy as np
import numpy.typing as npt

from anunnaki.phenomena._base import (
    Image,
    Mask,
    ParamSpec,
    Phenomenon,
    require_cv2,
    to_uint8,
)

__all__ = ["Raindrop"]

#: How much wider than the drop the refracted view is (a drop shows a minified scene).
MAGNIFICATION = 2.2
#: Drops (and soft edges) thinner than this many pixels are treated as absent (hard).
_MIN_RADIUS_PX = 1e-6


class Raindrop(Phenomenon):
    """One raindrop on the lens, at normalised image coordinates."""

    name = "raindrop"
    stochastic = False
    params = (
        ParamSpec(
            "x", 0.0, 1.0, "image width", "Horizontal centre (0 left edge, 1 right edge).", 0.5
        ),
        ParamSpec(
            "y", 0.0, 1.0, "image height", "Vertical centre (0 top edge, 1 bottom edge).", 0.5
        ),
        ParamSpec(
            "radius",
            0.0,
            0.5,
            "image width",
            "Radius of the fully covered disc, as a fraction of the image width.",
            0.0,
        ),
        ParamSpec(
            "feather",
            0.0,
            1.0,
            "radius",
            "Width of the soft edge outside the disc, as a fraction of the radius.",
            0.25,
            default=0.25,
        ),
    )
    #: Full strength: a drop covering the middle 60 % of the width.
    strength_target = MappingProxyType({"radius": 0.3})

    def occlusion_mask(
        self, height: int, width: int, params: dict[str, float], seed: int
    ) -> Mask | None:
        """The blend weight of the drop: 1 on the disc, the smooth-step on the edge, 0 outside.

        The drop replaces the scene behind it by a refracted view of its surroundings, so
        what is under the disc is hidden (and half hidden where the edge blends 50/50).
        """
        del seed  # deterministic, as perturb
        mask = np.zeros((height, width), np.float32)
        geometry = _geometry(height, width, params)
        if geometry is not None:
            (r0, r1, c0, c1), alpha = geometry[0], geometry[1]
            mask[r0:r1, c0:c1] = alpha
        return mask

    def perturb(self, image: Image, params: dict[str, float], seed: int) -> Image:
        """Blend a refracted, blurred view of the surroundings into the drop's disc."""
        height, width = image.shape[:2]
        geometry = _geometry(height, width, params)
        if geometry is None:
            return image.copy()
        (r0, r1, c0, c1), alpha, distance, dx, dy = geometry
        inside = alpha > 0.0
        radius = params["radius"] * width
        cx, cy = params["x"] * width, params["y"] * height
        cv2 = require_cv2()
        rho = np.minimum(distance / radius, 1.0)
        scale = -MAGNIFICATION * (1.0 + 0.35 * rho**2)  # negative: the view is inverted
        map_x = (cx + dx * scale - 0.5).astype(np.float32)
        map_y = (cy + dy * scale - 0.5).astype(np.float32)
        drop = cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101)
        drop = cv2.GaussianBlur(drop, (0, 0), sigmaX=0.6 + 0.05 * radius)
        shade = 1.0 + 0.10 * (1.0 - rho**2) - 0.30 * rho**4  # bright centre, dark rim
        patch = image[r0:r1, c0:c1].astype(np.float64)
        a = alpha[..., None]
        blended = to_uint8(a * drop.astype(np.float64) * shade[..., None] + (1.0 - a) * patch)
        out = image.copy()
        region = out[r0:r1, c0:c1]
        region[inside] = blended[inside]
        return out


_Float = npt.NDArray[np.float64]


def _geometry(
    height: int, width: int, params: dict[str, float]
) -> tuple[tuple[int, int, int, int], _Float, _Float, _Float, _Float] | None:
    """Where the drop is: ``((r0, r1, c0, c1), alpha, distance, dx, dy)`` over its box.

    ``alpha`` is the blend weight of the drop in each pixel of rows ``r0:r1``, columns
    ``c0:c1`` (the drop's bounding box clipped to the image); ``None``: no drop at all. The
    one place both the image (:meth:`Raindrop.perturb`) and the mask come from.
    """
    radius = params["radius"] * width
    feather = params["feather"] * radius
    outer = radius + feather
    if radius < _MIN_RADIUS_PX:
        return None
    cx, cy = params["x"] * width, params["y"] * height
    # Pixel (row, col) has its centre at (col + 0.5, row + 0.5).
    c0, c1 = max(0, math.floor(cx - outer - 0.5)), min(width, math.ceil(cx + outer + 0.5))
    r0, r1 = max(0, math.floor(cy - outer - 0.5)), min(height, math.ceil(cy + outer + 0.5))
    dx = (np.arange(c0, c1, dtype=np.float64) + 0.5 - cx)[None, :]
    dy = (np.arange(r0, r1, dtype=np.float64) + 0.5 - cy)[:, None]
    distance = np.hypot(dx, dy)
    if feather >= _MIN_RADIUS_PX:
        t = np.clip((distance - radius) / feather, 0.0, 1.0)
        alpha = 1.0 - t * t * (3.0 - 2.0 * t)
    else:
        alpha = (distance <= radius).astype(np.float64)
    if not (alpha > 0.0).any():
        return None
    return (r0, r1, c0, c1), alpha, distance, dx, dy
