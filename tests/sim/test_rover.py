"""The simulated rover: commands, the stop rule (detections and ultrasonic only), collisions."""

from __future__ import annotations

import math

import pytest
from pydantic import JsonValue
from sim_helpers import rover_scenario

from anunnaki import topics
from anunnaki.messages import Detections, Message, ModeRequest, body_of
from anunnaki.sim import CAMERA_FOV, RoverSim, StopRule

NO_ULTRASONIC = [{"at": 0, "fault": "dropout", "sensor": "ultrasonic", "duration": 1e6}]


def pedestrian_box(distance: float, width: int = 64, height: int = 48) -> list[float]:
    """Where a 1.7 m pedestrian `distance` m ahead appears in the rover's camera."""
    f = (height / 2) / math.tan(math.radians(CAMERA_FOV) / 2)
    feet = height / 2 + f * 0.3 / distance
    head = height / 2 - f * 1.4 / distance
    half = f * 0.25 / distance
    return [width / 2 - half, max(head, 0.0), width / 2 + half, min(feet, height)]


def test_stop_rule_geometry() -> None:
    rule = StopRule()
    assert rule.box_ahead(pedestrian_box(2.0), 64, 48)
    assert not rule.box_ahead(pedestrian_box(6.0), 64, 48)  # far
    x1, y1, x2, y2 = pedestrian_box(2.0)
    assert not rule.box_ahead([x1 + 28, y1, x2 + 28, y2], 64, 48)  # off to the side
    assert rule.box_ahead([20, 2, 44, 48], 64, 48)  # tall, feet cut: very close
    det = Detections(
        frame_seq=0,
        model_id="m",
        width=64,
        height=48,
        boxes=[pedestrian_box(2.0)],
        labels=["pedestrian"],
        scores=[0.3],
    )
    assert not rule.detections_ahead(det)  # score too low
    det2 = det.model_copy(update={"scores": [0.9], "labels": ["duck"]})
    assert not rule.detections_ahead(det2)  # not a stopping class


def test_modes_stop_buzzer_and_teleop(bus) -> None:
    with RoverSim(bus, rover_scenario(), mode="autonomous", clear_layout=True) as rover:
        rover.step(1.5)
        assert rover.speed > 0.5  # autonomous: drives the route
        reply = bus.request("/rover/set_mode", ModeRequest(mode="manual"), timeout=2.0)
        assert reply["ok"] is True and rover.mode == "manual"
        rover.step(1.0)
        assert abs(rover.speed) < 0.05  # manual halts
        x0 = rover.position[0]
        bus.publish("/rover/teleop", {"linear": 0.6, "angular": 0.0})
        assert rover.wait_for(lambda: rover.teleop_count >= 1)
        rover.step(0.45)
        assert rover.position[0] > x0 + 0.1  # teleop moves in manual
        rover.step(1.0)
        assert abs(rover.speed) < 0.05  # and only while commands keep coming (0.5 s)
        bus.publish("/rover/buzzer", {"on": True})
        assert rover.wait_for(lambda: rover.buzzer)
        rover.step(0.2)
        status = rover.status()
        assert status["buzzer"] is True and status["mode"] == "manual"
        assert set(status) >= {"mode", "buzzer", "bumper", "lights", "speed", "collisions"}
        bad = bus.request("/rover/set_mode", {"mode": "warp"}, timeout=2.0)
        assert bad["ok"] is False and "modes" in bad["error"]
        bus.request("/rover/set_mode", {"mode": "autonomous"}, timeout=2.0)
        bus.publish("/rover/teleop", {"linear": -0.6, "angular": 0.0})
        assert rover.wait_for(lambda: rover.teleop_received >= 2)
        assert rover.teleop_count == 1  # ignored outside manual mode
        stop = bus.request("/rover/stop", {"reason": "test"}, timeout=2.0)
        assert stop["stopped"] is True
        rover.step(1.0)
        assert rover.mode == "stopped" and abs(rover.speed) < 0.05
        again = bus.request("/rover/set_mode", {"mode": "autonomous"}, timeout=2.0)
        assert again["ok"] is False  # run-stop is latched
        assert rover.status()["stopped"] is True


