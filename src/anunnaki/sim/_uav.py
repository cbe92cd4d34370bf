"""The simulated UAV: a free-flying camera on a package-delivery mission.

pybullet ships no quadrotor, and the mission needs none: the UAV is a kinematic point
(position, heading) that flies legs at a set horizontal speed and climb rate, with a
downward-looking camera rendering the scene of pedestrians, vehicles, roads, buildings and
trees below (the same camera as the UAV's datasets: 32° field of view).

The mission (mode ``auto``): climb at home to cruise altitude → each waypoint → the delivery
point → descend to 10 m, drop the package (``delivered``) → climb → home → land. Fail-safe
modes (``/uav/set_mode``): ``hover`` holds position, ``return_home`` flies home at cruise
altitude and lands, ``land`` descends where it is; ``auto`` resumes the mission. Run-stop
(``/uav/stop``) lands in place and refuses further modes. An empty battery forces a landing.

The battery drains, per second airborne, ``drain_hover + drain_per_speed × speed`` percent,
plus any ``battery_drain`` fault of the scenario (obstacle O2); nothing on the ground (a
landed UAV draws no power, whatever the fault).
``/uav/link`` says whether the ground station answers: ``connected`` is false during a
scenario's ``link`` dropout.

What is left to fly is on ``/uav/status`` for anticipatory goals (docs/goal-models.md,
"Forecasts"): ``route_m``, the rest of the mission (the legs left, the drop and the way home
down to the ground), and ``home_m``, the way straight home as ``return_home`` flies it, with
``cruise_speed``. Both are in *metres at cruise speed*: a horizontal metre counts once, a
vertical one ``speed / climb_rate`` times (the time it takes), the drop's hold ``speed ×
deliver_time``, so ``route_m / cruise_speed`` is the flight time left.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

from anunnaki import topics
from anunnaki.messages import body_of
from anunnaki.sim._layout import layout_placements
from anunnaki.sim._platform import SimPlatform, as_scenario
from anunnaki.sim._rover import _placement
from anunnaki.sim._scenario import Scenario
from anunnaki.sim._scene import Scene
from anunnaki.sim._world import Camera

__all__ = ["CAMERA_DOWN", "TRACK_RATE", "UAV_CAMERA_FOV", "UavMode", "UavSim"]

log = logging.getLogger("anunnaki.sim")

UavMode = Literal["auto", "hover", "return_home", "land", "stopped"]
UAV_CAMERA_FOV = 32.0
"""Vertical field of view of the UAV's camera (degrees), as in the UAV's datasets."""
CAMERA_DOWN = 50.0
"""How far below the horizon the UAV's camera looks (degrees)."""
DELIVER_ALTITUDE = 10.0
TRACK_RATE = 2.0
"""How often (Hz of simulated time) the flight's track is sampled (:meth:`UavSim.flight`)."""
_METRES_PER_DEGREE = 111_320.0


def _ms(t: float | None) -> float | None:
    """A time to the millisecond (``None`` stays)."""
    return None if t is None else round(t, 3)


