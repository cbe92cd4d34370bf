"""Rosbags in and out: a recorded ROS 1 or ROS 2 robot is a trace; a run exports to a bag."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from anunnaki import topics

pytest.importorskip("rosbags")
import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Bag1Writer
from rosbags.rosbag2 import Writer as Bag2Writer
from rosbags.typesys import Stores, get_typestore

from anunnaki.cli.main import main
from anunnaki.errors import ModelFileError
from anunnaki.goals import Evaluator, load_goal_model
from anunnaki.ros1 import load_bridge, parse_bridge, read_bag
from anunnaki.tactics import load_tactics
from anunnaki.utu import AutonomicManager, Knowledge

ROVER = Path(__file__).parents[2] / "examples" / "rover"
BRIDGE = ROVER / "ros1" / "bridge.yaml"
T0 = 1_700_000_000  # the recording's first second (epoch)


def rover_messages(store: Any, *, ros1: bool) -> list[tuple[float, str, str, Any]]:
    """Two seconds of the Fig. 13 rover at 10 Hz: (t, topic, type, message)."""
    ty = store.types
    time = ty["builtin_interfaces/msg/Time"]

    def header(seq: int, t: float) -> Any:
        stamp = time(sec=int(t), nanosec=round((t % 1) * 1e9))
        extra = {"seq": seq} if ros1 else {}
        return ty["std_msgs/msg/Header"](**extra, stamp=stamp, frame_id="camera")

    out: list[tuple[float, str, str, Any]] = []
    for i in range(20):
        t = T0 + i / 10
        mode = "autonomous" if i < 15 else "manual"
        string, boolean = ty["std_msgs/msg/String"], ty["std_msgs/msg/Bool"]
        out += [
            (t, "/rover/controller/mode", "std_msgs/msg/String", string(data=mode)),
            (t, "/rover/controller/buzzer_on", "std_msgs/msg/Bool", boolean(data=False)),
            (t, "/rover/controller/bumper", "std_msgs/msg/Bool", boolean(data=False)),
            (t, "/rover/controller/lights", "std_msgs/msg/Bool", boolean(data=True)),
        ]
        rng = ty["sensor_msgs/msg/Range"](
            header=header(i, t), radiation_type=0, field_of_view=0.5, min_range=0.02,
            max_range=4.0, range=0.5 if 5 <= i < 8 else 3.0,
        )  # fmt: skip
        out.append((t, "/ultrasonic/range", "sensor_msgs/msg/Range", rng))
        image = ty["sensor_msgs/msg/Image"](
            header=header(i, t), height=2, width=4, encoding="rgb8", is_bigendian=0, step=12,
            data=np.zeros(24, np.uint8),
        )  # fmt: skip
        out.append((t, "/camera/image_raw", "sensor_msgs/msg/Image", image))
    return out


def write_ros1_bag(path: Path) -> Path:
    store = get_typestore(Stores.ROS1_NOETIC)
    with Bag1Writer(path) as writer:
        conns: dict[str, Any] = {}
        for t, topic, msgtype, msg in rover_messages(store, ros1=True):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(conns[topic], round(t * 1e9), store.serialize_ros1(msg, msgtype))
    return path


def write_ros2_bag(path: Path) -> Path:
    store = get_typestore(Stores.ROS2_HUMBLE)
    with Bag2Writer(path, version=9) as writer:
        conns: dict[str, Any] = {}
        for t, topic, msgtype, msg in rover_messages(store, ros1=False):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(conns[topic], round(t * 1e9), store.serialize_cdr(msg, msgtype))
    return path


@pytest.mark.parametrize("version", ["ros1", "ros2"])
def test_a_rosbag_is_a_trace_through_the_bridge_file(tmp_path: Path, version: str) -> None:
    bag = (
        write_ros1_bag(tmp_path / "run.bag")
        if version == "ros1"
        else write_ros2_bag(tmp_path / "run")
    )
    records = read_bag(bag, load_bridge(BRIDGE))
    topics = {r.topic for r in records}
    # frames stay out of traces (P1); their header and size come through, as live
    assert topics == {"/rover/controller/state", "/camera/image_info", "/ultrasonic/range"}
    states = [r.msg for r in records if r.topic == "/rover/controller/state"]
    assert states[3] == {
        "control_mode": "autonomous",
        "buzzer_on": False,
        "bumper_pressed": False,
        "lights_on": True,
    }
    info = [r.msg for r in records if r.topic == "/camera/image_info"]
    assert info[0]["width"] == 4 and info[0]["height"] == 2
    if version == "ros1":
        assert [i["header"]["seq"] for i in info[:3]] == [0, 1, 2]
    assert records[0].t == pytest.approx(T0)
    # the goal model reads the recording as it would read the robot
    model = load_goal_model(ROVER / "goals.yaml", ROVER / "binding-ros.yaml", strict=False)
    ev = Evaluator(model)
    seen: dict[str, list[Any]] = {"G13": [], "G7": []}
    for r in records:
        ev.tick(r.t)
        ev.observe(r.topic, r.msg, r.t)
        for goal, statuses in seen.items():
            statuses.append(ev.state(goal).status)
    assert False in seen["G13"] and seen["G13"][-1] is True  # 0.5 m from 0.5 s to 0.8 s
    assert seen["G7"][-1] is False  # manual from 1.5 s on


def test_evaluate_takes_a_rosbag_with_its_bridge_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = write_ros1_bag(tmp_path / "run.bag")
    args = [
        "evaluate",
        str(ROVER / "goals.yaml"),
        "-b",
        str(ROVER / "binding-ros.yaml"),
        "-t",
        str(bag),
    ]
    assert main(args) == 2
    assert "give --bridge BRIDGE.yaml" in capsys.readouterr().err
    assert main([*args, "--bridge", str(BRIDGE), "--json"]) == 0
    last = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert last["silent_topics"] == {"/utu/oracle/output": ["A4"]}  # the rest came from the bag


def test_a_bag_whose_topic_has_another_type_is_refused(tmp_path: Path) -> None:
    bag = write_ros1_bag(tmp_path / "run.bag")
    spec = parse_bridge(
        "anunnaki: ros1-bridge/1\ntopics:\n"
        "  - {ros: /ultrasonic/range, type: std_msgs/Float32, direction: to_bus}\n"
    )
    with pytest.raises(ModelFileError, match="is sensor_msgs/Range in the bag, but the bridge"):
        read_bag(bag, spec)


def test_a_run_exports_to_a_bag_and_reads_back(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    records = read_bag(write_ros1_bag(tmp_path / "in.bag"), load_bridge(BRIDGE))
    model = load_goal_model(ROVER / "goals.yaml", ROVER / "binding-ros.yaml")
    db = tmp_path / "run.db"
    m = AutonomicManager(
        model, load_tactics(ROVER / "tactics.xml"), knowledge=Knowledge(str(db)), warmup=0.2
    )
    for r in records:
        m.feed(r.topic, r.msg, t=r.t)
        m.feed("/utu/oracle/output", {"category": 0, "confidence": 0.9}, t=r.t)
        m.step(r.t)
    decisions = [d for d in m.knowledge.decisions()]
    m.close()
    assert any(d.tactic == "warn-pedestrians" for d in decisions)  # the near object
    out = tmp_path / "out.bag"
    assert main(["log", str(db), "--export-bag", str(out)]) == 0
    assert "decisions) to" in capsys.readouterr().out  # (no model texts recorded: no hint)
    with AnyReader([out]) as reader:
        got: dict[str, list[Any]] = {}
        for conn, _, raw in reader.messages():
            got.setdefault(conn.topic, []).append(
                json.loads(reader.deserialize(raw, conn.msgtype).data)
            )
    assert len(got[topics.BAG_DECISIONS]) == len(decisions)
    assert got[topics.BAG_DECISIONS][0]["kind"] == decisions[0].kind
    assert got["/ultrasonic/range"][:2] == [{"range": 3.0}, {"range": 3.0}]
    assert len(got["/rover/controller/state"]) == 80
    # Read back without a bridge file: its topics are the bus's, its messages their JSON.
    back = read_bag(out)
    kb = Knowledge(str(db))
    recorded = [row for row in kb.inputs() if not row.topic.startswith("__")]
    kb.close()

    def rows(items: Any) -> list[tuple[float, str, str]]:
        return sorted((round(r.t, 6), r.topic, json.dumps(r.msg, sort_keys=True)) for r in items)

    assert rows(back) == rows(recorded)
    goals, binding = str(ROVER / "goals.yaml"), str(ROVER / "binding-ros.yaml")
    assert main(["evaluate", goals, "--binding", binding, "--trace", str(out)]) == 0
    assert "G13" in capsys.readouterr().out
    assert main(["log", str(db), "--export-bag", str(out)]) == 2  # not overwritten...
    assert "--force" in capsys.readouterr().err
    assert main(["log", str(db), "--export-bag", str(out), "--force"]) == 0  # ...unless asked
    assert len(read_bag(out)) == len(back)


def test_a_bag_of_a_robot_needs_its_bridge_file(tmp_path: Path) -> None:
    with pytest.raises(ModelFileError, match=r"not a bag of an Anunnaki run.*--bridge"):
        read_bag(write_ros1_bag(tmp_path / "robot.bag"))