def test_lights_command(bus) -> None:
    """``/rover/lights {on}`` switches the lights, shown in ``/rover/status``; nothing else."""
    with RoverSim(bus, rover_scenario(), mode="manual", clear_layout=True) as rover:
        status = bus.subscribe("/rover/status", queue=256)
        seen = 0

        def statuses(step: float) -> list[dict]:
            """Step the rover; return the status messages it published meanwhile."""
            nonlocal seen
            rover.step(step)
            out = []
            while seen < rover.published["/rover/status"]:
                out.append(status.recv(timeout=5.0).message)
                seen += 1
            assert out, "no status published"
            return out

        assert {m["lights"] for m in statuses(0.3)} == {False} and not rover.lights
        bus.publish("/rover/lights", {"on": True})
        assert rover.wait_for(lambda: rover.lights)
        assert rover.commands[-1][1:] == ("lights", {"on": True})
        got = statuses(0.3)
        assert {m["lights"] for m in got} == {True}
        # The lights alone: no buzzer, no warning, the mode and the (halted) rover unchanged.
        assert not any(m["buzzer"] or m["warning"] for m in got)
        assert {m["mode"] for m in got} == {"manual"} and abs(rover.speed) < 0.05
        bus.publish("/rover/lights", {"on": False})
        assert rover.wait_for(lambda: not rover.lights)
        assert {m["lights"] for m in statuses(0.3)} == {False}
        bus.publish("/rover/lights", {"on": True})
        assert rover.wait_for(lambda: rover.lights)
        bus.publish("/rover/lights", {})  # no "on": off
        assert rover.wait_for(lambda: not rover.lights)
        assert {m["lights"] for m in statuses(0.2)} == {False}
        assert [c[2] for c in rover.commands if c[1] == "lights"] == [
            {"on": True}, {"on": False}, {"on": True}, {}]  # fmt: skip
        # Not a boolean: counted and ignored ("false" is truthy; it must not switch them on).
        bus.publish("/rover/lights", {"on": "false"})
        bus.publish("/rover/buzzer", {"on": 1})
        assert rover.wait_for(lambda: rover.malformed == 2)
        assert not rover.lights and not rover.buzzer_cmd
        assert len([c for c in rover.commands if c[1] in ("lights", "buzzer")]) == 4


def test_stops_and_warns_for_a_close_pedestrian_detection(bus) -> None:
    sc = rover_scenario(faults=NO_ULTRASONIC)
    with RoverSim(bus, sc, clear_layout=True) as rover:
        rover.step(1.0)
        assert rover.speed > 0.5 and not rover.buzzer
        det = Detections(
            frame_seq=rover.frames - 1,
            model_id="detector",
            width=64,
            height=48,
            boxes=[pedestrian_box(2.0)],
            labels=["pedestrian"],
            scores=[0.9],
        )
        bus.publish("/lec/detector/detections", det)
        assert rover.wait_for(lambda: rover.detections_received >= 1)
        rover.step(0.3)
        assert rover.obstacle == "detector"
        assert rover.buzzer and rover.lights and rover.status()["warning"] is True
        rover.step(0.4)
        assert abs(rover.speed) < 0.05
        rover.step(1.5)  # no fresh evidence: drives on after clear_time
        assert rover.speed > 0.3 and not rover.buzzer
        far = det.model_copy(update={"boxes": [pedestrian_box(8.0)]})
        bus.publish("/lec/detector/detections", far)
        assert rover.wait_for(lambda: rover.detections_received >= 2)
        rover.step(0.5)
        assert rover.speed > 0.5 and rover.obstacle is None  # far away: no reason to stop
        bus.publish("/lec/detector/detections", {"boxes": "nonsense"})
        assert rover.wait_for(lambda: rover.malformed == 1)  # logged, counted, ignored
        rover.step(0.2)
        assert rover.speed > 0.5


