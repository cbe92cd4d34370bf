"""Scenes: pybullet worlds of pedestrians, deer, vehicles and distractors, and their frames.

A :class:`Scene` places the objects of a layout (:mod:`anunnaki.sim._layout`) in a pybullet
world using the models of :mod:`anunnaki.sim._models`, varies them from frame to frame
(object poses, limbs, distractor colours) and renders frames from cameras and lights drawn
by :mod:`anunnaki.sim._camera`, with ground truth from the segmentation mask
(:mod:`anunnaki.sim._groundtruth`). Everything is deterministic for
``(platform, layout, seed)``. This module is the world and its lifetime; what it holds,
how it looks, where it is seen from and what counts as a box live beside it.
"""

from __future__ import annotations

import functools
import math
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from anunnaki._closing import Closing
from anunnaki.sim._camera import MIN_DISTANCE, random_camera, random_light, sky_rows
from anunnaki.sim._groundtruth import (
    MIN_LABEL_HEIGHT,
    Frame,
    annotate_mask,
)
from anunnaki.sim._layout import (
    _PLATFORM_CODE,
    ROVER_CLASSES,
    UAV_CLASSES,
    Placement,
    Platform,
    _hsv,
    _random_color,
    layout_placements,
)
from anunnaki.sim._models import (
    _DEER,
    _DEER_SCALE_PER_M,
    _DISTRACTORS,
    _HUMANOID,
    _HUMANOID_LINKS,
    _HUMANOID_SCALE_PER_M,
    _VEHICLES,
    _ground_texture,
    _lite_urdf,
)
from anunnaki.sim._world import Camera, Light, World, pybullet

__all__ = ["ROBOT_GROUP", "SCENE_GROUP", "Scene", "dataset_frames"]

ROBOT_GROUP = 1
"""Collision group of robots (the rover): they collide with everything."""
SCENE_GROUP = 2
"""Collision group of scene objects and the ground: they collide with robots only."""


@dataclass
class _Body:
    placement: Placement
    body: int
    label: int  # -1 for distractors
    base_orn: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    extra: dict[str, float] = field(default_factory=dict)


class Scene(Closing):
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

    def random_camera(
        self, rng: np.random.Generator, *, min_distance: float = MIN_DISTANCE
    ) -> Camera:
        """A random but plausible camera for this platform (see :func:`random_camera`)."""
        objs = [e.placement for e in self._bodies if e.label >= 0]
        return random_camera(self.platform, objs, rng, min_distance=min_distance)

    @staticmethod
    def random_light(rng: np.random.Generator) -> Light:
        """Slightly varied daylight: direction, colour temperature, ambient/diffuse."""
        return random_light(rng)

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
        """Sky colour per image row ``[H, 3] uint8`` (see :func:`sky_rows`)."""
        return sky_rows(self.height, light)

    def render_mask(self, camera: Camera, *, light: Light | None = None) -> np.ndarray:
        """The object-id mask ``[H, W] int32`` (-1 background) for ``camera``."""
        _, mask = self.world.render(camera, self.width, self.height, light)
        return np.where(mask >= 0, mask & 0xFFFFFF, -1).astype(np.int32)

    def close(self) -> None:
        """Disconnect the pybullet client and remove temporary files (idempotent)."""
        self.world.close()
        shutil.rmtree(self._tmp, ignore_errors=True)


def dataset_frames(
    platform: Platform,
    *,
    layout: int,
    seed: int,
    n: int,
    width: int = 128,
    height: int = 128,
    min_label_height: float | None = None,
    clutter: bool = True,
    min_distance: float = MIN_DISTANCE,
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
        clutter: ``False`` keeps only the layout's objects of a class (no distractors,
            roads, buildings or trees): bare ground with pedestrians and deer, the look of a
            rover scenario with ``background: false``.
        min_distance: Rover: the nearest distance (m) of an object the camera aims at
            (:func:`random_camera`).

    Yields:
        :class:`Frame` s with ``t = seq / 10`` and ``seq = 0 … n-1``; deterministic for
        ``(platform, layout, seed, width, height)``. The scene's pybullet client is closed
        when the iterator is exhausted or closed.

    """
    if n < 0:
        raise ValueError(f"n must be >= 0, got {n}")
    rng = np.random.default_rng(np.random.SeedSequence([seed, layout, _PLATFORM_CODE[platform]]))
    classes = ROVER_CLASSES if platform == "rover" else UAV_CLASSES
    placements = (
        None if clutter else [p for p in layout_placements(platform, layout) if p.kind in classes]
    )
    with Scene(
        platform,
        layout,
        width=width,
        height=height,
        placements=placements,
        min_label_height=min_label_height,
    ) as scene:
        for i in range(n):
            scene.vary(rng)
            camera = scene.random_camera(rng, min_distance=min_distance)
            light = scene.random_light(rng)
            yield scene.render(camera, light=light, t=i / 10.0, seq=i)
