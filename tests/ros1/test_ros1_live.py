"""The bridge against a real ROS 1 master: values reach the goal model, tactics act on ROS.

Each test starts ``rosmaster --core`` on a free loopback port, the example rover as a plain
rospy node and the bridge process (ros1_support.py); this process joins the bridge's zenoh
bus. Everything waits on events (output lines, messages, goal states) with a deadline that
only guards against a hung test.
"""

from __future__ import annotations

import hashlib
import json
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from ros1_support import DEADLINE, ROVER, Proc, RosSetup, need_ros

from anunnaki.bus import Bus, open_bus
from anunnaki.goals import load_binding, parse_goal_model
from anunnaki.lec import LecNode, ModelRegistry
from anunnaki.lec._detector import DetectionResult
from anunnaki.messages import Detections
from anunnaki.tactics import load_tactics
from anunnaki.utu import AutonomicManager

pytestmark = pytest.mark.slow  # about 7 s each: a master, the rover and the bridge start


@contextmanager
def joined(endpoint: str) -> Iterator[Bus]:
    """This process's bus, connected to the bridge's."""
    with open_bus("zenoh", mode="peer", connect=[endpoint], listen=[]) as bus:
        yield bus


def rover_utu(bus: Bus) -> AutonomicManager:
    """Utu with the rover's goal model, the ROS binding and the unchanged rover tactics."""
    binding = load_binding(ROVER / "binding-ros.yaml")
    model = parse_goal_model((ROVER / "goals.yaml").read_text(), binding=binding)
    tactics = load_tactics(ROVER / "tactics.xml")
    return AutonomicManager(model, tactics, bus=bus, warmup=0.5, failsafe="fail-safe")


def step_until(
    m: AutonomicManager,
    done: Callable[[], bool],
    what: str,
    each: Callable[[], None] = lambda: None,
) -> None:
    """Step Utu on wall time until ``done()`` (a deadline guards against a hung test)."""
    end = time.monotonic() + DEADLINE
    wake = threading.Event()
    while not done():
        assert time.monotonic() < end, f"never: {what}"
        each()
        m.step()
        wake.wait(0.05)  # the pace of a live loop (spin's rate), not a synchronisation


@pytest.fixture(scope="module")
def shared(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[RosSetup, Proc, str]]:
    """One master, rover (something near from the start) and bridge for the tests below."""
    need_ros()
    setup = RosSetup(tmp_path_factory.mktemp("ros_home"))
    try:
        rover = setup.rover("--near-from", "0")
        _, endpoint = setup.bridge()
        yield setup, rover, endpoint
    finally:
        setup.close()


def test_ros_values_reach_the_goal_model_and_tactics_act_on_the_robot(
    shared: tuple[RosSetup, Proc, str],
) -> None:
    _, rover, endpoint = shared
    with joined(endpoint) as bus:
        m = rover_utu(bus)
        ev = m.analyzer.evaluator
        try:
            # ROS → bridge → bus → goal model: the controller state (four ROS topics merged
            # into /rover/controller/state) and the ultrasonic range
            step_until(
                m,
                lambda: ev.value("A1.mode") == "autonomous" and ev.value("A3.range") == 0.5,
                "the rover's mode and range in the goal model",
            )
            # G12 (warn pedestrians) fails → warn-pedestrians publishes on the logical
            # 'buzzer' → /rover/controller/buzzer → a std_msgs/Bool on ROS. Utu keeps
            # stepping meanwhile: the tactic may start a step or more after the values
            # arrived (a loaded machine's run waited 60 s on a loop nobody stepped)
            step_until(m, lambda: rover.printed("buzzer True"), "the buzzer on ROS")
            step_until(m, lambda: ev.value("A1.buzzer") is True, "the buzzer_on state back")
            # the oracle reports category 1 → G3 fails → the fail-safe requests the logical
            # 'set_mode' → /rover/controller/set_mode → an anunnaki_msgs/SetString call
            oracle = {"category": 1, "confidence": 0.9}
            step_until(
                m,
                lambda: any(
                    d.kind == "postcondition_ok" and d.tactic == "fail-safe"
                    for d in m.knowledge.decisions()
                ),
                "the fail-safe verified",
                each=lambda: bus.publish("/utu/oracle/output", oracle),
            )
            assert rover.wait_for("set_mode manual") == "set_mode manual: accepted"
            assert ev.value("A1.mode") == "manual"  # the robot's own state, back through ROS
            sent = [d.data for d in m.knowledge.decisions() if d.kind == "action"]
            called = {"service": "/rover/controller/set_mode", "mode": "manual", "ok": True}
            assert any(called.items() <= d.items() for d in sent)  # the log names ROS's service
        finally:
            m.close()


