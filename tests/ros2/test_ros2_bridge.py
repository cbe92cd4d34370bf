"""ROS 2 over zenoh: CDR samples published on zenoh as ROS 2 would, read through a bridge file.

No ROS 2 runs here: the "ROS 2 side" is a plain zenoh session putting CDR bytes on the key
expressions zenoh-bridge-ros2dds and rmw_zenoh use (docs/ros.md says what was and was not
tested against a live ROS 2).
"""

from __future__ import annotations

import json
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from anunnaki.bus import Bus, BusConfig, open_bus
from anunnaki.errors import AnunnakiError
from anunnaki.ros2 import Ros2ZenohBridge, decode_cdr, encode_cdr, ros2_key
from anunnaki.rosbridge import load_bridge, parse_bridge

pytest.importorskip("rosbags")
zenoh = pytest.importorskip("zenoh")

ROVER = Path(__file__).parents[2] / "examples" / "rover"
DEADLINE = 30.0
# std_msgs/msg/Bool's RIHS01 type hash, as ROS 2 Jazzy's share/std_msgs/msg/Bool.json says
BOOL_HASH = "RIHS01_feb91e995ff9ebd09c0cb3d2aed18b11077585839fb5db80193b62d74528f6c9"


@pytest.fixture(autouse=True)
def jazzy(monkeypatch: pytest.MonkeyPatch) -> None:
    """The robot runs Jazzy, as a ROS 2 install's setup.bash says ($ROS_DISTRO)."""
    monkeypatch.setenv("ROS_DISTRO", "jazzy")


def test_key_expressions_of_both_ros2_zenoh_flavours() -> None:
    assert ros2_key("/rover/controller/mode", "std_msgs/String") == "rover/controller/mode"
    assert ros2_key("/a/b", "std_msgs/Bool", namespace="/robot1") == "robot1/a/b"
    assert (
        ros2_key("/ultrasonic/range", "sensor_msgs/Range", flavour="rmw_zenoh", domain=3)
        == "3/ultrasonic/range/sensor_msgs::msg::dds_::Range_/*"
    )


def test_cdr_samples_are_what_ros2_puts_on_the_wire() -> None:
    # encapsulation header (CDR little endian, 00 01 00 00), then the fields, 4-aligned
    assert encode_cdr("std_msgs/String", {"data": "hi"}) == bytes.fromhex("0001000003000000686900")
    assert encode_cdr("std_msgs/Bool", {"data": True}) == bytes.fromhex("0001000001")
    raw = encode_cdr(
        "sensor_msgs/Range", {"header": {"stamp": 12.5, "frame_id": "us"}, "range": 0.5}
    )
    assert decode_cdr("sensor_msgs/Range", raw) == {
        "header": {"stamp": 12.5, "frame_id": "us"},
        "radiation_type": 0,
        "field_of_view": 0.0,
        "min_range": 0.0,
        "max_range": 0.0,
        "range": 0.5,
        "variance": 0.0,
    }
    twist = decode_cdr(
        "geometry_msgs/Twist", encode_cdr("geometry_msgs/Twist", {"angular": {"z": 1.0}})
    )
    assert twist == {
        "linear": {"x": 0.0, "y": 0.0, "z": 0.0},
        "angular": {"x": 0.0, "y": 0.0, "z": 1.0},
    }


def test_range_decodes_with_the_robots_distribution_not_a_hard_coded_one() -> None:
    # Jazzy added Range.variance: its samples are 4 bytes longer than Humble's, and a Humble
    # definition refused them ("CDR message size mismatch"; issue #31)
    jazzy = encode_cdr("sensor_msgs/Range", {"range": 0.5, "variance": 0.01})
    humble = encode_cdr("sensor_msgs/Range", {"range": 0.5}, distro="humble")
    assert len(jazzy) == len(humble) + 4
    assert decode_cdr("sensor_msgs/Range", jazzy)["variance"] == pytest.approx(0.01)
    assert "variance" not in decode_cdr("sensor_msgs/Range", humble, distro="humble")
    assert decode_cdr("sensor_msgs/Range", humble, distro="humble")["range"] == 0.5


