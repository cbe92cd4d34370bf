"""The simulated rover: a husky driving a route among pedestrians, deer and distractors.

It carries a forward camera, an ultrasonic range finder, a bumper, a buzzer and lights.

How the autonomous rover decides to stop (:class:`StopRule`): from what its sensors give
it, never from the simulator's ground truth —

* the detector's published detections (``Detections`` on ``/lec/detector/detections``): a
  pedestrian or deer box with score ≥ ``min_score`` whose bottom edge puts it within
  ``stop_distance`` metres ahead (flat-ground monocular ranging: a point on the ground at
  distance d appears ``f·h/d`` pixels below the horizon, for a camera ``h`` = 0.3 m high
  with focal length ``f`` in pixels) and whose lateral extent at that distance overlaps the
  corridor ``±corridor`` m; or a box taller than ``near_height`` of the image overlapping
  the corridor (something very close, its feet cut by the frame);
* the ultrasonic range finder reading below ``ultrasonic_range`` metres.

Evidence older than ``max_age`` seconds is ignored (a detector that fell silent gives no
evidence either way). On evidence the rover brakes, sounds the buzzer and flashes its
lights; it drives on ``clear_time`` seconds after the last evidence. A collision is a new
bumper contact with a pedestrian or a deer; any contact sets ``bumper``.
"""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from anunnaki import topics
from anunnaki.messages import Detections, body_of
from anunnaki.sim._layout import Placement, layout_placements
from anunnaki.sim._models import _lite_urdf
from anunnaki.sim._platform import SimPlatform, as_scenario
from anunnaki.sim._scenario import ObjectSpec, Scenario
from anunnaki.sim._scene import ROBOT_GROUP, Scene
from anunnaki.sim._world import Camera, pybullet

__all__ = [
    "CAMERA_FOV",
    "CAMERA_HEIGHT",
    "RoverMode",
    "RoverSim",
    "StopRule",
]

log = logging.getLogger("anunnaki.sim")

RoverMode = Literal["autonomous", "manual", "stopped"]
CAMERA_HEIGHT = 0.3
"""Height of the rover's camera above ground (m)."""
CAMERA_FOV = 60.0
"""Vertical field of view of the rover's camera (degrees), as in the rover's datasets."""
_CAMERA_FORWARD = 0.55  # m ahead of the base origin: the front bumper
_WHEEL_RADIUS = 0.17775
_TRACK = 0.555
_TELEOP_TIMEOUT = 0.5
_CONTACT_EVERY = 4  # ticks between bumper checks (60 Hz)


@dataclass(frozen=True)
class StopRule:
    """When the autonomous rover stops (see the module docstring).

    Attributes:
        classes: Detected classes that stop the rover.
        min_score: Minimum detection score.
        stop_distance: Stop for a box estimated this close ahead (m).
        corridor: Half-width of the path ahead (m).
        near_height: Stop for a box this tall (fraction of image height) in the corridor.
        ultrasonic_range: Stop when the ultrasonic reads less than this (m).
        max_age: Ignore detections and ranges older than this (s).
        clear_time: Drive on this long after the last evidence (s).

    """

    classes: tuple[str, ...] = ("pedestrian", "deer")
    min_score: float = 0.5
    stop_distance: float = 3.0
    corridor: float = 0.7
    near_height: float = 0.6
    ultrasonic_range: float = 1.0
    max_age: float = 0.5
    clear_time: float = 1.0

    def box_ahead(
        self, box: Sequence[float], width: int, height: int, *, fov: float = CAMERA_FOV
    ) -> bool:
        """Whether a detection box (pixels) shows something close ahead."""
        x1, _, x2, y2 = (float(v) for v in box)
        f = (height / 2.0) / math.tan(math.radians(fov) / 2.0)
        below = y2 - height / 2.0  # rows below the horizon
        if (y2 - float(box[1])) >= self.near_height * height:
            distance = CAMERA_HEIGHT * f / max(below, 1.0)
            distance = min(distance, self.stop_distance)
        elif below <= 0.5:
            return False
        else:
            distance = CAMERA_HEIGHT * f / below
            if distance > self.stop_distance:
                return False
        left = (x1 - width / 2.0) / f * distance
        right = (x2 - width / 2.0) / f * distance
        return right >= -self.corridor and left <= self.corridor

    def detections_ahead(self, det: Detections) -> bool:
        """Whether any detection in ``det`` stops the rover."""
        return any(
            label in self.classes
            and score >= self.min_score
            and self.box_ahead(box, det.width, det.height)
            for box, label, score in zip(det.boxes, det.labels, det.scores, strict=True)
        )


