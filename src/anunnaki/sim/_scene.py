"""Scenes: pybullet worlds of pedestrians, deer, vehicles and distractors, and their frames.

A scene is built from a *layout* number: the layout seeds every placement (which objects,
where, how big, what colour), so layout 0, 1, 2 … are different worlds, which is how
train/validation/test splits are made without leaking a scene into two splits. Within a
scene, frames vary by camera pose, lighting, object poses (yaw, limbs) and distractor colours,
drawn from a separate seed. Everything is deterministic for ``(platform, layout, seed)``.

Ground truth comes from pybullet's segmentation mask, never from a model: see
:func:`boxes_from_mask` for the rule that keeps a box.
"""

from __future__ import annotations

import functools
import math
import re
import shutil
import tempfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, NamedTuple

import numpy as np

from anunnaki.sim._world import Camera, Light, World, pybullet

__all__ = [
    "MIN_BOX_SIZE",
    "MIN_IN_FRAME",
    "MIN_LABEL_HEIGHT",
    "MIN_VISIBLE",
    "ROVER_CLASSES",
    "UAV_CLASSES",
    "Annotation",
    "Camera",
    "Frame",
    "Light",
    "Placement",
    "Platform",
    "Scene",
    "annotate_mask",
    "boxes_from_mask",
    "dataset_frames",
    "layout_placements",
]

Platform = Literal["rover", "uav"]

ROVER_CLASSES: tuple[str, ...] = ("pedestrian", "deer")
"""Classes of the rover's scenes; a label is an index into this tuple."""
UAV_CLASSES: tuple[str, ...] = ("pedestrian", "vehicle")
"""Classes of the UAV's scenes; a label is an index into this tuple."""

MIN_BOX_SIZE = 4.0
"""A kept box is at least this many pixels wide *and* high."""
MIN_VISIBLE = 0.25
"""A kept box covers at least this fraction of the object's projected, in-frame extent."""
MIN_IN_FRAME = 0.5
"""At least this fraction of the object's projected extent lies inside the image."""
MIN_LABEL_HEIGHT: dict[str, float] = {"rover": 0.134, "uav": 0.0}
"""Per platform: a labelled box is at least this fraction of the image height tall.

Objects seen but smaller become *ignore boxes* (see :func:`annotate_mask`). The rover's
value follows from its stop rule (``anunnaki.sim.StopRule``): it acts on pedestrians and
deer within ``stop_distance`` = 3 m, and its detector is asked to see them from twice that
far, 6 m, so it has locked on before they are in range (at the 0.8 m/s cruise speed, 3.75 s
or about 37 frames at 10 Hz). The smallest such object is the smallest deer, 0.93 m tall
(a pedestrian is 1.59-1.95 m). With the camera's 60° vertical field of view the focal
length is ``f = (H/2) / tan 30° = 0.866 H`` pixels, so a 0.93 m object at 6 m is
``0.866 H · 0.93 / 6 = 0.134 H`` tall: 17.2 px at 128 × 128 (a pedestrian at 6 m: 29 px;
the smallest deer at 3 m: 34 px). The UAV has no such rule: 0 keeps every box of at least
:data:`MIN_BOX_SIZE`.
"""

_PLATFORM_CODE = {"rover": 1, "uav": 2}

ROBOT_GROUP = 1
"""Collision group of robots (the rover): they collide with everything."""
SCENE_GROUP = 2
"""Collision group of scene objects and the ground: they collide with robots only."""

ROUTE_LENGTH = 44.0
"""Length of the rover's route along +x (m); objects are placed along it."""
UAV_AREA = 70.0
"""Side of the square area (m) the UAV's scenes are placed in, centred on the origin."""


@dataclass(frozen=True)
class Frame:
    """One rendered camera frame with its ground truth.

    Attributes:
        image: ``[H, W, 3]`` ``uint8`` RGB.
        boxes: ``[N, 4]`` ``float32`` ``x1, y1, x2, y2`` in pixels (``x2``/``y2`` exclusive:
            a box one pixel wide has ``x2 = x1 + 1``), from the segmentation mask.
        labels: ``[N]`` ``int64`` indices into the scene's classes.
        t: Simulation time (s).
        seq: Frame sequence number.
        ignore: ``[K, 4]`` ``float32`` *ignore boxes*: objects of a class that are in the
            image but not labelled (too small, mostly occluded or mostly cut by the frame),
            tight around their visible pixels. A detection there is neither right nor wrong
            (``anunnaki.lec.f1_at_iou``) and training puts no background loss there — the
            KITTI "DontCare" / COCO ``iscrowd`` practice.
        ignore_labels: ``[K]`` ``int64`` class of each ignore box.

    """

    image: np.ndarray
    boxes: np.ndarray
    labels: np.ndarray
    t: float
    seq: int
    ignore: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), np.float32))
    ignore_labels: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))


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