def test_a_bridge_file_names_the_distribution_and_none_known_is_an_error(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    from anunnaki.ros2._distro import installed_distro

    spec = parse_bridge("anunnaki: ros2-bridge/1\ndistro: humble\n")
    with open_bus("inproc") as b:
        assert Ros2ZenohBridge(spec, b, session=None).distro == "humble"
        monkeypatch.delenv("ROS_DISTRO")
        if installed_distro() is None:  # this venv has no ROS 2 wheels
            with pytest.raises(AnunnakiError, match=r"Name it in the bridge file \(distro: "):
                Ros2ZenohBridge(parse_bridge("anunnaki: ros2-bridge/1\n"), b, session=None)
    with pytest.raises(AnunnakiError, match="unknown ROS 2 distribution 'iron'"):
        decode_cdr("std_msgs/Bool", b"", distro="iron")


@pytest.fixture
def bus() -> Iterator[Bus]:
    with open_bus("zenoh") as b:
        yield b


@pytest.fixture
def ros2_side(bus: Bus) -> Iterator[Any]:
    """A plain zenoh session, as zenoh-bridge-ros2dds or rmw_zenoh's router would be."""
    endpoint = bus.endpoints[0]  # type: ignore[attr-defined]
    config = BusConfig(kind="zenoh", mode="peer", connect=[endpoint], listen=[])
    session = zenoh.open(zenoh.Config.from_json5(json.dumps(config.to_zenoh([]))))
    try:
        yield session
    finally:
        session.close()


class Waiter:
    def __init__(self, bus: Bus, topic: str, until: Any) -> None:
        self.got: list[Any] = []
        self.done = threading.Event()
        self.until = until
        bus.subscribe(topic, self.on)

    def on(self, sample: Any) -> None:
        self.got.append(sample.message.to_body())
        if self.until(self.got[-1]):
            self.done.set()


def publish_until(session: Any, key: str, raw: bytes, done: threading.Event) -> None:
    """Put the sample until it arrives: the sessions find each other asynchronously."""
    while not done.wait(0.05):
        session.put(key, raw)


@pytest.mark.parametrize("flavour", ["ros2dds", "rmw_zenoh"])
def test_ros2_samples_reach_the_bus_and_actions_reach_ros2(
    bus: Bus, ros2_side: Any, flavour: str
) -> None:
    spec = load_bridge(ROVER / "ros1" / "bridge.yaml")
    with Ros2ZenohBridge(spec, bus, ros2_side, flavour=flavour, domain=0):  # type: ignore[arg-type]

        def key(topic: str, ros1_type: str) -> str:
            return ros2_key(topic, ros1_type, flavour=flavour, type_hash="RIHS01_0123")  # type: ignore[arg-type]

        state = Waiter(bus, "/rover/controller/state", lambda m: m.get("control_mode") == "manual")
        mode = encode_cdr("std_msgs/String", {"data": "manual"})
        publish_until(ros2_side, key("/rover/controller/mode", "std_msgs/String"), mode, state.done)
        assert state.got[-1]["control_mode"] == "manual"
        rng = Waiter(bus, "/ultrasonic/range", lambda m: True)
        sample = encode_cdr("sensor_msgs/Range", {"header": {"stamp": 1.5}, "range": 0.5})
        publish_until(ros2_side, key("/ultrasonic/range", "sensor_msgs/Range"), sample, rng.done)
        assert rng.got[-1] == {"range": 0.5}
        # an action: the bus's buzzer command becomes a std_msgs/msg/Bool sample for ROS 2
        heard: list[dict[str, Any]] = []
        arrived = threading.Event()

        samples: list[Any] = []

        def on_buzzer(s: Any) -> None:
            heard.append(decode_cdr("std_msgs/Bool", s.payload.to_bytes()))
            samples.append((str(s.key_expr), s.attachment))
            arrived.set()

        listen = ros2_key("/rover/controller/buzzer", "std_msgs/Bool", flavour=flavour)  # type: ignore[arg-type]
        sub = ros2_side.declare_subscriber(listen, on_buzzer)
        try:
            while not arrived.wait(0.05):
                bus.publish("/rover/controller/buzzer", {"on": True})
        finally:
            sub.undeclare()
        assert heard[0] == {"data": True}
        key_expr, attachment = samples[0]
        if flavour == "rmw_zenoh":  # the real type hash, and the attachment rmw_zenoh needs
            assert key_expr.endswith("/std_msgs::msg::dds_::Bool_/" + BOOL_HASH)
            raw = attachment.to_bytes()
            assert len(raw) == 33 and raw[16] == 16  # seq, time, gid length, gid
            assert int.from_bytes(raw[:8], "little") >= 1
        else:
            assert key_expr == "rover/controller/buzzer" and attachment is None


def test_a_bad_sample_is_counted_and_the_next_goes_through(bus: Bus, ros2_side: Any) -> None:
    spec = parse_bridge(
        "anunnaki: ros1-bridge/1\ntopics:\n"
        "  - {ros: /battery, type: sensor_msgs/BatteryState, direction: to_bus,"
        " fields: {pct: percentage}}\n"
    )
    with Ros2ZenohBridge(spec, bus, ros2_side) as bridge:
        got = Waiter(bus, "/battery", lambda m: True)
        ros2_side.put("battery", b"\x00\x01\x00\x00\x01")  # cut short
        good = encode_cdr("sensor_msgs/BatteryState", {"percentage": 0.75})
        publish_until(ros2_side, "battery", good, got.done)
        assert got.got[-1] == {"pct": 0.75}
        assert bridge.stats["malformed"] >= 1


def test_the_ros2_launch_kind_bridges_a_robots_zenoh(bus: Bus, ros2_side: Any) -> None:
    from anunnaki.managed import MANAGED, ManagedContext
    from anunnaki.utu import parse_config

    cls = MANAGED.factory("ros2")
    options = cls.Options.model_validate(  # type: ignore[attr-defined]
        {"bridge": "ros1/bridge.yaml", "flavour": "rmw_zenoh", "oracle": {"name": "light"}}
    )
    kind = cls(options, base=ROVER)
    utu = parse_config(f"anunnaki: utu/1\ngoal_model: {ROVER}/goals.yaml\nclock: wall\n")
    kind.check(utu)
    said: list[str] = []
    ctx = ManagedContext(
        bus=bus,
        stop=threading.Event(),
        speed=1.0,
        until=None,
        say=said.append,
    )
    run = kind.start(ctx)  # no connect: the robot's zenoh joins the launch's session
    try:
        assert "ROS 2 robot over zenoh (rmw_zenoh" in said[0]
        rng = Waiter(bus, "/ultrasonic/range", lambda m: True)
        key = ros2_key(
            "/ultrasonic/range", "sensor_msgs/Range", flavour="rmw_zenoh", type_hash="RIHS01_ab"
        )
        publish_until(ros2_side, key, encode_cdr("sensor_msgs/Range", {"range": 2.5}), rng.done)
        assert rng.got[-1] == {"range": 2.5}
    finally:
        ctx.stop.set()
        run.thread.join(timeout=DEADLINE)
        run.close()
    assert not run.thread.is_alive()
