"""An exported rosbag2 plays to a real rclpy subscriber, and MCAP's own reader accepts it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from ros2_support import DEADLINE, Netns, need_ros2

from anunnaki import topics
from anunnaki.rosbridge import write_bag
from anunnaki.trace import Record

INPUTS = [
    Record(1.0, "/rover/controller/state", {"control_mode": "autonomous", "buzzer_on": False}),
    Record(1.5, "/ultrasonic/range", {"range": 0.5}),
    Record(2.0, "/rover/controller/state", {"control_mode": "manual", "buzzer_on": True}),
]
DECISIONS = [(1.6, {"kind": "started", "tactic": "warn-pedestrians"})]


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_an_exported_rosbag2_plays_to_an_rclpy_subscriber(tmp_path: Path, storage: str) -> None:
    need_ros2()
    bag = tmp_path / "run"
    write_bag(bag, INPUTS, DECISIONS, storage=storage)
    ns = Netns(tmp_path / "ros2")
    try:
        player = Path(__file__).with_name("bag_player.py")
        proc = ns.python(str(player), str(bag), name="player")
        line = proc.wait_for('{"received"', timeout=DEADLINE)
    finally:
        ns.close()
    out = json.loads(line)
    received = {t: [json.loads(d) for d in data] for t, data in out["received"].items()}
    assert received == {
        "/rover/controller/state": [INPUTS[0].msg, INPUTS[2].msg],
        "/ultrasonic/range": [INPUTS[1].msg],
        topics.BAG_DECISIONS: [DECISIONS[0][1]],
    }
    if storage == "mcap":
        assert out["mcap"] == {
            "/rover/controller/state": 2,
            "/ultrasonic/range": 1,
            topics.BAG_DECISIONS: 1,
        }
