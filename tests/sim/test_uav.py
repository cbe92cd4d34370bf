"""The simulated UAV: the delivery mission, the battery, fail-safe modes, GPS."""

from __future__ import annotations

import math

import pytest

from anunnaki import topics
from anunnaki.sim import UavSim

FAST = {
    "platform": "uav",
    "camera": {"rate": 2, "width": 32, "height": 32},
    "mission": {
        "waypoints": [[10, 0]],
        "delivery": [10, 10],
        "cruise_altitude": 16,
        "speed": 10,
        "climb_rate": 8,
        "deliver_time": 1,
    },
}


def test_the_mission_progresses_and_the_battery_drains(bus) -> None:
    with UavSim(bus, FAST) as uav:
        phases = []
        levels = []
        battery = bus.subscribe("/uav/battery", queue=256)
        for _ in range(24):
            uav.step(1.0)
            phases.append(uav.phase)
        while (sample := battery.try_recv()) is not None:
            levels.append(sample.message["level"])
        expected = [
            "takeoff",
            "waypoint 1",
            "to delivery",
            "descend",
            "deliver",
            "climb",
            "return",
            "landing",
            "landed",
        ]
        seen = list(dict.fromkeys(phases))
        assert [p for p in expected if p in seen] == seen  # in mission order
        assert seen[-1] == "landed" and uav.delivered and uav.altitude == 0.0
        assert len(levels) >= 20 and levels == sorted(levels, reverse=True)
        assert levels[0] > levels[-1]
        landed = uav.battery
        uav.step(2.0)
        assert uav.battery == landed  # no drain on the ground


def test_hover_return_home_and_land(bus) -> None:
    with UavSim(bus, FAST) as uav:
        uav.step(2.2)  # climbed, heading to the first waypoint
        assert uav.phase == "waypoint 1"
        assert bus.request("/uav/set_mode", {"mode": "hover"}, timeout=2.0)["ok"]
        here = (uav.x, uav.y, uav.altitude)
        uav.step(2.0)
        assert (uav.x, uav.y, uav.altitude) == here and uav.status()["mode"] == "hover"
        assert bus.request("/uav/set_mode", {"mode": "auto"}, timeout=2.0)["ok"]
        uav.step(1.0)
        assert (uav.x, uav.y) != here[:2]  # resumes the mission
        assert bus.request("/uav/set_mode", {"mode": "return_home"}, timeout=2.0)["ok"]
        uav.step(8.0)
        assert math.hypot(uav.x, uav.y) < 0.5 and uav.altitude == 0.0
        assert uav.phase == "landed" and not uav.delivered
        assert bus.request("/uav/set_mode", {"mode": "auto"}, timeout=2.0)["ok"]
        uav.step(2.0)
        assert uav.altitude > 5.0  # takes off again
        assert bus.request("/uav/set_mode", {"mode": "land"}, timeout=2.0)["ok"]
        x, y = uav.x, uav.y
        uav.step(4.0)
        assert uav.altitude == 0.0 and (uav.x, uav.y) == (x, y)
        bad = bus.request("/uav/set_mode", {"mode": "loop"}, timeout=2.0)
        assert bad["ok"] is False
        assert bus.request("/uav/stop", {"reason": "test"}, timeout=2.0)["stopped"]
        assert bus.request("/uav/set_mode", {"mode": "auto"}, timeout=2.0)["ok"] is False


def test_battery_drain_fault_and_empty_battery_forces_landing(bus) -> None:
    sc = {**FAST, "faults": [{"at": 2, "fault": "battery_drain", "rate": 40}]}
    with UavSim(bus, sc, mode="hover") as uav:
        uav.set_mode("auto")
        uav.step(2.0)
        before = uav.battery
        uav.step(1.0)
        assert before - uav.battery > 35  # the fault's drain
        uav.step(10.0)
        assert uav.battery == 0.0 and uav.altitude == 0.0
        assert uav.phase == "forced landing"


def test_gps_is_metres_around_the_origin(bus) -> None:
    sc = {**FAST, "mission": {**FAST["mission"], "origin": [45.0, 7.0]}}
    with UavSim(bus, sc) as uav:
        uav.x, uav.y = 1000.0, 2000.0
        lat, lon = uav.gps()
        assert lat == pytest.approx(45.0 + 2000 / 111_320)
        assert lon == pytest.approx(7.0 + 1000 / (111_320 * math.cos(math.radians(45))))
        gps = bus.subscribe("/uav/gps", queue=64)
        uav.step(0.5)
        assert set(gps.recv(timeout=2.0).message.data) == {"lat", "lon", "alt"}
        assert uav.published["/uav/gps"] == 5  # 10 Hz


def test_clean_frames_are_published_when_asked(bus) -> None:
    """``publish_clean``: each camera frame also as rendered before the scenario's phenomena,
    under the same seq, for a scorer that compares the model on both (off by default)."""
    foggy = {**FAST, "phenomena": [{"at": 0, "phenomenon": "fog", "strength": 0.7}]}
    for wanted in (False, True):
        with UavSim(bus, foggy) as uav:
            uav.publish_clean = wanted
            clean = bus.subscribe(topics.CLEAN_FRAMES, queue=64)
            camera = bus.subscribe("/uav/camera/image", queue=64)
            uav.step(3.0)
            frames = {s.message.seq: s.message for s in iter(camera.try_recv, None)}
            renders = {s.message.seq: s.message for s in iter(clean.try_recv, None)}
            clean.close()
            camera.close()
        assert len(frames) >= 5
        if not wanted:
            assert renders == {}
            continue
        assert sorted(renders) == sorted(frames)
        for seq, frame in frames.items():
            before, after = renders[seq].to_array(), frame.to_array()
            assert renders[seq].encoding == frame.encoding and before.shape == after.shape
            assert after.mean() > before.mean() + 20  # the fog lightens the frame, not its render


def test_the_flight_is_logged_take_off_delivery_touch_down_and_track(bus) -> None:
    """What the report keeps of a flight (issue 34, item 7): the touch-down ends its phases."""
    with UavSim(bus, FAST) as uav:
        before = uav.flight()
        assert before["took_off"] is None and before["landed"] is None
        assert uav.summary() == "mission: never took off; package not delivered; battery 100.0 %"
        uav.step(24.0)
        flight = uav.flight()
        summary = uav.summary()
    assert flight["took_off"] == pytest.approx(0.0, abs=0.01) and flight["delivered"]
    assert flight["delivered_at"] is not None and 0 < flight["delivered_at"] < flight["landed"]
    assert flight["landed_xy"] == [0.0, 0.0] and flight["landed_home"] is True
    assert flight["battery_at_landing"] == pytest.approx(flight["battery"])  # none drawn since
    track = flight["track"]
    assert [row["t"] for row in track] == [0.5 * k for k in range(48)]  # 2 Hz over 24 s
    assert set(track[0]) == {"t", "x", "y", "altitude", "battery", "mode"}
    assert max(row["altitude"] for row in track) == 16.0 and track[-1]["altitude"] == 0.0
    assert all(row["mode"] == "auto" for row in track)
    assert summary == (
        f"mission: took off at t = 0.0 s; package delivered at t = {flight['delivered_at']:.1f} s; "
        f"landed at home (0.0, 0.0) at t = {flight['landed']:.1f} s with battery "
        f"{flight['battery_at_landing']:.1f} %"
    )