# --- models ------------------------------------------------------------------------------

# Model files (pybullet_data), their scale per metre of "size", and the z-rotation that
# stands them up / faces them along +x.
_HUMANOID = "humanoid/humanoid.urdf"  # DeepMimic humanoid: y-up, 1.58 m tall at scale 0.25
_HUMANOID_SCALE_PER_M = 0.25 / 1.58
_DEER = "laikago/laikago_toes_zup_lores.urdf"  # low-poly quadruped, 0.71 m long at scale 1
_DEER_SCALE_PER_M = 1.0 / 0.71
# Model scale per metre of size, from each model's bounding box at scale 1.
_VEHICLES = (("racecar/racecar.urdf", 1.0 / 0.458), ("husky/husky.urdf", 1.0 / 1.009))
_DISTRACTORS = {
    "cube": ("cube.urdf", 1.0),
    "sphere": ("sphere2.urdf", 1.0),
    "duck": ("duck_vhacd.urdf", 1.0 / 0.091),
    "ball": ("soccerball.urdf", 1.0),
    "mug": ("objects/mug.urdf", 1.0 / 0.128),
    "teddy": ("teddy_vhacd.urdf", 1.0 / 0.101),
}


def _strip_material(src: Path, directory: Path) -> str:
    """Copy an OBJ file without its material (and texture) lines; return the copy's path."""
    target = directory / f"{src.parent.name}_{src.name}"
    if not target.exists():
        lines = src.read_text().splitlines(keepends=True)
        target.write_text("".join(ln for ln in lines if not ln.startswith(("mtllib", "usemtl"))))
    return str(target)


_PRIMITIVE = re.compile(r"<(box|cylinder|sphere)\b[^>]*/>")
# Meshes of thousands of triangles that the lite copies replace (wheels) or drop (hinges).
_HEAVY_MESHES = frozenset(
    {
        "wheel.stl",
        "left_front_wheel.obj",
        "right_front_wheel.obj",
        "left_rear_wheel.obj",
        "right_rear_wheel.obj",
        "left_steering_hinge.STL",
        "right_steering_hinge.STL",
        "user_rail.stl",
    }
)
# Heavy meshes without a primitive collision shape, shown as a primitive: (origin, geometry).
_STAND_INS = {
    "top_plate.stl": ('<origin rpy="0 0 0" xyz="0 0 0.21"/>', '<box size="0.812 0.414 0.03"/>'),
}


def _lite_urdf(model: str, directory: Path) -> str:
    """Write a quick-loading, quick-rendering copy of a pybullet_data URDF; return its path.

    pybullet's tiny renderer pays for every triangle of every body in view or not (the
    husky's four 7,000-triangle wheels cost 20 ms a frame even behind the camera), and the
    loader decodes a texture once per link (0.2 s for the laikago). The copy

    * shows a heavy mesh's primitive collision shape instead (wheels become the cylinders
      they already collide as) and drops it when there is none (steering hinges);
    * loads OBJ meshes without their material and texture (objects are tinted anyway);
    * for the quadruped, collides with the low-poly meshes it shows instead of STL hulls.

    Measured here: husky 6x faster to render, laikago 10x faster to load, same silhouettes.
    """
    import pybullet_data

    src = Path(pybullet_data.getDataPath()) / model
    out = directory / (model.replace("/", "_"))
    if out.exists():
        return str(out)

    def link(match: re.Match[str]) -> str:
        block = match.group(0)
        visual = re.search(r"<visual>.*?</visual>", block, re.S)
        collision = re.search(r"<collision>.*?</collision>", block, re.S)
        if visual is None:
            return block
        mesh = re.search(r'<mesh filename="([^"]*)"([^>]*)/>', visual.group(0))
        if mesh is None:
            return block
        path = src.parent / mesh.group(1)
        vis = visual.group(0)
        if path.name in _STAND_INS:
            origin_xml, geometry_xml = _STAND_INS[path.name]
            new_vis = re.sub(r"<origin[^>]*/>", origin_xml, vis, count=1)
            return block.replace(vis, re.sub(r"<mesh[^>]*/>", geometry_xml, new_vis))
        if path.name in _HEAVY_MESHES:
            prim = _PRIMITIVE.search(collision.group(0)) if collision else None
            if prim is None or collision is None:
                return block.replace(vis, "")
            origin = re.search(r"<origin[^>]*/>", collision.group(0))
            new_vis = re.sub(r"<origin[^>]*/>", origin.group(0) if origin else "", vis, count=1)
            new_vis = re.sub(r"<mesh[^>]*/>", prim.group(0), new_vis)
            return block.replace(vis, new_vis)
        shown = _strip_material(path, directory) if path.suffix == ".obj" else str(path)
        block = block.replace(
            vis, vis.replace(f'filename="{mesh.group(1)}"', f'filename="{shown}"')
        )
        if collision is not None and model.startswith("laikago/"):
            coll = collision.group(0)
            block = block.replace(coll, re.sub(r'filename="[^"]*"', f'filename="{shown}"', coll))
        return block

    text = re.sub(r"<link .*?</link>", link, src.read_text(), flags=re.S)

    def absolute(match: re.Match[str]) -> str:
        name = match.group(1)
        return match.group(0) if name.startswith("/") else f'filename="{src.parent / name}"'

    out.write_text(re.sub(r'filename="([^"]*)"', absolute, text))
    return str(out)


