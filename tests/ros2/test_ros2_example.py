"""The ROS 2 example end to end: examples/rover/ros2.yaml manages the rclpy rover.

The rover (examples/rover/ros2/rover_robot.py, three rclpy nodes) and ``anunnaki run
examples/rover/ros2.yaml`` (Utu, the detector and the light oracle on the bridged camera, and
the native bridge it starts with the ROS 2 environment's Python) run in one loopback-only
network namespace. The rover's camera is dim and something is near from the start: once Utu
is warm, the fail-safe hands the rover to a human through its own SetBool service and the
buzzer sounds. Then the bridge is killed with SIGKILL (no clean stop, no goodbye to DDS):
the rover's subscription to the bridge's heartbeat sees its liveliness lapse (``alive_count``
0, a lease after the last heartbeat) and the rover puts itself in its safe state; the launch
ends, saying why.
"""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from ros2_support import DEADLINE, ROS2_PYTHON, Netns, need_ros2, wait_until

ROVER = Path(__file__).parents[2] / "examples" / "rover"


@pytest.fixture
def ns(tmp_path: Path) -> Iterator[Netns]:
    need_ros2()
    pytest.importorskip("torch")  # the launch runs the detector on the bridged camera
    setup = Netns(tmp_path / "ros2")
    setup.env["ANUNNAKI_ROS2_PYTHON"] = str(ROS2_PYTHON)
    try:
        yield setup
    finally:
        setup.close()


def children(pid: int) -> list[int]:
    """The child processes of ``pid`` (every thread's), from /proc."""
    out: list[int] = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        text = (task / "children").read_text().split()
        out.extend(int(x) for x in text)
    return out


def test_the_ros2_example_fails_safe_sounds_the_buzzer_and_survives_a_killed_bridge(
    ns: Netns,
) -> None:
    script = str(ROVER / "ros2" / "rover_robot.py")
    rover = ns.python(
        script, "--dim-at", "0", "--near-from", "0", name="rover", ready="rover ready"
    )
    run = ns.start(
        [sys.executable, "-m", "anunnaki.cli.main", "run", str(ROVER / "ros2.yaml")],
        "anunnaki run",
    )
    run.wait_for("ros2: ros2 bridge ready", timeout=DEADLINE)
    run.wait_for("managed: ROS 2 robot through")
    # the light oracle sees the dim frames (through the bridge), G3 fails, the fail-safe
    # requests the logical set_mode: the bridge turns mode=manual into the rover's SetBool
    assert rover.wait_for("set_mode manual") == "set_mode manual: accepted"
    line = run.wait_for("change_mode ok=true")
    assert "service=/rover/controller/set_mode mode=manual" in line
    run.wait_for("postcondition_ok     fail-safe")
    # something is near (the bridged Range): G12 fails and the buzzer sounds on the rover
    assert rover.wait_for("buzzer ") == "buzzer True"
    # the bridge is killed outright: the rover's own fail-safe sees its heartbeat lapse
    rover.wait_for("manager anunnaki_bridge alive")
    bridges = [p for p in children(run.p.pid) if "anunnaki.ros2" in _cmdline(p)]
    assert len(bridges) == 1, [_cmdline(p) for p in children(run.p.pid)]
    before = len(rover.lines)
    os.kill(bridges[0], signal.SIGKILL)
    gone = "manager anunnaki_bridge gone: safe state manual"
    wait_until(lambda: any(gone in line for line in rover.lines[before:]), "the safe state")
    run.wait_for("the bridge process exited")
    assert run.p.wait(timeout=DEADLINE) is not None
    assert rover.p.poll() is None  # the robot carries on, in its safe state


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except FileNotFoundError:
        return ""
