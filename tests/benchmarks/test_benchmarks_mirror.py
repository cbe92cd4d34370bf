"""Every script of ``benchmarks/`` has its quick-mode test, so none can rot unseen."""

from __future__ import annotations

from pathlib import Path

from bench_helpers import BENCH, ROOT

HERE = Path(__file__).parent

#: Scripts tested beside the tests whose helpers they need.
ELSEWHERE = {
    "ros1": ROOT / "tests" / "ros1" / "test_ros1_benchmark.py",
    "ros2": ROOT / "tests" / "ros2" / "test_ros2_benchmark.py",
    "ros2_probe": ROOT / "tests" / "ros2" / "test_ros2_benchmark.py",
    "robustify": ROOT / "tests" / "enki" / "test_robustify_benchmark.py",
}
#: Scripts that are part of another benchmark, not benchmarks of their own.
PARTS = {
    "ros1_node": "benchmarks/ros1.py's ROS side (an echo node under Debian's python3)",
    "ros2_node": "benchmarks/ros2.py's ROS 2 side (rclpy nodes in the ROS 2 environment)",
}


def test_every_benchmark_script_has_a_test_of_its_name() -> None:
    scripts = {p.stem for p in BENCH.glob("*.py")}
    tested = {
        p.name.removeprefix("test_").removesuffix("_benchmark.py")
        for p in HERE.glob("test_*_benchmark.py")
    }
    assert scripts - set(PARTS) == tested | set(ELSEWHERE)
    assert all(test.exists() for test in ELSEWHERE.values())
    assert set(PARTS) <= scripts