def _route_distance(route: Sequence[tuple[float, float]], x: float, y: float) -> float:
    best = math.inf
    for (ax, ay), (bx, by) in itertools.pairwise(route):
        dx, dy = bx - ax, by - ay
        n = dx * dx + dy * dy
        u = 0.0 if n == 0 else min(max(((x - ax) * dx + (y - ay) * dy) / n, 0.0), 1.0)
        best = min(best, math.hypot(x - ax - u * dx, y - ay - u * dy))
    return best


def _placement(spec: ObjectSpec) -> Placement:
    defaults = {"pedestrian": 1.7, "deer": 1.4, "vehicle": 4.0}
    size = spec.size if spec.size is not None else defaults.get(spec.kind, 0.4)
    color = {"pedestrian": (0.8, 0.2, 0.2, 1.0), "deer": (0.6, 0.42, 0.25, 1.0)}.get(
        spec.kind, (0.5, 0.5, 0.8, 1.0)
    )
    return Placement(spec.kind, spec.x, spec.y, yaw=spec.yaw, size=size, color=color)


def _background(sc: Scenario, route: Sequence[tuple[float, float]]) -> list[Placement]:
    """The layout's objects the scenario keeps: off the route and ahead of its start."""
    if not sc.background:
        return []
    return [
        p
        for p in layout_placements("rover", sc.layout)
        if _route_distance(route, p.x, p.y) > 1.3 and p.x > route[0][0] + 1.5
    ]


def _walkers(scene: Scene, sc: Scenario, n_layout: int) -> list[tuple[int, ObjectSpec]]:
    """(body, spec) of the scenario's objects that walk (placed after the layout's)."""
    placed = scene.placements[n_layout:]
    bodies = scene.bodies[n_layout:]
    return [
        (body, spec)
        for body, spec, pl in zip(bodies, sc.objects, placed, strict=True)
        if spec.walk_to is not None and spec.speed > 0 and pl.kind == spec.kind
    ]