class SeenDetector:
    """A detector double that keeps the frames it is given (what the LEC decoded)."""

    classes = ("person", "car")
    model_id = "seen"
    domain = "default"

    def __init__(self) -> None:
        self.shapes: list[tuple[int, ...]] = []
        self.pixels: list[tuple[int, int, int]] = []

    def detect(self, images: Any) -> list[DetectionResult]:
        for image in images:
            self.shapes.append(tuple(image.shape))
            self.pixels.append(tuple(int(v) for v in image[120, 5]))
        return [DetectionResult([[1, 2, 11, 12]], [1], [0.9]) for _ in images]


def test_an_image_from_ros_reaches_the_lec_node(
    shared: tuple[RosSetup, Proc, str], tmp_path: Path
) -> None:
    _, _, endpoint = shared
    detector = SeenDetector()
    path = tmp_path / "seen.model"
    path.write_text(json.dumps({"model_id": "seen"}))
    entry = {"id": "seen", "domain": "default", "file": path}
    registry = ModelRegistry(
        [{**entry, "sha256": hashlib.sha256(path.read_bytes()).hexdigest()}],
        loader=lambda _p: detector,
    )
    got: list[Detections] = []
    arrived = threading.Event()

    def on_detections(sample: Any) -> None:
        got.append(sample.message)
        if len(got) >= 3:
            arrived.set()

    with joined(endpoint) as bus:
        bus.subscribe("/lec/detector/detections", on_detections)
        with LecNode(bus, registry, camera="/rover/camera/image", active_period=None):
            assert arrived.wait(DEADLINE), "no detections from the ROS camera's frames"
    first = got[0]
    assert (first.width, first.height, first.model_id) == (320, 240, "seen")
    assert [d.frame_seq for d in got] == sorted(d.frame_seq for d in got)  # the ROS header.seq
    assert detector.shapes[0] == (240, 320, 3)
    assert detector.pixels[0] == (100, 100, 200)  # the rover's background colour, as RGB


def test_the_bridge_survives_a_dying_node_and_a_master_restart(ros: RosSetup) -> None:
    rover = ros.rover("--no-camera")
    bridge, endpoint = ros.bridge()
    with joined(endpoint) as bus:
        m = rover_utu(bus)
        ev = m.analyzer.evaluator
        try:
            step_until(m, lambda: ev.value("A3.range") == 3.0, "the range in the goal model")
            rover.stop()  # the node dies: A3 goes stale after its binding's 1 s, G13 unknown
            step_until(m, lambda: ev.state("G13").status is None, "G13 unknown")
            ros.stop_master()
            ros.start_master()  # a new master knows nobody; the bridge registers again
            bridge_topics = lambda: {  # noqa: E731
                t for t, nodes in ros.system_state()[1] if "/anunnaki_bridge" in nodes
            }
            step_until(
                m,
                lambda: "/ultrasonic/range" in bridge_topics(),
                "the bridge's subscriptions registered with the new master",
            )
            ros.rover("--no-camera")  # the robot comes back (as roslaunch's respawn does)
            step_until(m, lambda: ev.state("G13").status is True, "G13 known and satisfied again")
            reply = bus.request("/rover/controller/set_mode", {"mode": "manual"}, timeout=10.0)
            assert reply.to_body()["ok"] is True
            step_until(m, lambda: ev.value("A1.mode") == "manual", "the new mode back through ROS")
            assert bridge.p.poll() is None  # the same bridge process all along
        finally:
            m.close()