_HUMANOID_LINKS = {
    "trousers": (0, 9, 10, 12, 13),
    "shirt": (1, 3, 6),
    "skin": (2, 4, 5, 7, 8),
    "shoes": (11, 14),
}


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


def layout_placements(platform: Platform, layout: int) -> list[Placement]:  # noqa: C901, PLR0912
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
    out: list[Placement] = []
    taken: list[tuple[float, float, float]] = []
    if platform == "rover":
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
        kinds = sorted(_DISTRACTORS)
        for _ in range(counts["distractor"]):
            kind = kinds[int(rng.integers(len(kinds)))]
            size = {"cube": (0.2, 0.6), "sphere": (0.2, 0.6), "duck": (0.2, 0.5)}.get(
                kind, (0.2, 0.35)
            )
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
    half = UAV_AREA / 2
    # Roads first (flat, visual only): a cross of two roads through the area.
    for axis in (0, 1):
        offset = float(rng.uniform(-half / 2, half / 2))
        grey = float(rng.uniform(0.3, 0.45))
        x, y = (offset, 0.0) if axis == 0 else (0.0, offset)
        yaw = math.pi / 2 if axis == 0 else 0.0
        out.append(Placement("road", x, y, yaw=yaw, size=UAV_AREA, color=(grey, grey, grey, 1)))
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


# --- ground texture ----------------------------------------------------------------------


def _ground_texture(rng: np.random.Generator, platform: Platform, size: int = 128) -> np.ndarray:
    """A tileable grass/soil texture ``[size, size, 3] uint8`` (periodic Fourier noise)."""
    out = np.empty((size, size, 3), dtype=np.float64)
    fy = np.fft.fftfreq(size)[:, None]
    fx = np.fft.fftfreq(size)[None, :]
    radius = np.sqrt(fx**2 + fy**2)
    radius[0, 0] = 1.0
    spectrum = 1.0 / radius**1.4
    spectrum[0, 0] = 0.0
    noise = np.real(np.fft.ifft2(spectrum * np.exp(2j * np.pi * rng.random((size, size)))))
    noise = (noise - noise.mean()) / (noise.std() + 1e-9)
    fine = rng.normal(0.0, 1.0, (size, size))
    if platform == "rover":
        base = np.array([0.36, 0.45, 0.22]) * rng.uniform(0.85, 1.15)
        soil = np.array([0.45, 0.38, 0.28])
    else:
        base = np.array([0.33, 0.44, 0.24]) * rng.uniform(0.85, 1.15)
        soil = np.array([0.5, 0.46, 0.38])
    mix = 1.0 / (1.0 + np.exp(-1.5 * (noise - 0.6)))  # patches of soil
    for c in range(3):
        out[:, :, c] = base[c] * (1 - mix) + soil[c] * mix + 0.035 * fine + 0.03 * noise
    return (np.clip(out, 0.0, 1.0) * 255.0).astype(np.uint8)


# --- box extraction ----------------------------------------------------------------------


class Annotation(NamedTuple):
    """Ground truth of one frame (:func:`annotate_mask`).

    Attributes:
        boxes: ``[N, 4]`` ``float32`` labelled boxes (xyxy pixels, ``x2``/``y2`` exclusive).
        labels: ``[N]`` ``int64`` their classes.
        ignore: ``[K, 4]`` ``float32`` ignore boxes: seen but not labelled.
        ignore_labels: ``[K]`` ``int64`` their classes.

    """

    boxes: np.ndarray
    labels: np.ndarray
    ignore: np.ndarray
    ignore_labels: np.ndarray


