"""Scene layouts: which objects a scene holds, where, how big and what colour.

A scene is built from a *layout* number: the layout seeds every placement, so layout 0, 1,
2 … are different worlds, which is how train/validation/test splits are made without
leaking a scene into two splits. This module is pure numpy — no pybullet client — so a layout can
be drawn, inspected and tested without a physics client; :class:`~anunnaki.sim.Scene`
places what it draws.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

__all__ = [
    "DISTRACTOR_KINDS",
    "ROUTE_LENGTH",
    "ROVER_CLASSES",
    "UAV_AREA",
    "UAV_CLASSES",
    "Placement",
    "Platform",
    "layout_placements",
]

Platform = Literal["rover", "uav"]

ROVER_CLASSES: tuple[str, ...] = ("pedestrian", "deer")
"""Classes of the rover's scenes; a label is an index into this tuple."""
UAV_CLASSES: tuple[str, ...] = ("pedestrian", "vehicle")
"""Classes of the UAV's scenes; a label is an index into this tuple."""

_PLATFORM_CODE = {"rover": 1, "uav": 2}

#: The small objects a scene scatters to confuse a detector (how each looks is
#: :mod:`anunnaki.sim._models`' business: this module only draws where they stand).
DISTRACTOR_KINDS: tuple[str, ...] = ("ball", "cube", "duck", "mug", "sphere", "teddy")

ROUTE_LENGTH = 44.0
"""Length of the rover's route along +x (m); objects are placed along it."""
UAV_AREA = 70.0
"""Side of the square area (m) the UAV's scenes are placed in, centred on the origin."""


@dataclass(frozen=True)
class Placement:
    """One object in a scene.

    Attributes:
        kind: ``pedestrian``, ``deer``, ``vehicle`` or a distractor (``cube``, ``sphere``,
            ``duck``, ``ball``, ``mug``, ``building``, ``tree``, ``road``).
        x: World x of the object's centre (m).
        y: World y (m).
        yaw: Heading (rad).
        size: The object's characteristic size (m): height of a pedestrian, length of a deer
            or a vehicle, edge or diameter of a distractor.
        color: RGBA tint (distractors, clothes, fur, paint).
        variant: Model variant (vehicles: 0 racecar, 1 husky; others 0).

    """

    kind: str
    x: float
    y: float
    yaw: float = 0.0
    size: float = 1.0
    color: tuple[float, float, float, float] = (0.7, 0.7, 0.7, 1.0)
    variant: int = 0


def _hsv(h: float, s: float, v: float) -> tuple[float, float, float, float]:
    i = int(h * 6.0) % 6
    f = h * 6.0 - math.floor(h * 6.0)
    p, q, t = v * (1 - s), v * (1 - f * s), v * (1 - (1 - f) * s)
    r, g, b = [(v, t, p), (q, v, p), (p, v, t), (p, q, v), (t, p, v), (v, p, q)][i]
    return (r, g, b, 1.0)


def _random_color(rng: np.random.Generator) -> tuple[float, float, float, float]:
    return _hsv(float(rng.random()), float(rng.uniform(0.3, 0.9)), float(rng.uniform(0.4, 1.0)))


def _fur(rng: np.random.Generator) -> tuple[float, float, float, float]:
    v = float(rng.uniform(0.45, 0.75))
    return (v, v * float(rng.uniform(0.62, 0.75)), v * float(rng.uniform(0.35, 0.5)), 1.0)


def _spaced(
    rng: np.random.Generator,
    taken: list[tuple[float, float, float]],
    radius: float,
    xr: tuple[float, float],
    yr: tuple[float, float],
) -> tuple[float, float] | None:
    """Draw a position at least ``radius`` (plus the others' radii) from every taken one."""
    for _ in range(60):
        x, y = float(rng.uniform(*xr)), float(rng.uniform(*yr))
        if all((x - a) ** 2 + (y - b) ** 2 >= (radius + r) ** 2 for a, b, r in taken):
            taken.append((x, y, radius))
            return x, y
    return None


def layout_placements(platform: Platform, layout: int) -> list[Placement]:
    """The objects of scene ``layout`` for ``platform`` (deterministic in ``layout``).

    Rover: 5-8 pedestrians, 3-6 deer and 8-13 distractors along a 44 m route (x in
    [2, 44] m, y in [-4.5, 4.5] m). UAV: 12-22 pedestrians (some in groups), 6-11 vehicles,
    roads, buildings and trees over a 70 m square.
    """
    if platform not in _PLATFORM_CODE:
        raise ValueError(f"platform must be 'rover' or 'uav', got {platform!r}")
    if layout < 0:
        raise ValueError(f"layout must be >= 0, got {layout}")
    rng = np.random.default_rng(np.random.SeedSequence([layout, _PLATFORM_CODE[platform], 17]))
    if platform == "rover":
        return _rover_layout(rng)
    return _uav_layout(rng)


