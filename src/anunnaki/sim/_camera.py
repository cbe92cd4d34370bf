"""Where a scene is seen from, and in what light: random cameras, daylight and the sky.

Training and test frames are drawn from many viewpoints: a rover's low camera looking
along its route, a UAV's camera looking down from 15-40 m. This module draws those
cameras (aimed at an object of a class most of the time), slightly varied daylight, and
the sky colour the renderer paints where no object is. It reads only placements, so the
viewpoint rules can change without touching the world that is rendered.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from anunnaki.sim._layout import ROUTE_LENGTH, UAV_AREA, Placement, Platform
from anunnaki.sim._world import Camera, Light

__all__ = ["MIN_DISTANCE", "random_camera", "random_light", "sky_rows"]

MIN_DISTANCE = 1.5
"""Rover: the nearest (m) an object the camera aims at is, by default."""


def random_camera(
    platform: Platform,
    objects: Sequence[Placement],
    rng: np.random.Generator,
    *,
    min_distance: float = MIN_DISTANCE,
) -> Camera:
    """A random but plausible camera for ``platform``.

    Rover: 0.3 m above ground on or near the route, looking ahead (yaw within about
    ±25°, pitch ±4°); seven times in ten it is aimed within ±20° of an object of a class
    1.5-12 m away, the distance log-uniform so that a third of those frames show it
    within 3 m — the range in which the rover's stop rule acts on a detection. UAV:
    15-40 m up, looking down 35-80° below the horizon, aimed near an object of a class
    eight times in ten.

    Args:
        platform: ``"rover"`` or ``"uav"``.
        objects: The scene's objects of a class (the candidates to aim at).
        rng: Draws the pose.
        min_distance: Rover: the nearest an aimed-at object is (metres; 1.5 by default,
            0.4 shows objects that fill the frame, as when the rover stops right before one).

    """
    if platform == "rover":
        return _rover_camera(objects, rng, min_distance)
    return _uav_camera(objects, rng)


def _rover_camera(
    objects: Sequence[Placement], rng: np.random.Generator, min_distance: float
) -> Camera:
    z = 0.3 + float(rng.normal(0.0, 0.02))
    if objects and rng.random() < 0.7:
        tgt = objects[int(rng.integers(len(objects)))]
        dist = math.exp(float(rng.uniform(math.log(min_distance), math.log(12.0))))
        bearing = float(rng.normal(0.0, 0.35))
        yaw = bearing + float(rng.uniform(-0.35, 0.35))
        x = tgt.x - dist * math.cos(bearing)
        y = tgt.y - dist * math.sin(bearing)
    else:
        x = float(rng.uniform(-2.0, ROUTE_LENGTH - 6.0))
        y = float(rng.uniform(-2.0, 2.0))
        yaw = float(rng.normal(0.0, 0.4))
    pitch = float(rng.uniform(-0.07, 0.07))
    eye = (x, y, z)
    target = (
        x + math.cos(yaw) * math.cos(pitch) * 10.0,
        y + math.sin(yaw) * math.cos(pitch) * 10.0,
        z + math.sin(pitch) * 10.0,
    )
    return Camera(eye, target, fov=60.0, near=0.05, far=60.0)


def _uav_camera(objects: Sequence[Placement], rng: np.random.Generator) -> Camera:
    alt = float(rng.uniform(15.0, 40.0))
    down = float(rng.uniform(math.radians(35), math.radians(80)))
    yaw = float(rng.uniform(-math.pi, math.pi))
    if objects and rng.random() < 0.8:
        tgt = objects[int(rng.integers(len(objects)))]
        tx, ty = tgt.x + float(rng.normal(0, 3)), tgt.y + float(rng.normal(0, 3))
    else:
        half = UAV_AREA / 2
        tx, ty = (float(v) for v in rng.uniform(-half * 0.8, half * 0.8, size=2))
    reach = alt / math.tan(down)
    eye = (tx - reach * math.cos(yaw), ty - reach * math.sin(yaw), alt)
    return Camera(eye, (tx, ty, 0.0), fov=32.0, near=0.5, far=250.0)


def random_light(rng: np.random.Generator) -> Light:
    """Slightly varied daylight: direction, colour temperature, ambient/diffuse."""
    az = float(rng.uniform(-math.pi, math.pi))
    el = float(rng.uniform(0.5, 1.4))
    warm = float(rng.uniform(-0.06, 0.06))
    return Light(
        direction=(math.cos(az) * math.cos(el), math.sin(az) * math.cos(el), math.sin(el)),
        color=(1.0, 1.0 - abs(warm) * 0.5, 1.0 - warm),
        ambient=float(rng.uniform(0.5, 0.7)),
        diffuse=float(rng.uniform(0.3, 0.5)),
        specular=float(rng.uniform(0.0, 0.1)),
    )


def sky_rows(height: int, light: Light | None) -> np.ndarray:
    """Sky colour per image row ``[height, 3] uint8``: a blue gradient lit by ``light``."""
    light = light or Light()
    rows = np.linspace(0.0, 1.0, height)[:, None]
    top, horizon = np.array([0.45, 0.62, 0.88]), np.array([0.8, 0.87, 0.95])
    scale = min(1.0, light.ambient + 0.5 * light.diffuse) * np.asarray(light.color)
    return (np.clip((top * (1 - rows) + horizon * rows) * scale, 0, 1) * 255).astype(np.uint8)