def annotate_mask(
    mask: np.ndarray,
    instances: Mapping[int, tuple[int, Callable[[], tuple[np.ndarray, np.ndarray]]]],
    camera: Camera,
    *,
    min_size: float = MIN_BOX_SIZE,
    min_height: float = 0.0,
    min_visible: float = MIN_VISIBLE,
    min_in_frame: float = MIN_IN_FRAME,
) -> Annotation:
    """Ground-truth and ignore boxes from a segmentation mask.

    For each object of a class (``instances``: body id → (label, world AABB)) with at least
    one visible pixel, the box is tight around its visible pixels (``x2``/``y2``
    exclusive). It is *labelled* when

    * it is at least ``min_size`` pixels wide and high (default 4), and at least
      ``min_height`` pixels high (the platform's :data:`MIN_LABEL_HEIGHT`);
    * the object is not mostly cut by the frame: at least ``min_in_frame`` (0.5) of the
      area of its projected world bounding box lies inside the image;
    * it is not mostly occluded: the visible box covers at least ``min_visible`` (0.25) of
      that projected box's in-frame part.

    Every other visible object becomes an *ignore box*: it is there, so a detector that
    finds it is not wrong, but it is not required either.

    Args:
        mask: ``[H, W]`` pybullet segmentation (object and link index).
        instances: body id → (label index, a function returning the body's world AABB
            ``(low[3], high[3])``; called only for bodies seen in the mask).
        camera: The camera that rendered ``mask``.
        min_size: See above.
        min_height: See above.
        min_visible: See above.
        min_in_frame: See above.

    Returns:
        An :class:`Annotation`; boxes ordered by body id.

    """
    h, w = mask.shape
    objects = np.where(mask >= 0, mask & 0xFFFFFF, -1)
    present = set(np.unique(objects).tolist())
    kept: tuple[list[list[float]], list[int]] = ([], [])
    ignored: tuple[list[list[float]], list[int]] = ([], [])
    for body in sorted(instances):
        if body not in present:
            continue
        label, aabb = instances[body]
        pix = objects == body
        cols = np.flatnonzero(pix.any(axis=0))
        rows = np.flatnonzero(pix.any(axis=1))
        x1, x2 = float(cols[0]), float(cols[-1] + 1)
        y1, y2 = float(rows[0]), float(rows[-1] + 1)
        box = [x1, y1, x2, y2]
        out = ignored
        if x2 - x1 >= min_size and y2 - y1 >= max(min_size, min_height):
            lo, hi = aabb()
            corners = np.array(
                [[a, b, c] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])]
            )
            uv = camera.project(corners, w, h)
            px1, py1 = uv.min(axis=0)
            px2, py2 = uv.max(axis=0)
            full = max((px2 - px1) * (py2 - py1), 1e-9)
            cx1, cy1 = max(px1, 0.0), max(py1, 0.0)
            cx2, cy2 = min(px2, float(w)), min(py2, float(h))
            inside = max(cx2 - cx1, 0.0) * max(cy2 - cy1, 0.0)
            if (
                inside / full >= min_in_frame
                and (x2 - x1) * (y2 - y1) / max(inside, 1e-9) >= min_visible
            ):
                out = kept
        out[0].append(box)
        out[1].append(label)
    return Annotation(
        np.asarray(kept[0], dtype=np.float32).reshape(-1, 4),
        np.asarray(kept[1], dtype=np.int64),
        np.asarray(ignored[0], dtype=np.float32).reshape(-1, 4),
        np.asarray(ignored[1], dtype=np.int64),
    )


def boxes_from_mask(
    mask: np.ndarray,
    instances: Mapping[int, tuple[int, Callable[[], tuple[np.ndarray, np.ndarray]]]],
    camera: Camera,
    *,
    min_size: float = MIN_BOX_SIZE,
    min_height: float = 0.0,
    min_visible: float = MIN_VISIBLE,
    min_in_frame: float = MIN_IN_FRAME,
) -> tuple[np.ndarray, np.ndarray]:
    """The labelled boxes of :func:`annotate_mask` (``boxes [N, 4]``, ``labels [N]``)."""
    ann = annotate_mask(
        mask,
        instances,
        camera,
        min_size=min_size,
        min_height=min_height,
        min_visible=min_visible,
        min_in_frame=min_in_frame,
    )
    return ann.boxes, ann.labels


# --- the scene ---------------------------------------------------------------------------


@dataclass
class _Body:
    placement: Placement
    body: int
    label: int  # -1 for distractors
    base_orn: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    extra: dict[str, float] = field(default_factory=dict)