def _rover_layout(rng: np.random.Generator) -> list[Placement]:
    """Pedestrians, deer and distractors along the rover's route."""
    out: list[Placement] = []
    taken: list[tuple[float, float, float]] = []
    xr, yr = (2.0, ROUTE_LENGTH), (-4.5, 4.5)
    counts = {
        "pedestrian": int(rng.integers(5, 9)),
        "deer": int(rng.integers(3, 7)),
        "distractor": int(rng.integers(8, 14)),
    }
    for _ in range(counts["pedestrian"]):
        pos = _spaced(rng, taken, 0.5, xr, yr)
        if pos is not None:
            out.append(_pedestrian(rng, *pos))
    for _ in range(counts["deer"]):
        pos = _spaced(rng, taken, 0.8, xr, yr)
        if pos is not None:
            out.append(_deer(rng, *pos))
    kinds = sorted(DISTRACTOR_KINDS)
    for _ in range(counts["distractor"]):
        kind = kinds[int(rng.integers(len(kinds)))]
        size = {"cube": (0.2, 0.6), "sphere": (0.2, 0.6), "duck": (0.2, 0.5)}.get(kind, (0.2, 0.35))
        pos = _spaced(rng, taken, 0.4, xr, yr)
        if pos is not None:
            out.append(
                Placement(
                    kind,
                    *pos,
                    yaw=float(rng.uniform(-math.pi, math.pi)),
                    size=float(rng.uniform(*size)),
                    color=_random_color(rng),
                )
            )
    return out


def _uav_layout(rng: np.random.Generator) -> list[Placement]:
    """Roads, buildings, trees, vehicles and pedestrians (some in groups) over the area."""
    taken: list[tuple[float, float, float]] = []
    out = _uav_roads(rng)
    out += _uav_scenery(rng, taken)
    out += _uav_vehicles(rng, taken)
    out += _uav_pedestrians(rng, taken)
    return out


def _uav_roads(rng: np.random.Generator) -> list[Placement]:
    """Roads (flat, visual only): a cross of two roads through the area."""
    half = UAV_AREA / 2
    out = []
    for axis in (0, 1):
        offset = float(rng.uniform(-half / 2, half / 2))
        grey = float(rng.uniform(0.3, 0.45))
        x, y = (offset, 0.0) if axis == 0 else (0.0, offset)
        yaw = math.pi / 2 if axis == 0 else 0.0
        out.append(Placement("road", x, y, yaw=yaw, size=UAV_AREA, color=(grey, grey, grey, 1)))
    return out


def _uav_scenery(
    rng: np.random.Generator, taken: list[tuple[float, float, float]]
) -> list[Placement]:
    """Buildings, then trees."""
    half = UAV_AREA / 2
    out = []
    for _ in range(int(rng.integers(4, 8))):
        pos = _spaced(rng, taken, 5.0, (-half, half), (-half, half))
        if pos is not None:
            out.append(
                Placement(
                    "building",
                    *pos,
                    yaw=float(rng.uniform(0, math.pi)),
                    size=float(rng.uniform(4.0, 9.0)),
                    color=_hsv(float(rng.uniform(0.0, 0.15)), 0.25, float(rng.uniform(0.5, 0.9))),
                )
            )
    for _ in range(int(rng.integers(6, 12))):
        pos = _spaced(rng, taken, 1.5, (-half, half), (-half, half))
        if pos is not None:
            out.append(
                Placement(
                    "tree",
                    *pos,
                    size=float(rng.uniform(2.0, 4.0)),
                    color=_hsv(float(rng.uniform(0.22, 0.36)), 0.6, float(rng.uniform(0.3, 0.6))),
                )
            )
    return out


def _uav_vehicles(
    rng: np.random.Generator, taken: list[tuple[float, float, float]]
) -> list[Placement]:
    half = UAV_AREA / 2
    out = []
    for _ in range(int(rng.integers(6, 12))):
        pos = _spaced(rng, taken, 2.2, (-half, half), (-half, half))
        if pos is not None:
            variant = int(rng.integers(2))
            out.append(
                Placement(
                    "vehicle",
                    *pos,
                    yaw=float(rng.uniform(-math.pi, math.pi)),
                    size=float(rng.uniform(3.5, 4.8) if variant == 0 else rng.uniform(2.5, 3.5)),
                    color=_random_color(rng),
                    variant=variant,
                )
            )
    return out


def _uav_pedestrians(
    rng: np.random.Generator, taken: list[tuple[float, float, float]]
) -> list[Placement]:
    """Groups of 2-5 pedestrians, then a few on their own."""
    half = UAV_AREA / 2
    out = []
    groups = int(rng.integers(3, 6))
    for _ in range(groups):
        cx, cy = (float(v) for v in rng.uniform(-half * 0.8, half * 0.8, size=2))
        for _ in range(int(rng.integers(2, 6))):
            pos = _spaced(rng, taken, 0.45, (cx - 4, cx + 4), (cy - 4, cy + 4))
            if pos is not None:
                out.append(_pedestrian(rng, *pos))
    for _ in range(int(rng.integers(3, 7))):
        pos = _spaced(rng, taken, 0.45, (-half, half), (-half, half))
        if pos is not None:
            out.append(_pedestrian(rng, *pos))
    return out


def _pedestrian(rng: np.random.Generator, x: float, y: float) -> Placement:
    return Placement(
        "pedestrian",
        x,
        y,
        yaw=float(rng.uniform(-math.pi, math.pi)),
        size=float(rng.uniform(1.55, 1.9)),
        color=_random_color(rng),
    )


def _deer(rng: np.random.Generator, x: float, y: float) -> Placement:
    return Placement(
        "deer",
        x,
        y,
        yaw=float(rng.uniform(-math.pi, math.pi)),
        size=float(rng.uniform(1.1, 1.6)),
        color=_fur(rng),
    )
