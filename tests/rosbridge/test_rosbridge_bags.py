"""A run exports to a rosbag2 folder (MCAP or SQLite 3) that reads back as its trace."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("rosbags")
from rosbags.highlevel import AnyReader

from anunnaki import topics
from anunnaki.errors import AnunnakiError
from anunnaki.rosbridge import bag_storage, is_bag, read_bag, write_bag
from anunnaki.trace import Record

INPUTS = [
    Record(1.0, "/rover/controller/state", {"control_mode": "autonomous", "buzzer_on": False}),
    Record(1.5, "/ultrasonic/range", {"range": 0.5}),
    Record(2.0, "/rover/controller/state", {"control_mode": "manual", "buzzer_on": True}),
]
DECISIONS = [(1.6, {"kind": "started", "tactic": "warn-pedestrians"})]


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_run_exports_to_a_rosbag2_folder_that_reads_back(tmp_path: Path, storage: str) -> None:
    out = tmp_path / "run"
    assert write_bag(out, INPUTS, DECISIONS, storage=storage) == 4
    assert is_bag(out) and (out / "metadata.yaml").exists()
    suffix = ".mcap" if storage == "mcap" else ".db3"
    assert [p.suffix for p in out.iterdir() if p.name != "metadata.yaml"] == [suffix]
    assert "version: 9" in (out / "metadata.yaml").read_text()
    assert read_bag(out) == INPUTS  # the decisions stay out of the trace
    with AnyReader([out]) as reader:
        assert {c.topic: c.msgtype for c in reader.connections} == {
            "/rover/controller/state": "std_msgs/msg/String",
            "/ultrasonic/range": "std_msgs/msg/String",
            topics.BAG_DECISIONS: "std_msgs/msg/String",
        }


def test_the_storage_follows_the_name_and_a_folder_is_replaced_only_if_a_bag(
    tmp_path: Path,
) -> None:
    assert bag_storage("run.bag") == "ros1"
    assert bag_storage("run") == "mcap"
    assert bag_storage("run", "sqlite3") == "sqlite3"
    with pytest.raises(AnunnakiError, match="unknown bag storage 'zip'"):
        bag_storage("run", "zip")
    out = tmp_path / "run"
    write_bag(out, INPUTS)
    with pytest.raises(AnunnakiError, match="exists already; give another name, or --force"):
        write_bag(out, INPUTS)
    assert write_bag(out, INPUTS[:1], overwrite=True) == 1
    assert read_bag(out) == INPUTS[:1]
    other = tmp_path / "photos"
    other.mkdir()
    with pytest.raises(AnunnakiError, match="is a folder but no rosbag2"):
        write_bag(other, INPUTS, overwrite=True)


def test_a_jazzy_rosbag2_reads_through_the_ros2_rovers_bridge_file(tmp_path: Path) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    from anunnaki.rosbridge import load_bridge

    store = get_typestore(Stores.ROS2_JAZZY)
    ty = store.types
    bag = tmp_path / "robot"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        mode = writer.add_connection(
            "/rover/controller/mode", "std_msgs/msg/String", typestore=store
        )
        rng = writer.add_connection("/ultrasonic/range", "sensor_msgs/msg/Range", typestore=store)
        stamp = ty["builtin_interfaces/msg/Time"](sec=5, nanosec=0)
        header = ty["std_msgs/msg/Header"](stamp=stamp, frame_id="us")
        r = ty["sensor_msgs/msg/Range"](
            header=header, radiation_type=0, field_of_view=0.5, min_range=0.02, max_range=4.0,
            range=0.5, variance=0.01,
        )  # fmt: skip
        s = ty["std_msgs/msg/String"](data="manual")
        writer.write(mode, 5_000_000_000, store.serialize_cdr(s, "std_msgs/msg/String"))
        writer.write(rng, 5_100_000_000, store.serialize_cdr(r, "sensor_msgs/msg/Range"))
    spec = load_bridge(Path(__file__).parents[2] / "examples" / "rover" / "ros2" / "bridge.yaml")
    assert read_bag(bag, spec) == [
        Record(5.0, "/rover/controller/state", {"control_mode": "manual"}),
        Record(5.1, "/ultrasonic/range", {"range": 0.5}),
    ]


def test_a_rosbag2_replays_as_a_run_that_replay_and_explain_read(tmp_path: Path) -> None:
    # a bag of the rover's phases (as anunnaki log --export-bag writes one) is the scripted
    # system's trace: anunnaki run records a run that replay reproduces and explain reads
    import io
    from contextlib import redirect_stdout

    from anunnaki.cli.main import main
    from anunnaki.trace import read_trace

    rover = Path(__file__).parents[2] / "examples" / "rover"
    bag = tmp_path / "phases"
    write_bag(bag, read_trace(rover / "trace.jsonl").records)
    launch = tmp_path / "launch.yaml"
    text = (rover / "utu.yaml").read_text(encoding="utf-8")
    for name in ("goals.yaml", "binding.yaml", "tactics.yaml"):
        text = text.replace(f": {name}", f": {rover / name}")
    launch.write_text(text.replace("trace: trace.jsonl", f"trace: {bag}"), encoding="utf-8")
    db = tmp_path / "run.db"
    out = io.StringIO()
    with redirect_stdout(out):
        assert main(["run", str(launch), "--speed", "0", "--knowledge", str(db)]) == 0
    assert f"from {bag} (" in out.getvalue()
    with redirect_stdout(io.StringIO()) as said:
        assert main(["replay", str(db)]) == 0
    assert "identical" in said.getvalue()
    with redirect_stdout(io.StringIO()) as said:
        assert main(["explain", str(db), "--at", "30"]) == 0
    assert "G1" in said.getvalue()