class Scene:
    """A pybullet world for one platform and layout, rendering :class:`Frame` s.

    One pybullet client per scene; close it (or use ``with``). Class-object bodies are in
    :attr:`objects` (body id → (:class:`Placement`, label)).

    Args:
        platform: ``"rover"`` or ``"uav"``.
        layout: Scene number; seeds the placement of objects (:func:`layout_placements`).
        width: Image width in pixels.
        height: Image height in pixels.
        placements: Objects to place instead of the layout's (the layout still seeds the
            ground texture); e.g. a pedestrian on the rover's route.
        extra: Additional objects placed on top of the layout's.
        min_label_height: A labelled box is at least this fraction of the image height
            tall; smaller objects become ignore boxes (default: the platform's
            :data:`MIN_LABEL_HEIGHT`).

    """

    def __init__(
        self,
        platform: Platform,
        layout: int = 0,
        *,
        width: int = 128,
        height: int = 128,
        placements: Sequence[Placement] | None = None,
        extra: Sequence[Placement] = (),
        min_label_height: float | None = None,
    ) -> None:
        if platform not in _PLATFORM_CODE:
            raise ValueError(f"platform must be 'rover' or 'uav', got {platform!r}")
        if width < 8 or height < 8:
            raise ValueError(f"image size must be at least 8x8, got {width}x{height}")
        self.platform: Platform = platform
        self.layout = layout
        self.width = width
        self.height = height
        self.classes = ROVER_CLASSES if platform == "rover" else UAV_CLASSES
        self.min_label_height = (
            MIN_LABEL_HEIGHT[platform] if min_label_height is None else (min_label_height)
        )
        self.world = World()
        self._tmp = Path(tempfile.mkdtemp(prefix="anunnaki-sim-"))
        self._bodies: list[_Body] = []
        try:
            rng = np.random.default_rng(
                np.random.SeedSequence([layout, _PLATFORM_CODE[platform], 29])
            )
            self._ground(rng)
            chosen = list(layout_placements(platform, layout) if placements is None else placements)
            for placement in [*chosen, *extra]:
                self.add(placement)
        except BaseException:
            self.close()
            raise

    @property
    def client(self) -> int:
        """The pybullet client id (pass it as ``physicsClientId``)."""
        return self.world.client

    # -- building ---------------------------------------------------------------------------
    def _ground(self, rng: np.random.Generator) -> None:
        import cv2

        self.ground = self.world.load("plane.urdf", fixed=True)
        self._static_collisions(self.ground)
        path = self._tmp / "ground.png"
        cv2.imwrite(str(path), _ground_texture(rng, self.platform)[:, :, ::-1])
        texture = pybullet.loadTexture(str(path), physicsClientId=self.client)
        pybullet.changeVisualShape(
            self.ground, -1, textureUniqueId=texture, physicsClientId=self.client
        )

    def add(self, placement: Placement) -> int:
        """Place one object; return its body id."""
        kind = placement.kind
        label = self.classes.index(kind) if kind in self.classes else -1
        orn: tuple[float, float, float, float]
        if kind == "pedestrian":
            orn = pybullet.getQuaternionFromEuler([math.pi / 2, 0.0, placement.yaw])
            body = self.world.load(
                _HUMANOID, (0, 0, 5), orn, scale=placement.size * _HUMANOID_SCALE_PER_M, frozen=True
            )
            self._dress(body, placement.color, placement)
        elif kind == "deer":
            orn = pybullet.getQuaternionFromEuler([0.0, 0.0, placement.yaw])
            body = self.world.load(
                _lite_urdf(_DEER, self._tmp),
                (0, 0, 5),
                orn,
                scale=placement.size * _DEER_SCALE_PER_M,
                frozen=True,
            )
            for link in range(-1, self.world.num_links(body)):
                self.world.color(body, link, placement.color)
        elif kind == "vehicle":
            urdf, per_m = _VEHICLES[placement.variant % len(_VEHICLES)]
            orn = pybullet.getQuaternionFromEuler([0.0, 0.0, placement.yaw])
            body = self.world.load(
                _lite_urdf(urdf, self._tmp),
                (0, 0, 5),
                orn,
                scale=placement.size * per_m,
                frozen=True,
            )
            for link, geometry in self._visual_geometry(body):
                if geometry != pybullet.GEOM_CYLINDER:  # wheels stay dark
                    self.world.color(body, link, placement.color)
        elif kind in _DISTRACTORS:
            urdf, per_m = _DISTRACTORS[kind]
            orn = pybullet.getQuaternionFromEuler([0.0, 0.0, placement.yaw])
            body = self.world.load(urdf, (0, 0, 5), orn, scale=placement.size * per_m, frozen=True)
            self.world.color(body, -1, placement.color)
        elif kind in ("building", "tree", "road"):
            body, orn = self._primitive(placement)
        else:
            raise ValueError(
                f"unknown object kind {kind!r}; kinds: pedestrian, deer, vehicle, "
                f"{', '.join(sorted(_DISTRACTORS))}, building, tree, road"
            )
        self._static_collisions(body)
        entry = _Body(placement, body, label, orn)
        self._bodies.append(entry)
        self._settle(entry)
        return body

    def _static_collisions(self, body: int) -> None:
        """Let scene objects collide with robots (group 1) only.

        Not with each other or the ground: nothing in the scene moves by physics, so those
        contacts would only cost time.
        """
        for link in range(-1, self.world.num_links(body)):
            pybullet.setCollisionFilterGroupMask(
                body, link, SCENE_GROUP, ROBOT_GROUP, physicsClientId=self.client
            )

    def _visual_geometry(self, body: int) -> list[tuple[int, int]]:
        """(link, geometry type) of each visual shape of ``body``."""
        data = pybullet.getVisualShapeData(body, physicsClientId=self.client)
        return [(int(d[1]), int(d[2])) for d in data]

    def _primitive(self, pl: Placement) -> tuple[int, tuple[float, float, float, float]]:
        pb, cid = pybullet, self.client
        orn = tuple(pb.getQuaternionFromEuler([0.0, 0.0, pl.yaw]))
        if pl.kind == "road":
            # In 7 m segments: the tiny renderer is slow on triangles far larger than the view.
            n = max(1, math.ceil(pl.size / 7.0))
            seg = pl.size / n
            visual = pb.createVisualShape(
                pb.GEOM_BOX,
                halfExtents=[seg / 2, 3.0, 0.01],
                rgbaColor=list(pl.color),
                physicsClientId=cid,
            )
            c, s = math.cos(pl.yaw), math.sin(pl.yaw)
            offsets = [(-pl.size / 2 + seg * (k + 0.5)) for k in range(n)]
            for o in offsets:
                body = pb.createMultiBody(
                    0, -1, visual, [pl.x + o * c, pl.y + o * s, 0.0], orn, physicsClientId=cid
                )
        elif pl.kind == "building":
            half = [pl.size / 2, pl.size / 2 * 0.7, pl.size / 2 * 0.8]
            visual = pb.createVisualShape(
                pb.GEOM_BOX, halfExtents=half, rgbaColor=list(pl.color), physicsClientId=cid
            )
            shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=cid)
            body = pb.createMultiBody(
                0, shape, visual, [pl.x, pl.y, half[2]], orn, physicsClientId=cid
            )
        else:  # tree: a crown on a trunk
            r = pl.size / 2
            crown = pb.createVisualShape(
                pb.GEOM_SPHERE, radius=r, rgbaColor=list(pl.color), physicsClientId=cid
            )
            shape = pb.createCollisionShape(pb.GEOM_SPHERE, radius=r, physicsClientId=cid)
            body = pb.createMultiBody(
                0, shape, crown, [pl.x, pl.y, r * 1.6], orn, physicsClientId=cid
            )
        return int(body), (float(orn[0]), float(orn[1]), float(orn[2]), float(orn[3]))

    def _dress(self, body: int, shirt: tuple[float, float, float, float], pl: Placement) -> None:
        rng = np.random.default_rng([int(abs(pl.x) * 1000), int(abs(pl.y) * 1000), body])
        skin_v = float(rng.uniform(0.35, 0.95))
        colors = {
            "shirt": shirt,
            "trousers": _hsv(
                float(rng.uniform(0.55, 0.7)),
                float(rng.uniform(0.1, 0.6)),
                float(rng.uniform(0.15, 0.6)),
            ),
            "skin": (skin_v, skin_v * 0.78, skin_v * 0.62, 1.0),
            "shoes": (0.12, 0.1, 0.1, 1.0),
        }
        for part, links in _HUMANOID_LINKS.items():
            for link in links:
                self.world.color(body, link, colors[part])

    def _settle(self, entry: _Body) -> None:
        """Put the object's lowest point on the ground at its placement's (x, y)."""
        pl = entry.placement
        if pl.kind in ("road", "building", "tree"):
            return
        self.world.set_pose(entry.body, (pl.x, pl.y, 5.0), entry.base_orn)
        lo, hi = self.world.aabb(entry.body)
        cx, cy = (lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2
        self.world.set_pose(
            entry.body,
            (pl.x + (pl.x - cx), pl.y + (pl.y - cy), 5.0 - lo[2] + 0.002),
            entry.base_orn,
        )

    # -- per-frame variation ----------------------------------------------------------------
    def vary(self, rng: np.random.Generator) -> None:
        """Vary object poses (yaw jitter, limbs) and distractor colours, in place."""
        pb, cid = pybullet, self.client
        for entry in self._bodies:
            pl = entry.placement
            if pl.kind in ("road", "building", "tree"):
                continue
            yaw = pl.yaw + float(rng.normal(0.0, 0.3))
            if pl.kind == "pedestrian":
                entry.base_orn = tuple(pb.getQuaternionFromEuler([math.pi / 2, 0.0, yaw]))
                self.pose_pedestrian(
                    entry.body,
                    float(rng.uniform(0, 2 * math.pi)),
                    stride=float(rng.uniform(0.0, 0.6)),
                )
            elif pl.kind == "deer":
                entry.base_orn = tuple(pb.getQuaternionFromEuler([0.0, 0.0, yaw]))
                for j in range(self.world.num_links(entry.body)):
                    info = pb.getJointInfo(entry.body, j, physicsClientId=cid)
                    if info[2] == pb.JOINT_REVOLUTE:
                        pb.resetJointState(
                            entry.body, j, float(rng.normal(0.0, 0.15)), physicsClientId=cid
                        )
            else:
                entry.base_orn = tuple(pb.getQuaternionFromEuler([0.0, 0.0, yaw]))
                if entry.label < 0:
                    self.world.color(entry.body, -1, _random_color(rng))
            self._settle(entry)

    def pose_pedestrian(self, body: int, phase: float, *, stride: float = 0.5) -> None:
        """Set a walking pose: ``phase`` (rad) along the gait cycle, ``stride`` amplitude."""
        pb, cid = pybullet, self.client
        s = math.sin(phase)
        for joint, angle in ((9, stride * s), (12, -stride * s)):  # hips
            pb.resetJointStateMultiDof(
                body,
                joint,
                targetValue=pb.getQuaternionFromEuler([0, 0, angle]),
                physicsClientId=cid,
            )
        for joint, angle in ((3, -0.8 * stride * s), (6, 0.8 * stride * s)):  # shoulders
            pb.resetJointStateMultiDof(
                body,
                joint,
                targetValue=pb.getQuaternionFromEuler([0, 0, angle]),
                physicsClientId=cid,
            )
        for joint, angle in ((10, -stride * max(s, 0.0)), (13, -stride * max(-s, 0.0))):
            pb.resetJointState(body, joint, angle, physicsClientId=cid)  # knees

    def move(self, body: int, x: float, y: float, yaw: float | None = None) -> None:
        """Move a placed object to ``(x, y)`` on the ground (optionally turning it)."""
        for entry in self._bodies:
            if entry.body == body:
                pl = entry.placement
                new_yaw = pl.yaw if yaw is None else yaw
                entry.placement = Placement(pl.kind, x, y, new_yaw, pl.size, pl.color, pl.variant)
                roll = math.pi / 2 if pl.kind == "pedestrian" else 0.0
                entry.base_orn = tuple(pybullet.getQuaternionFromEuler([roll, 0.0, new_yaw]))
                self._settle(entry)
                return
        raise KeyError(f"no object with body id {body}")

    # -- queries ----------------------------------------------------------------------------
    @property
    def objects(self) -> dict[int, tuple[Placement, int]]:
        """Class objects: body id → (placement, label index)."""
        return {e.body: (e.placement, e.label) for e in self._bodies if e.label >= 0}

    @property
    def bodies(self) -> list[int]:
        """Body ids of every placed object, in placement order."""
        return [e.body for e in self._bodies]

    @property
    def tmpdir(self) -> Path:
        """The scene's private directory for generated assets (removed on close)."""
        return self._tmp

    @property
    def placements(self) -> list[Placement]:
        """Every placed object, in order."""
        return [e.placement for e in self._bodies]

    def random_camera(self, rng: np.random.Generator) -> Camera:
        """A random but plausible camera for this platform.

        Rover: 0.3 m above ground on or near the route, looking ahead (yaw within about
        ±25°, pitch ±4°); seven times in ten it is aimed within ±20° of an object of a class
        1.5-12 m away, the distance log-uniform so that a third of those frames show it
        within 3 m — the range in which the rover's stop rule acts on a detection. UAV:
        15-40 m up, looking down 35-80° below the horizon, aimed near an object of a class
        eight times in ten.
        """
        objs = [e.placement for e in self._bodies if e.label >= 0]
        if self.platform == "rover":
            z = 0.3 + float(rng.normal(0.0, 0.02))
            if objs and rng.random() < 0.7:
                tgt = objs[int(rng.integers(len(objs)))]
                dist = math.exp(float(rng.uniform(math.log(1.5), math.log(12.0))))
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
        alt = float(rng.uniform(15.0, 40.0))
        down = float(rng.uniform(math.radians(35), math.radians(80)))
        yaw = float(rng.uniform(-math.pi, math.pi))
        if objs and rng.random() < 0.8:
            tgt = objs[int(rng.integers(len(objs)))]
            tx, ty = tgt.x + float(rng.normal(0, 3)), tgt.y + float(rng.normal(0, 3))
        else:
            half = UAV_AREA / 2
            tx, ty = (float(v) for v in rng.uniform(-half * 0.8, half * 0.8, size=2))
        reach = alt / math.tan(down)
        eye = (tx - reach * math.cos(yaw), ty - reach * math.sin(yaw), alt)
        return Camera(eye, (tx, ty, 0.0), fov=32.0, near=0.5, far=250.0)

    @staticmethod
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

    def render(
        self, camera: Camera, *, light: Light | None = None, t: float = 0.0, seq: int = 0
    ) -> Frame:
        """Render one frame with its labelled and ignore boxes (see :func:`annotate_mask`)."""
        image, mask = self.world.render(camera, self.width, self.height, light)
        sky = mask < 0
        if sky.any():
            image[sky] = self._sky(light)[np.nonzero(sky)[0]]
        instances = {
            e.body: (e.label, functools.partial(self.world.aabb, e.body))
            for e in self._bodies
            if e.label >= 0
        }
        ann = annotate_mask(mask, instances, camera, min_height=self.min_label_height * self.height)
        return Frame(
            image=image,
            boxes=ann.boxes,
            labels=ann.labels,
            t=float(t),
            seq=int(seq),
            ignore=ann.ignore,
            ignore_labels=ann.ignore_labels,
        )

    def _sky(self, light: Light | None) -> np.ndarray:
        """Sky colour per image row ``[H, 3] uint8``: a blue gradient lit by ``light``."""
        light = light or Light()
        rows = np.linspace(0.0, 1.0, self.height)[:, None]
        top, horizon = np.array([0.45, 0.62, 0.88]), np.array([0.8, 0.87, 0.95])
        scale = min(1.0, light.ambient + 0.5 * light.diffuse) * np.asarray(light.color)
        return (np.clip((top * (1 - rows) + horizon * rows) * scale, 0, 1) * 255).astype(np.uint8)

    def render_mask(self, camera: Camera, *, light: Light | None = None) -> np.ndarray:
        """The object-id mask ``[H, W] int32`` (-1 background) for ``camera``."""
        _, mask = self.world.render(camera, self.width, self.height, light)
        return np.where(mask >= 0, mask & 0xFFFFFF, -1).astype(np.int32)

    def close(self) -> None:
        """Disconnect the pybullet client and remove temporary files (idempotent)."""
        self.world.close()
        shutil.rmtree(self._tmp, ignore_errors=True)

    def __enter__(self) -> Scene:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def dataset_frames(
    platform: Platform,
    *,
    layout: int,
    seed: int,
    n: int,
    width: int = 128,
    height: int = 128,
    min_label_height: float | None = None,
) -> Iterator[Frame]:
    """Yield ``n`` labelled frames of scene ``layout`` from random camera poses.

    Args:
        platform: ``"rover"`` (classes :data:`ROVER_CLASSES`) or ``"uav"``
            (:data:`UAV_CLASSES`).
        layout: Scene number: object placement is drawn from it, so different layouts are
            different scenes (use disjoint layouts for train/validation/test).
        seed: Seeds camera poses, lighting, object poses and distractor colours.
        n: Number of frames.
        width: Image width (pixels).
        height: Image height (pixels).
        min_label_height: Smallest labelled box height as a fraction of ``height``; objects
            seen but smaller are the frames' ignore boxes (default: the platform's
            :data:`MIN_LABEL_HEIGHT`, rover 0.134, UAV 0).

    Yields:
        :class:`Frame` s with ``t = seq / 10`` and ``seq = 0 … n-1``; deterministic for
        ``(platform, layout, seed, width, height)``. The scene's pybullet client is closed
        when the iterator is exhausted or closed.

    """
    if n < 0:
        raise ValueError(f"n must be >= 0, got {n}")
    rng = np.random.default_rng(np.random.SeedSequence([seed, layout, _PLATFORM_CODE[platform]]))
    with Scene(
        platform, layout, width=width, height=height, min_label_height=min_label_height
    ) as scene:
        for i in range(n):
            scene.vary(rng)
            camera = scene.random_camera(rng)
            light = scene.random_light(rng)
            yield scene.render(camera, light=light, t=i / 10.0, seq=i)