def test_stops_when_the_ultrasonic_range_is_short(bus) -> None:
    sc = rover_scenario(objects=[{"kind": "cube", "x": 4.0, "y": 0.0, "size": 0.5}])
    with RoverSim(bus, sc, clear_layout=True) as rover:
        ranges = bus.subscribe("/rover/ultrasonic", queue=256)
        rover.step(6.0)
        assert rover.obstacle == "ultrasonic" and rover.buzzer
        assert abs(rover.speed) < 0.05 and rover.collisions == 0 and not rover.bumper
        readings = []
        while (sample := ranges.try_recv()) is not None:
            readings.append(sample.message["range"])
        # the cube's face is 4 - 0.25 m from the origin, the sensor 0.55 m ahead of it
        assert readings[0] == pytest.approx(3.2, abs=0.05) and min(readings) < 1.0


def test_ground_truth_alone_never_stops_it(bus) -> None:
    # A pedestrian stands on the route 9 m ahead: the ground truth shows it in every frame,
    # but with no detections and nothing within ultrasonic range the rover drives on.
    sc = rover_scenario(
        objects=[{"kind": "pedestrian", "x": 9.0, "y": 0.0}],
        camera={"rate": 10, "width": 128, "height": 96},
    )
    with RoverSim(bus, sc, clear_layout=True) as rover:
        truth = bus.subscribe(topics.GROUND_TRUTH, queue=256)
        rover.step(4.0)
        labels = []
        while (sample := truth.try_recv()) is not None:
            labels.extend(sample.message["labels"])
        assert labels.count("pedestrian") >= 30
        assert rover.speed > 0.7 and not rover.buzzer and rover.obstacle is None


def test_collisions_are_counted(bus) -> None:
    sc = rover_scenario(objects=[{"kind": "pedestrian", "x": 3.0, "y": 0.0}], faults=NO_ULTRASONIC)
    with RoverSim(bus, sc, clear_layout=True) as rover:
        bumped = False
        for _ in range(40):
            rover.step(0.1)
            bumped = bumped or rover.bumper
        assert rover.collisions == 1 and bumped
        assert rover.status()["collisions"] == 1


def test_stepping_is_deterministic(bus) -> None:
    def run() -> tuple[float, float, int, list[int]]:
        with RoverSim(bus, rover_scenario(layout=2)) as rover:
            sizes: list[int] = []
            rover.frame_hook = lambda sim, frame, image: sizes.append(int(image.sum()))
            rover.step(1.3)
            x, y = rover.position
            return round(x, 6), round(y, 6), rover.frames, sizes

    assert run() == run()


def test_publishes_what_the_binding_names(bus) -> None:
    with RoverSim(bus, rover_scenario(), clear_layout=True) as rover:
        image = bus.subscribe("/rover/camera/image", queue=64)
        rover.step(1.0)
        counts = rover.published
        assert counts["/rover/camera/image"] == 10 and counts["/rover/camera/info"] == 10
        assert counts["/rover/ultrasonic"] == 10 and counts["/rover/status"] == 10
        assert counts["/clock"] == 40
        msg = image.recv(timeout=2.0).message
        assert msg.encoding == "jpeg" and (msg.width, msg.height) == (64, 48)


class _ModeWithData(Message):
    """A message type with a mapping field called ``data`` beside the fields a handler reads."""

    mode: str
    data: dict[str, JsonValue]


def test_a_typed_message_with_a_data_field_is_read_whole(bus) -> None:
    # The platforms had a body_of of their own that read such a message as its ``data`` alone
    # (here {"note": …}: no mode, refused); they read it as every other part does now.
    message = _ModeWithData(mode="manual", data={"note": "from a plugin's message type"})
    assert body_of(message) == {"mode": "manual", "data": {"note": "from a plugin's message type"}}
    with RoverSim(bus, rover_scenario(), mode="autonomous", clear_layout=True) as rover:
        assert rover._srv_set_mode(message) == {"ok": True, "mode": "manual"}
        assert rover.mode == "manual"
