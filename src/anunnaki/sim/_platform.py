"""What the rover and the UAV share: simulated time, sensor schedules, the camera pipeline.

Time is the simulation's: an integer physics tick at ``physics_hz`` (240 Hz). Every sensor
has a schedule in ticks, so a 10 Hz camera fires every 24 ticks exactly and a 4.8 Hz
ultrasonic every 50, and ``step(dt)`` is deterministic: the same calls publish the same
messages with the same contents, whatever the wall clock does. ``run()`` only paces those
steps against the wall clock.

Commands arrive on bus threads; handlers only record them under a lock, and the next
physics tick applies them (pybullet clients are not thread-safe).

The camera pipeline: render the clean frame (ground truth from its segmentation mask) →
apply the scenario's phenomena in order (:mod:`anunnaki.phenomena`) → encode (JPEG/PNG) →
publish the image, its info, the clean frame's ground truth (``/sim/ground_truth``; with
``hidden``, one flag per labelled box, when a phenomenon reports an occlusion mask: the box is
at least half hidden, ``anunnaki.phenomena.HIDDEN``) and what was applied (``/sim/phenomena``).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from anunnaki import topics
from anunnaki._closing import Closing
from anunnaki.messages import Clock, Detections, Image, body_of
from anunnaki.sim._groundtruth import Frame
from anunnaki.sim._scenario import Scenario, Timeline, load_scenario
from anunnaki.sim._scene import Scene
from anunnaki.sim._world import Camera, Light

__all__ = [
    "FrameHook",
    "SimPlatform",
    "as_scenario",
]

log = logging.getLogger("anunnaki.sim")


FrameHook = Callable[["SimPlatform", Frame, np.ndarray], None]
"""Called after each camera frame with the clean frame and the perturbed image."""


def as_scenario(
    scenario: Scenario | str | Path | Mapping[str, Any] | None, platform: str
) -> Scenario:
    """A :class:`Scenario` from a file, a mapping or ``None`` (the platform's defaults)."""
    if scenario is None:
        return Scenario(platform=platform)
    if isinstance(scenario, Scenario):
        sc = scenario
    elif isinstance(scenario, str | Path):
        sc = load_scenario(scenario)
    else:
        from anunnaki.sim._scenario import parse_scenario

        sc = parse_scenario(dict(scenario))
    if sc.platform != platform:
        raise ValueError(f"the scenario is for the {sc.platform}, not the {platform}")
    return sc


@dataclass
class _Schedule:
    next_tick: int = 0


class SimPlatform(Closing):
    """Base of the simulated platforms: ticks, schedules, camera, clock and ground truth.

    Subclasses implement :meth:`_tick` (one physics step), :meth:`_camera` (the camera pose)
    and :meth:`_sensors` (publish what is due besides the camera); the framework calls them.

    ``publish_clean`` (default ``False``): also publish each camera frame as rendered before
    the scenario's phenomena, on ``topics.CLEAN_FRAMES`` (same ``seq`` and encoding, just
    before the camera frame), for a scorer that compares the model on both (a simulated
    system turns it on when its oracle or scorer asks for them).
    """

    prefix = "/sim"
    platform = "rover"

    def __init__(
        self,
        bus: Any,
        scenario: Scenario,
        *,
        scene: Scene,
        physics_hz: float = 240.0,
        clock_rate: float = 40.0,
        status_rate: float = 10.0,
        publish_ground_truth: bool = True,
        frame_hook: FrameHook | None = None,
    ) -> None:
        self.bus = bus
        self.scenario = scenario
        self.timeline = Timeline(scenario)
        self.scene = scene
        self.physics_hz = float(physics_hz)
        self.clock_rate = clock_rate
        self.status_rate = status_rate
        self.publish_ground_truth = publish_ground_truth
        self.publish_clean = False
        self.frame_hook = frame_hook
        self.tick = 0
        self.frames = 0
        self.published: dict[str, int] = {}
        self.last_frame: Frame | None = None
        self.last_image: np.ndarray | None = None
        self.last_phenomena: list[tuple[str, dict[str, float]]] = []
        self._lock = threading.RLock()
        self._changed = threading.Condition(self._lock)
        self._pending = 0.0
        self._schedules: dict[str, _Schedule] = {}
        self._light = Light()
        self._declared: list[Any] = []
        self._closed = False
        from anunnaki.phenomena import PHENOMENA

        self._get_phenomenon = PHENOMENA.create

    # -- time -----------------------------------------------------------------------------
    @property
    def t(self) -> float:
        """Simulation time (s)."""
        return self.tick / self.physics_hz

    def step(self, dt: float) -> None:
        """Advance the simulation by ``dt`` seconds and publish whatever falls due.

        Physics runs at ``physics_hz``; ``dt`` need not be a multiple of a tick (the rest
        carries over to the next call).
        """
        if dt < 0:
            raise ValueError(f"dt must be >= 0, got {dt}")
        self._pending += dt * self.physics_hz
        n = math.floor(self._pending + 1e-6)
        self._pending -= n
        for _ in range(n):
            self._publish_due()  # what is due at this instant, then advance one tick
            self._tick(1.0 / self.physics_hz)
            self.tick += 1

    def run(
        self,
        stop: threading.Event | None = None,
        *,
        speed: float = 1.0,
        until: float | None = None,
        every: float = 1.0,
        callback: Callable[[SimPlatform], None] | None = None,
    ) -> None:
        """Run live: ``speed`` × real time (0 = as fast as possible) until ``stop`` is set.

        Args:
            stop: Set it to end the run (from another thread or a signal handler).
            speed: Simulated seconds per wall second; 0 runs flat out.
            until: End at this simulation time.
            every: Call ``callback`` every this many simulated seconds.
            callback: ``callback(sim)``, e.g. to print progress.

        """
        stop = stop or threading.Event()
        wall0, sim0 = time.monotonic(), self.t
        next_call = self.t + every
        chunk = 1.0 / 60.0
        while not stop.is_set():
            if until is not None and self.t >= until - 1e-9:
                break
            if speed > 0:
                target = sim0 + (time.monotonic() - wall0) * speed
                ahead = self.t - target
                if ahead > 0:
                    if stop.wait(min(ahead / speed, 0.05)):
                        break
                    continue
                dt = min(max(target - self.t, 1.0 / self.physics_hz), 0.25)
            else:
                dt = chunk
            if until is not None:
                dt = min(dt, until - self.t)
            if callback is not None:
                dt = min(dt, max(next_call - self.t, 1.0 / self.physics_hz))
            self.step(dt)
            if callback is not None and self.t >= next_call - 1e-9:
                next_call += every
                try:
                    callback(self)
                except Exception:  # a progress printer never kills the simulation
                    log.exception("sim: callback failed")

    # -- scheduling -------------------------------------------------------------------------
    def _due(self, name: str, rate: float) -> bool:
        """Whether the sensor ``name`` at ``rate`` Hz fires at this tick (and re-arm it)."""
        sched = self._schedules.setdefault(name, _Schedule(self.tick))
        if rate <= 0 or self.tick < sched.next_tick:
            return False
        sched.next_tick = self.tick + max(1, round(self.physics_hz / rate))
        return True

    def _publish(self, topic: str, message: Any, sensor: str | None = None) -> bool:
        """Publish unless ``sensor`` is in a scenario dropout; count it."""
        if sensor is not None and self.timeline.silent(sensor, self.t):
            return False
        try:
            self.bus.publish(topic, message)
        except Exception:  # a closed or broken bus never kills the simulation
            log.exception("sim: publishing on %s failed", topic)
            return False
        self.published[topic] = self.published.get(topic, 0) + 1
        return True

    def _publish_due(self) -> None:
        t = self.t
        if self._due("clock", self.clock_rate):
            self._publish(topics.CLOCK, Clock(time=t))
        cam = self.scenario.camera
        if self._due("camera", self.timeline.rate("camera", cam.rate, t)):
            self._camera_frame()
        self._sensors()
        if self._due("status", self.timeline.rate("status", self.status_rate, t)):
            self._publish(f"{self.prefix}/status", self.status(), "status")

    # -- camera -----------------------------------------------------------------------------
    def _camera_frame(self) -> None:
        t, seq = self.t, self.frames
        self._before_frame()
        frame = self.scene.render(self._camera(), light=self._light, t=t, seq=seq)
        applied = self.timeline.phenomena(t)
        image = frame.image
        hidden: Any = None  # the boxes the phenomena hide, when one of them has a mask
        for k, (name, params) in enumerate(applied):
            seed = (self.scenario.seed * 1_000_003 + seq * 31 + k) % (2**31)
            phenomenon = self._get_phenomenon(name)
            mask = phenomenon.occlusion(image.shape, params, seed)
            if mask is not None:
                hidden = mask if hidden is None else 1.0 - (1.0 - hidden) * (1.0 - mask)
            image = phenomenon.apply(image, params, seed)
        if hidden is not None:
            from anunnaki.lec import box_occlusion
            from anunnaki.phenomena import HIDDEN

            hidden = box_occlusion(frame.boxes, hidden) >= HIDDEN
        self.frames += 1
        self.last_frame, self.last_image, self.last_phenomena = frame, image, applied
        cam = self.scenario.camera
        self._publish(
            topics.PHENOMENA,
            {
                "t": t,
                "seq": seq,
                "phenomena": [{"name": n, "params": dict(p)} for n, p in applied],
                "faults": self.timeline.faults(t),
            },
        )
        if not self.timeline.silent("camera", t):
            message = Image.from_array(
                image,
                encoding=cam.encoding,
                quality=cam.quality,
                frame_id=f"{self.platform}_camera",
                seq=seq,
            )
            if self.publish_clean:
                # no phenomenon: the clean render is the frame, and its message the same
                # (frozen) one, encoded once
                clean = message
                if image is not frame.image:
                    clean = Image.from_array(
                        frame.image,
                        encoding=cam.encoding,
                        quality=cam.quality,
                        frame_id=f"{self.platform}_camera",
                        seq=seq,
                    )
                self._publish(topics.CLEAN_FRAMES, clean)
            self._publish(f"{self.prefix}/camera/image", message)
            self._publish(
                f"{self.prefix}/camera/info",
                {"seq": seq, "width": cam.width, "height": cam.height, "t": t},
            )
            if self.publish_ground_truth:
                self._publish(
                    topics.GROUND_TRUTH,
                    {
                        "seq": seq,
                        "t": t,
                        "width": cam.width,
                        "height": cam.height,
                        "boxes": [[float(v) for v in b] for b in frame.boxes],
                        "labels": [self.scene.classes[int(i)] for i in frame.labels],
                        "ignore": [[float(v) for v in b] for b in frame.ignore],
                    }
                    # which boxes a phenomenon hides (at least half): the visible-box F1
                    | ({} if hidden is None else {"hidden": [bool(h) for h in hidden]}),
                )
        if self.frame_hook is not None:
            self.frame_hook(self, frame, image)

    # -- hooks for subclasses -------------------------------------------------------------
    def _tick(self, h: float) -> None:
        """One physics step of ``h`` seconds (subclasses)."""
        raise NotImplementedError

    def _camera(self) -> Camera:
        """The camera pose now (subclasses)."""
        raise NotImplementedError

    def _sensors(self) -> None:
        """Publish the platform's sensors that are due (subclasses)."""

    def _before_frame(self) -> None:
        """Called before each camera frame is rendered (animate the scene)."""

    def status(self) -> dict[str, Any]:
        """The status message (subclasses)."""
        raise NotImplementedError

    def flight(self) -> dict[str, Any] | None:
        """A flying platform's flight so far (the UAV's); ``None`` for one that does not fly.

        The keys :attr:`RunReport.flight <anunnaki.sim.RunReport>` describes: the touch-down
        (``landed``) ends a run's phases (:func:`anunnaki.managed.phase_spans`).
        """
        return None

    def touched_down(self) -> bool:
        """Whether a flying platform is on the ground after a flight (never, for a rover)."""
        return False

    # -- commands -------------------------------------------------------------------------
    def _notify(self) -> None:
        """Wake :meth:`wait_for` callers (a command or a detection arrived)."""
        with self._changed:
            self._changed.notify_all()

    def wait_for(self, predicate: Callable[[], bool], timeout: float = 5.0) -> bool:
        """Wait until ``predicate()`` holds after a command arrives (or ``timeout`` s).

        Commands arrive on bus threads; tests use this instead of sleeping.
        """
        with self._changed:
            return self._changed.wait_for(predicate, timeout)

    # -- detections -----------------------------------------------------------------------
    @staticmethod
    def detections_of(message: Any) -> Detections | None:
        """A :class:`Detections` from a bus message (or its JSON body), else ``None``."""
        if isinstance(message, Detections):
            return message
        body = body_of(message)
        try:
            return Detections.model_validate(body)
        except Exception:
            return None

    # -- lifecycle ------------------------------------------------------------------------
    def close(self) -> None:
        """Withdraw services and subscriptions and close the scene (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for d in self._declared:
            try:
                d.close()
            except Exception:  # pragma: no cover - a closed bus already closed them
                log.debug("sim: closing %r failed", d, exc_info=True)
        self._declared.clear()
        self.scene.close()
