"""benchmarks/ros2.py runs with tiny parameters and writes the figures docs/results.md quotes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from ros2_support import ROOT, ROS2_PYTHON, need_ros2


def test_the_ros2_benchmark_writes_its_figures(tmp_path: Path) -> None:
    need_ros2()
    out = tmp_path / "ros2.json"
    args = ["--small", "5", "--images", "2", "--stream", "6", "--trials", "3", "--kills", "1"]
    args += ["--output", str(out)]
    done = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "ros2.py"), *args],
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
        cwd=ROOT,
        env={"ANUNNAKI_ROS2_PYTHON": str(ROS2_PYTHON), **_env()},
    )
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-4000:]
    doc = json.loads(out.read_text(encoding="utf-8"))
    assert doc["benchmark"] == "ros2"
    for part in ("small_message_round_trip", "image_320x240_round_trip"):
        assert {"direct", "bridged"} == set(doc[part])
        assert doc[part]["bridged"]["n"] > 0 and doc[part]["direct"]["n"] > 0
    stream = doc["image_320x240_stream"]["bridged"]
    assert stream["sent"] == 6 and stream["received"] + stream["dropped"] == 6
    assert set(doc["added_by_bridge"]) == {"small_median_ms", "small_p99_ratio", "image_median_ms"}
    reaction = doc["violation_to_robot_service_call"]
    assert reaction["n"] + reaction["lost"] == 3 and reaction["n"] > 0
    assert "first_call_ms" in reaction  # the warm-up trial, apart
    killed = doc["bridge_kill_to_rover_safe_state"]
    assert (killed["n"], killed["lost"], killed["heartbeat_lease_s"]) == (1, 0, 1.0)


def _env() -> dict[str, str]:
    import os

    return {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}


def test_the_ros2_probe_compares_executors_and_transports(tmp_path: Path) -> None:
    """benchmarks/ros2_probe.py, tiny: plain rclpy round trips per executor and transport."""
    need_ros2()
    out = tmp_path / "probe.json"
    args = ["--small", "5", "--images", "1", "--rounds", "1", "--executors", "multi,single"]
    args += ["--transports", "DEFAULT,UDPv4", "--output", str(out)]
    done = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "ros2_probe.py"), *args],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
        cwd=ROOT,
        env={"ANUNNAKI_ROS2_PYTHON": str(ROS2_PYTHON), **_env()},
    )
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-4000:]
    text = out.read_text(encoding="utf-8")
    assert json.loads(text)  # what it wrote is JSON
    for name in ("multi", "single", "DEFAULT", "UDPv4"):
        assert name in text, name