class UavSim(SimPlatform):
    """The simulated UAV on the bus.

    Publishes ``/uav/status`` {mode, altitude, delivered, phase, speed, battery, x, y,
    route_m, home_m, cruise_speed, t},
    ``/uav/gps`` {lat, lon, alt}, ``/uav/battery`` {level}, ``/uav/link`` {connected},
    ``/uav/camera/image``, ``/uav/camera/info``, ``/sim/ground_truth``, ``/sim/phenomena``
    and ``/clock``. Offers ``/uav/set_mode`` {mode: auto|hover|return_home|land} and
    ``/uav/stop`` {reason}; listens to ``/utu/run_stop``.

    Args:
        bus: The bus.
        scenario: A scenario (file, mapping or :class:`Scenario`); ``None`` for defaults.
        mode: The initial mode.
        physics_hz: Integration rate.
        clock_rate: ``/clock`` rate (Hz of simulated time).
        status_rate: ``/uav/status`` rate.
        link_rate: ``/uav/link`` rate.
        publish_ground_truth: Publish ``/sim/ground_truth`` (scoring only).
        frame_hook: ``hook(sim, frame, image)`` after each camera frame.

    """

    prefix = "/uav"
    platform = "uav"
    modes: tuple[str, ...] = ("auto", "hover", "return_home", "land")

    def __init__(
        self,
        bus: Any,
        scenario: Scenario | str | Path | Mapping[str, Any] | None = None,
        *,
        mode: UavMode = "auto",
        physics_hz: float = 240.0,
        clock_rate: float = 40.0,
        status_rate: float = 10.0,
        link_rate: float = 1.0,
        publish_ground_truth: bool = True,
        frame_hook: Any = None,
    ) -> None:
        sc = as_scenario(scenario, "uav")
        scene = Scene(
            "uav",
            sc.layout,
            width=sc.camera.width,
            height=sc.camera.height,
            placements=layout_placements("uav", sc.layout),
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
            m = sc.mission
            self.link_rate = link_rate
            self.x, self.y = m.home
            self.z = float(m.start_altitude)  # > 0: the run starts in the air, mid-mission
            self.yaw = 0.0
            self.speed = 0.0
            self.battery = float(m.battery)
            self.delivered = False
            self.delivered_at: float | None = None  # when the package was dropped
            self.airborne_at: float | None = None  # first take-off (simulated s)
            self.landed_at: float | None = None  # last touch-down after a flight
            self.landed_battery: float | None = None  # battery (%) at that touch-down
            self.forced = False  # the empty battery forced the UAV down
            self.mode: UavMode = mode
            self.phase = "takeoff"
            self.leg = 0
            self._hold = 0.0
            self.legs = self._plan()
            self.commands: list[tuple[float, str, dict[str, Any]]] = []
            self._track: list[dict[str, Any]] = []  # sampled at TRACK_RATE (flight())
            self._declared = [
                bus.service(f"{self.prefix}/set_mode", self._srv_set_mode),
                bus.service(f"{self.prefix}/stop", self._srv_stop),
                bus.subscribe(topics.RUN_STOP, self._on_run_stop, queue=4),
            ]
        except BaseException:
            scene.close()
            raise

    def _plan(self) -> list[tuple[str, float, float, float]]:
        """The mission's legs: (phase, x, y, altitude)."""
        m = self.scenario.mission
        cruise = m.cruise_altitude
        hx, hy = m.home
        dx, dy = m.delivery
        legs = [("takeoff", hx, hy, cruise)]
        legs += [(f"waypoint {i + 1}", x, y, cruise) for i, (x, y) in enumerate(m.waypoints)]
        legs += [
            ("to delivery", dx, dy, cruise),
            ("descend", dx, dy, min(DELIVER_ALTITUDE, cruise)),
            ("deliver", dx, dy, min(DELIVER_ALTITUDE, cruise)),
            ("climb", dx, dy, cruise),
            ("return", hx, hy, cruise),
            ("landing", hx, hy, 0.0),
        ]
        return legs

    # -- commands -------------------------------------------------------------------------
    def _srv_set_mode(self, message: Any) -> dict[str, Any]:
        body = body_of(message)
        mode = body.get("mode")
        if mode not in self.modes:
            return {"ok": False, "error": f"unknown mode {mode!r}; modes: {list(self.modes)}"}
        with self._lock:
            if self.mode == "stopped":
                return {"ok": False, "error": "the UAV is stopped (run-stop)"}
            self.set_mode(mode)
            self.commands.append((self.t, "set_mode", body))
        self._notify()
        log.info("uav: mode -> %s", mode)
        return {"ok": True, "mode": mode}

    def set_mode(self, mode: UavMode) -> None:
        """Change mode (what the ``set_mode`` service does, without the checks)."""
        with self._lock:
            self.mode = mode

    def _srv_stop(self, message: Any) -> dict[str, Any]:
        self.run_stop(str(body_of(message).get("reason", "")))
        return {"ok": True, "stopped": True}

    def run_stop(self, reason: str = "") -> None:
        """Stop: land in place and refuse further modes."""
        with self._lock:
            self.mode = "stopped"
            self.commands.append((self.t, "stop", {"reason": reason}))
        self._notify()
        log.info("uav: run-stop (%s)", reason)

    def _on_run_stop(self, sample: Any) -> None:
        self.run_stop(str(body_of(sample.message).get("reason", "run_stop")))

    # -- flight ---------------------------------------------------------------------------
    def _fly_to(self, tx: float, ty: float, tz: float, h: float) -> bool:
        """Move towards (tx, ty, tz) for ``h`` seconds; True when there."""
        m = self.scenario.mission
        dx, dy, dz = tx - self.x, ty - self.y, tz - self.z
        horizontal = math.hypot(dx, dy)
        # climb first when low, so take-off and landing are vertical
        step_h = (
            0.0
            if (self.z < min(tz, m.cruise_altitude) - 2.0 and tz > self.z)
            else min(horizontal, m.speed * h)
        )
        if horizontal > 1e-6 and step_h > 0:
            self.yaw = math.atan2(dy, dx)
            self.x += dx / horizontal * step_h
            self.y += dy / horizontal * step_h
        step_v = max(-m.climb_rate * h, min(m.climb_rate * h, dz))
        self.z = max(0.0, self.z + step_v)
        self.speed = math.hypot(step_h, step_v) / h if h > 0 else 0.0
        if math.hypot(tx - self.x, ty - self.y) < 0.3 and abs(tz - self.z) < 0.2:
            self.x, self.y, self.z = tx, ty, tz
            return True
        return False

    def _tick(self, h: float) -> None:
        m = self.scenario.mission
        with self._lock:
            mode = self.mode
        if self.battery <= 0.0 and self.z > 0.0 and mode not in ("land", "stopped"):
            mode = "land"
            self.phase = "forced landing"
            self.forced = True
        if mode == "auto":
            self._follow_mission(h)
        elif mode == "hover":
            self.phase = "hover"
            self.speed = 0.0
        elif mode == "return_home":
            self._return_home(h)
        else:  # land, stopped, forced landing
            if self.phase != "forced landing":
                self.phase = "landing" if self.z > 0 else "landed"
            self._fly_to(self.x, self.y, 0.0, h)
        if self.z <= 0.0:
            self.speed = 0.0
        airborne = self.z > 0.05
        if airborne:
            self.landed_at = None
            if self.airborne_at is None:
                self.airborne_at = self.t
            drain = self.timeline.extra_drain(self.t) + m.drain_hover
            self.battery = max(0.0, self.battery - (drain + m.drain_per_speed * self.speed) * h)
        elif self.airborne_at is not None and self.landed_at is None:
            self.landed_at, self.landed_battery = self.t, self.battery

    def _follow_mission(self, h: float) -> None:
        """Fly the mission's current leg (hold over the drop point to deliver), then land."""
        if self.leg >= len(self.legs):
            self.phase = "landed"
            self.speed = 0.0
            return
        phase, tx, ty, tz = self.legs[self.leg]
        self.phase = phase
        if phase == "deliver":
            self.speed = 0.0
            self._hold += h
            if self._hold >= self.scenario.mission.deliver_time:
                self.delivered, self.delivered_at = True, self.t
                self.leg += 1
        elif self._fly_to(tx, ty, tz, h):
            self.leg += 1

    def _return_home(self, h: float) -> None:
        """Fly home at cruise altitude (or higher), then land there."""
        m = self.scenario.mission
        hx, hy = m.home
        if math.hypot(hx - self.x, hy - self.y) > 0.3:
            # climbing vertically to cruise altitude first (from a low hover, the drop point)
            self.phase = "climb" if self.z < m.cruise_altitude - 2.0 else "return"
            self._fly_to(hx, hy, max(self.z, m.cruise_altitude), h)
        else:
            self.phase = "landing" if self.z > 0 else "landed"
            self._fly_to(hx, hy, 0.0, h)

    # -- what is left to fly ----------------------------------------------------------------
    def _path_m(self, legs: list[tuple[str, float, float, float]]) -> float:
        """Metres at cruise speed from here through ``legs`` (see the module docstring)."""
        m = self.scenario.mission
        vertical = m.speed / m.climb_rate
        x, y, z, total = self.x, self.y, self.z, 0.0
        for phase, tx, ty, tz in legs:
            if phase == "deliver":
                total += max(0.0, m.deliver_time - self._hold) * m.speed
                continue
            total += math.hypot(tx - x, ty - y) + abs(tz - z) * vertical
            x, y, z = tx, ty, tz
        return total

    def route_m(self) -> float:
        """The rest of the mission, down to the ground at home (metres at cruise speed)."""
        return self._path_m(self.legs[self.leg :])

    def home_m(self) -> float:
        """Straight home and down, as ``return_home`` flies it (metres at cruise speed)."""
        m = self.scenario.mission
        hx, hy = m.home
        if math.hypot(hx - self.x, hy - self.y) <= 0.3:
            return self._path_m([("landing", hx, hy, 0.0)])
        top = max(self.z, m.cruise_altitude)
        return self._path_m(
            [("climb", self.x, self.y, top), ("return", hx, hy, top), ("landing", hx, hy, 0.0)]
        )

    # -- sensors --------------------------------------------------------------------------
    def gps(self) -> tuple[float, float]:
        """(latitude, longitude) in degrees of the local position around the origin."""
        lat0, lon0 = self.scenario.mission.origin
        lat = lat0 + self.y / _METRES_PER_DEGREE
        lon = lon0 + self.x / (_METRES_PER_DEGREE * math.cos(math.radians(lat0)))
        return lat, lon

    def _sensors(self) -> None:
        t, m = self.t, self.scenario.mission
        if self._due("track", TRACK_RATE):  # the flight's log, not a sensor: no dropout
            self._track.append(
                {
                    "t": round(t, 3),
                    "x": round(self.x, 2),
                    "y": round(self.y, 2),
                    "altitude": round(self.z, 2),
                    "battery": round(self.battery, 2),
                    "mode": self.mode,
                }
            )
        if self._due("gps", self.timeline.rate("gps", m.gps_rate, t)):
            lat, lon = self.gps()
            self._publish(
                f"{self.prefix}/gps",
                {"lat": round(lat, 8), "lon": round(lon, 8), "alt": round(self.z, 3)},
                "gps",
            )
        if self._due("battery", self.timeline.rate("battery", m.battery_rate, t)):
            self._publish(f"{self.prefix}/battery", {"level": round(self.battery, 3)}, "battery")
        if self._due("link", self.timeline.rate("link", self.link_rate, t)):
            # the UAV's own view of the link: in a scenario's link dropout the ground station
            # stops answering, and the UAV says so (it does not fall silent itself)
            connected = not self.timeline.silent("link", t)
            self._publish(f"{self.prefix}/link", {"connected": connected})

    def _camera(self) -> Camera:
        z = max(self.z, 0.5)
        reach = z / math.tan(math.radians(CAMERA_DOWN))
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        eye = (self.x, self.y, z)
        target = (self.x + reach * c, self.y + reach * s, 0.0)
        return Camera(eye, target, fov=UAV_CAMERA_FOV, near=0.3, far=250.0)

    def flight(self) -> dict[str, Any]:
        """The flight so far: take-off, delivery, touch-down and the track at 2 Hz.

        Returns:
            ``took_off`` (first take-off, s, or ``None``), ``delivered`` (bool),
            ``delivered_at`` (s or ``None``), ``landed`` (the last touch-down after a
            flight, s; ``None`` while airborne or before take-off), ``landed_xy`` ([x, y]
            in metres, or ``None``), ``landed_home`` (within 1 m of home, or ``None``),
            ``landing`` (where the flight ended: ``home``; ``forced``, the empty battery
            forced it down wherever that was; ``elsewhere``; ``airborne`` still; or
            ``ground``, it never took off), ``battery_at_landing`` (%, or ``None``),
            ``battery`` (% now) and ``track``: ``{t, x, y, altitude, battery, mode}`` every
            0.5 s of simulated time.

        """
        with self._lock:
            hx, hy = self.scenario.mission.home
            landed = self.landed_at
            home = landed is not None and math.hypot(self.x - hx, self.y - hy) < 1.0
            if self.airborne_at is None:
                landing = "ground"
            elif landed is None:
                landing = "airborne"
            else:
                landing = "forced" if self.forced else "home" if home else "elsewhere"
            return {
                "landing": landing,
                "took_off": _ms(self.airborne_at),
                "delivered": self.delivered,
                "delivered_at": _ms(self.delivered_at),
                "landed": _ms(landed),
                "landed_xy": None if landed is None else [round(self.x, 2), round(self.y, 2)],
                "landed_home": None if landed is None else home,
                "battery_at_landing": None
                if self.landed_battery is None
                else round(self.landed_battery, 2),
                "battery": round(self.battery, 2),
                "track": [dict(row) for row in self._track],
            }

    def touched_down(self) -> bool:
        """Whether the UAV is on the ground after a flight (the mission can change no more)."""
        return self.landed_at is not None

    def summary(self) -> str:
        """The flight in one line: take-off, delivery, where and when it landed, battery."""
        f = self.flight()
        with self._lock:
            z, phase = self.z, self.phase
        hx, hy = self.scenario.mission.home
        took_off, delivered_at, landed = f["took_off"], f["delivered_at"], f["landed"]
        parts = [
            "never took off" if took_off is None else f"took off at t = {took_off:.1f} s",
            "package not delivered"
            if delivered_at is None
            else f"package delivered at t = {delivered_at:.1f} s",
        ]
        if landed is not None:
            x, y = f["landed_xy"]
            place = (
                "at home" if f["landed_home"] else f"{math.hypot(x - hx, y - hy):.0f} m from home"
            )
            how = "forced down (battery empty)" if f["landing"] == "forced" else "landed"
            parts.append(
                f"{how} {place} ({x:.1f}, {y:.1f}) at t = {landed:.1f} s with battery "
                f"{f['battery_at_landing']:.1f} %"
            )
        elif took_off is not None:
            parts.append(f"still airborne at {z:.1f} m ({phase}) with battery {f['battery']:.1f} %")
        else:
            parts.append(f"battery {f['battery']:.1f} %")
        return "mission: " + "; ".join(parts)

    @property
    def altitude(self) -> float:
        """Altitude above ground (m)."""
        return self.z

    def status(self) -> dict[str, Any]:
        """The ``/uav/status`` message."""
        with self._lock:
            return {
                "mode": self.mode,
                "altitude": round(self.z, 3),
                "delivered": self.delivered,
                "phase": self.phase,
                "speed": round(self.speed, 3),
                "battery": round(self.battery, 3),
                "x": round(self.x, 3),
                "y": round(self.y, 3),
                "route_m": round(self.route_m(), 2),
                "home_m": round(self.home_m(), 2),
                "cruise_speed": float(self.scenario.mission.speed),
                "t": round(self.t, 6),
            }
