"""The README's ROS 1 example runs: examples/rover/ros1.yaml against the example rover."""

from __future__ import annotations

import sys

import pytest
from ros1_support import ROVER, Proc, RosSetup

pytestmark = pytest.mark.slow  # a master, the rover, the launch with torch's detector


def test_the_ros1_example_hands_the_dimmed_rover_to_a_human(ros: RosSetup) -> None:
    rover = ros.rover("--dim-at", "2")  # the camera dims 2 s after the rover starts
    run = Proc(
        [sys.executable, "-m", "anunnaki.cli.main", "run", str(ROVER / "ros1.yaml")],
        ros.env,
        "anunnaki run",
    )
    ros.procs.append(run)
    run.wait_for("ros1 bridge ready")
    run.wait_for("managed: ROS 1 robot through")
    # the light oracle sees the dim frames (through the bridge), G3 fails, the fail-safe
    # calls the robot's own set_mode service: the rover says so, then Utu verifies it
    assert rover.wait_for("set_mode manual") == "set_mode manual: accepted"
    line = run.wait_for("change_mode ok=true")
    assert "service=/rover/controller/set_mode mode=manual" in line
    run.wait_for("postcondition_ok     fail-safe")
    run.p.terminate()
    assert run.p.wait(timeout=60) == 0
    run.wait_for("ros1 bridge stopped")