class RoverSim(SimPlatform):
    """The simulated rover on the bus (same topics and services as the scripted rover).

    Publishes ``/rover/camera/image`` (``Image``), ``/rover/camera/info`` {seq, width,
    height, t}, ``/rover/ultrasonic`` {range}, ``/rover/status`` {mode, buzzer, bumper,
    lights, speed, collisions, stopped, warning, obstacle, x, y, t}, ``/sim/ground_truth``,
    ``/sim/phenomena`` and ``/clock``. Offers ``/rover/set_mode`` {mode: autonomous|manual}
    and ``/rover/stop`` {reason}; listens to ``/rover/buzzer`` {on}, ``/rover/lights`` {on},
    ``/rover/teleop`` {linear, angular} (manual mode only), ``/utu/run_stop`` and the
    detector's ``/lec/detector/detections``.

    Args:
        bus: The bus.
        scenario: A scenario (file, mapping or :class:`Scenario`); ``None`` for defaults.
        stop_rule: When autonomous driving stops (from detections and ultrasonic only).
        mode: The initial mode.
        clear_layout: Leave the layout's objects out (only the scenario's objects).
        physics_hz: Physics rate.
        clock_rate: ``/clock`` rate (Hz of simulated time).
        status_rate: ``/rover/status`` rate.
        detections_topic: Where the detector publishes.
        publish_ground_truth: Publish ``/sim/ground_truth`` (scoring only).
        frame_hook: ``hook(sim, frame, image)`` after each camera frame.

    """

    prefix = "/rover"
    platform = "rover"
    modes: tuple[str, ...] = ("autonomous", "manual")

    def __init__(
        self,
        bus: Any,
        scenario: Scenario | str | Path | Mapping[str, Any] | None = None,
        *,
        stop_rule: StopRule | None = None,
        mode: RoverMode = "autonomous",
        clear_layout: bool = False,
        physics_hz: float = 240.0,
        clock_rate: float = 40.0,
        status_rate: float = 10.0,
        detections_topic: str = topics.DETECTIONS,
        publish_ground_truth: bool = True,
        frame_hook: Any = None,
    ) -> None:
        sc = as_scenario(scenario, "rover")
        route = [(float(x), float(y)) for x, y in sc.route]
        background = [] if clear_layout else _background(sc, route)
        scene = Scene(
            "rover",
            sc.layout,
            width=sc.camera.width,
            height=sc.camera.height,
            placements=background,
            extra=[_placement(o) for o in sc.objects],
        )
        try:
            super().__init__(
                bus,
                sc,
                scene=scene,
                physics_hz=physics_hz,
                clock_rate=clock_rate,
                status_rate=status_rate,
                publish_ground_truth=publish_ground_truth,
                frame_hook=frame_hook,
            )
            self.stop_rule = stop_rule or StopRule()
            self.route = route
            self._waypoint = 1
            self._build_rover()
            self._walkers = _walkers(scene, sc, len(background))
            self._class_bodies = set(scene.objects)
            self._init_state(mode)
            self._declared = self._declare(bus, detections_topic)
        except BaseException:
            scene.close()
            raise

    def _init_state(self, mode: RoverMode) -> None:
        """The rover's state at start: commands, sensors, contacts and counters."""
        self.mode: RoverMode = mode
        self.buzzer_cmd = False
        self.lights_cmd = False
        self.warning = False
        self.obstacle: str | None = None
        self.bumper = False
        self.collisions = 0
        self.collided_with: list[int] = []
        self.arrived = False
        self.speed = 0.0
        self.teleop_count = 0
        self.teleop_received = 0
        self.detections_received = 0
        self.malformed = 0
        self._touching: set[int] = set()
        self._last_touch: dict[int, float] = {}
        self._teleop: tuple[float, float, float] | None = None  # (t, linear, angular)
        self._detections: tuple[float, Detections] | None = None
        self._range: tuple[float, float] | None = None  # (t, metres)
        self._hold_until = -math.inf
        self._drive_cmd = (math.nan, math.nan)
        self.commands: list[tuple[float, str, dict[str, Any]]] = []

    def _declare(self, bus: Any, detections_topic: str) -> list[Any]:
        """The rover's services and subscriptions (closed with the platform)."""
        return [
            bus.service(f"{self.prefix}/set_mode", self._srv_set_mode),
            bus.service(f"{self.prefix}/stop", self._srv_stop),
            bus.subscribe(f"{self.prefix}/buzzer", self._on_buzzer, queue=16),
            bus.subscribe(f"{self.prefix}/lights", self._on_lights, queue=16),
            bus.subscribe(f"{self.prefix}/teleop", self._on_teleop, queue=64),
            bus.subscribe(topics.RUN_STOP, self._on_run_stop, queue=4),
            bus.subscribe(detections_topic, self._on_detections, queue=8),
        ]

    # -- building ---------------------------------------------------------------------------
    def _build_rover(self) -> None:
        pb, cid = pybullet, self.scene.client
        pb.setTimeStep(1.0 / self.physics_hz, physicsClientId=cid)
        (x0, y0), (x1, y1) = self.route[0], self.route[1]
        yaw = math.atan2(y1 - y0, x1 - x0)
        orn = pb.getQuaternionFromEuler([0.0, 0.0, yaw])
        self.body = self.scene.world.load(
            _lite_urdf("husky/husky.urdf", self.scene.tmpdir), (x0, y0, 0.02), tuple(orn)
        )
        wheels = {}
        for j in range(self.scene.world.num_links(self.body)):
            name = pb.getJointInfo(self.body, j, physicsClientId=cid)[1].decode()
            if name.endswith("wheel"):
                wheels[name] = j
        self._left = [j for n, j in sorted(wheels.items()) if "left" in n]
        self._right = [j for n, j in sorted(wheels.items()) if "right" in n]
        for link in range(-1, self.scene.world.num_links(self.body)):
            pb.setCollisionFilterGroupMask(
                self.body, link, ROBOT_GROUP, 0xFFFF, physicsClientId=cid
            )
        for _ in range(int(self.physics_hz * 0.25)):  # settle on the ground
            pb.stepSimulation(physicsClientId=cid)

    # -- commands (bus threads: record only) ------------------------------------------------
    def _srv_set_mode(self, message: Any) -> dict[str, Any]:
        body = body_of(message)
        mode = body.get("mode")
        if mode not in self.modes:
            return {"ok": False, "error": f"unknown mode {mode!r}; modes: {list(self.modes)}"}
        with self._lock:
            if self.mode == "stopped":
                return {"ok": False, "error": "the rover is stopped (run-stop)"}
            self.mode = mode
            self.commands.append((self.t, "set_mode", body))
        self._notify()
        log.info("rover: mode -> %s", mode)
        return {"ok": True, "mode": mode}

    def _srv_stop(self, message: Any) -> dict[str, Any]:
        body = body_of(message)
        self.run_stop(str(body.get("reason", "")))
        return {"ok": True, "stopped": True}

    def run_stop(self, reason: str = "") -> None:
        """Stop the rover at once; it stays stopped (``set_mode`` is refused)."""
        with self._lock:
            self.mode = "stopped"
            self.commands.append((self.t, "stop", {"reason": reason}))
        self._notify()
        log.info("rover: run-stop (%s)", reason)

    def _on_run_stop(self, sample: Any) -> None:
        self.run_stop(str(body_of(sample.message).get("reason", "run_stop")))

    def _switch(self, what: str, sample: Any) -> tuple[bool, dict[str, Any]] | None:
        """``{"on": true|false}`` (no ``on``: off); anything else is counted and ignored."""
        body = body_of(sample.message)
        on = body.get("on", False)
        if not isinstance(on, bool):
            with self._lock:
                self.malformed += 1
            self._notify()
            log.warning("rover: ignoring a %s command whose 'on' is not true/false: %r", what, on)
            return None
        return on, body

    def _on_buzzer(self, sample: Any) -> None:
        if (switch := self._switch("buzzer", sample)) is None:
            return
        with self._lock:
            self.buzzer_cmd = switch[0]
            self.commands.append((self.t, "buzzer", switch[1]))
        self._notify()

    def _on_lights(self, sample: Any) -> None:
        if (switch := self._switch("lights", sample)) is None:
            return
        with self._lock:
            self.lights_cmd = switch[0]
            self.commands.append((self.t, "lights", switch[1]))
        self._notify()

    def _on_teleop(self, sample: Any) -> None:
        body = body_of(sample.message)
        try:
            linear = float(body.get("linear", 0.0))
            angular = float(body.get("angular", 0.0))
        except (TypeError, ValueError):
            log.warning("rover: bad teleop command %r", body)
            return
        if not (math.isfinite(linear) and math.isfinite(angular)):
            return
        self.teleop(linear, angular)

    def teleop(self, linear: float, angular: float) -> bool:
        """A teleoperation command (m/s, rad/s); taken only in manual mode, for 0.5 s."""
        with self._lock:
            self.teleop_received += 1
            accepted = self.mode == "manual"
            if accepted:
                self.teleop_count += 1
                self._teleop = (self.t, max(-1.0, min(1.0, linear)), max(-2.0, min(2.0, angular)))
        self._notify()
        return accepted

    def _on_detections(self, sample: Any) -> None:
        det = self.detections_of(sample.message)
        if det is None:
            with self._lock:
                self.malformed += 1
            self._notify()
            log.warning("rover: ignoring a detections message that is not Detections")
            return
        self.observe_detections(det)

    def observe_detections(self, det: Detections) -> None:
        """Take in the detector's output for a frame (what the bus subscription does)."""
        with self._lock:
            self._detections = (self.t, det)
            self.detections_received += 1
        self._notify()

    # -- physics ----------------------------------------------------------------------------
    def _pose(self) -> tuple[float, float, float]:
        pos, orn = pybullet.getBasePositionAndOrientation(
            self.body, physicsClientId=self.scene.client
        )
        yaw = pybullet.getEulerFromQuaternion(orn)[2]
        return float(pos[0]), float(pos[1]), float(yaw)

    def _evidence(self, t: float) -> str | None:
        rule = self.stop_rule
        rng, det = self._range, self._detections
        if rng is not None and t - rng[0] <= rule.max_age and rng[1] < rule.ultrasonic_range:
            return "ultrasonic"
        if det is not None and t - det[0] <= rule.max_age and rule.detections_ahead(det[1]):
            return "detector"
        return None

    def _tick(self, h: float) -> None:
        pb, cid = pybullet, self.scene.client
        t = self.t
        with self._lock:
            mode = self.mode
            teleop = self._teleop
            evidence = self._evidence(t) if mode == "autonomous" else None
        x, y, yaw = self._pose()
        v = w = 0.0
        warning = False
        if mode == "manual":
            if teleop is not None and t - teleop[0] <= _TELEOP_TIMEOUT:
                v, w = teleop[1], teleop[2]
        elif mode == "autonomous":
            if evidence is not None:
                self._hold_until = t + self.stop_rule.clear_time
                self.obstacle = evidence
            if t < self._hold_until:
                warning = True
            else:
                self.obstacle = None
                v, w = self._pursue(x, y, yaw)
        self.warning = warning
        if (v, w) != self._drive_cmd:
            self._drive_cmd = (v, w)
            left = (v - w * _TRACK / 2.0) / _WHEEL_RADIUS
            right = (v + w * _TRACK / 2.0) / _WHEEL_RADIUS
            joints = self._left + self._right
            velocities = [left] * len(self._left) + [right] * len(self._right)
            pb.setJointMotorControlArray(
                self.body,
                joints,
                pb.VELOCITY_CONTROL,
                targetVelocities=velocities,
                forces=[60.0] * len(joints),
                physicsClientId=cid,
            )
        if self._walkers and self.tick % _CONTACT_EVERY == 0:
            self._walk(t, h * _CONTACT_EVERY)
        pb.stepSimulation(physicsClientId=cid)
        if self.tick % _CONTACT_EVERY == 0:
            self._contacts()
            lin, _ = pb.getBaseVelocity(self.body, physicsClientId=cid)
            speed = float(lin[0] * math.cos(yaw) + lin[1] * math.sin(yaw))
            self.speed = speed if abs(speed) >= 5e-3 else 0.0

    def _pursue(self, x: float, y: float, yaw: float) -> tuple[float, float]:
        while self._waypoint < len(self.route):
            tx, ty = self.route[self._waypoint]
            if math.hypot(tx - x, ty - y) > 0.5:
                break
            self._waypoint += 1
        if self._waypoint >= len(self.route):
            self.arrived = True
            return 0.0, 0.0
        tx, ty = self.route[self._waypoint]
        err = math.atan2(ty - y, tx - x) - yaw
        err = math.atan2(math.sin(err), math.cos(err))
        w = max(-1.0, min(1.0, 2.0 * err))
        v = self.scenario.cruise_speed * max(0.0, math.cos(err))
        return v, w

    def _walk(self, t: float, h: float) -> None:
        for body, spec in self._walkers:
            if t < spec.start or spec.walk_to is None:
                continue
            pl = self.scene.objects[body][0] if body in self.scene.objects else None
            x, y = (pl.x, pl.y) if pl is not None else (spec.x, spec.y)
            tx, ty = spec.walk_to
            d = math.hypot(tx - x, ty - y)
            if d < 1e-3:
                continue
            step = min(d, spec.speed * h)
            heading = math.atan2(ty - y, tx - x)
            self.scene.move(
                body, x + step * math.cos(heading), y + step * math.sin(heading), heading
            )

    def _contacts(self) -> None:
        cid = self.scene.client
        touching = {
            int(c[2])
            for c in pybullet.getContactPoints(bodyA=self.body, physicsClientId=cid)
            if int(c[2]) != self.scene.ground
        }
        self.bumper = bool(touching)
        t = self.t
        for body in touching - self._touching:
            # one collision per object and contact episode (a second apart at least)
            if body in self._class_bodies and t - self._last_touch.get(body, -math.inf) > 1.0:
                self.collisions += 1
                self.collided_with.append(body)
                log.info("rover: collision with body %d at t=%.2f", body, t)
        for body in touching:
            self._last_touch[body] = t
        self._touching = touching

    # -- sensors ----------------------------------------------------------------------------
    def range_ahead(self) -> float:
        """The ultrasonic's reading now: nearest hit of a 20-ray cone ahead (m).

        The sensor sits on the front bumper 0.25 m above ground; its beam is modelled as
        rays 12° either side and from 10° below to 25° above the horizontal.
        """
        x, y, yaw = self._pose()
        max_range = self.scenario.ultrasonic.max_range
        sx, sy, sz = x + _CAMERA_FORWARD * math.cos(yaw), y + _CAMERA_FORWARD * math.sin(yaw), 0.25
        starts, ends = [], []
        for el in np.radians([-10.0, 0.0, 12.0, 25.0]):
            for az in np.radians([-12.0, -6.0, 0.0, 6.0, 12.0]):
                heading = yaw + float(az)
                horizontal = max_range * math.cos(float(el))
                starts.append([sx, sy, sz])
                ends.append(
                    [
                        sx + horizontal * math.cos(heading),
                        sy + horizontal * math.sin(heading),
                        sz + max_range * math.sin(float(el)),
                    ]
                )
        hits = pybullet.rayTestBatch(starts, ends, physicsClientId=self.scene.client)
        fractions = [h[2] for h in hits if h[0] >= 0 and h[0] not in (self.body, self.scene.ground)]
        return float(min(fractions) * max_range) if fractions else float(max_range)

    def _sensors(self) -> None:
        t = self.t
        us = self.scenario.ultrasonic
        due = self._due("ultrasonic", self.timeline.rate("ultrasonic", us.rate, t))
        if due and not self.timeline.silent("ultrasonic", t):  # a dropped-out one measures nothing
            r = self.range_ahead()
            with self._lock:
                self._range = (t, r)
            self._publish(f"{self.prefix}/ultrasonic", {"range": round(r, 4)}, "ultrasonic")

    def _camera(self) -> Camera:
        x, y, yaw = self._pose()
        c, s = math.cos(yaw), math.sin(yaw)
        eye = (x + _CAMERA_FORWARD * c, y + _CAMERA_FORWARD * s, CAMERA_HEIGHT)
        target = (eye[0] + 10.0 * c, eye[1] + 10.0 * s, CAMERA_HEIGHT)
        return Camera(eye, target, fov=CAMERA_FOV, near=0.05, far=60.0)

    def _before_frame(self) -> None:
        for body, spec in self._walkers:
            if self.t >= spec.start and spec.kind == "pedestrian":
                self.scene.pose_pedestrian(body, self.t * 6.0, stride=0.45)

    # -- state ------------------------------------------------------------------------------
    @property
    def buzzer(self) -> bool:
        """The buzzer sounds: commanded on, or warning of an obstacle."""
        return self.buzzer_cmd or self.warning

    @property
    def lights(self) -> bool:
        """The lights are on: commanded on, or flashing a warning."""
        return self.lights_cmd or self.warning

    @property
    def position(self) -> tuple[float, float]:
        """The rover's (x, y) in metres."""
        x, y, _ = self._pose()
        return x, y

    def distance_to(self, body: int) -> float:
        """Closest distance between the rover's and ``body``'s collision shapes (m)."""
        pts = pybullet.getClosestPoints(self.body, body, 100.0, physicsClientId=self.scene.client)
        return float(min(p[8] for p in pts)) if pts else math.inf

    def status(self) -> dict[str, Any]:
        """The ``/rover/status`` message."""
        x, y, _ = self._pose()
        with self._lock:
            return {
                "mode": self.mode,
                "buzzer": self.buzzer,
                "bumper": self.bumper,
                "lights": self.lights,
                "speed": round(self.speed, 4),
                "collisions": self.collisions,
                "stopped": self.mode == "stopped",
                "warning": self.warning,
                "obstacle": self.obstacle,
                "x": round(x, 4),
                "y": round(y, 4),
                "t": round(self.t, 6),
            }
