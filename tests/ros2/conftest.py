"""The live ROS 2 tests leave no Fast DDS shared-memory segments behind.

Fast DDS (rclpy's default middleware) keeps a segment and a port file in ``/dev/shm`` per
participant and removes them when the participant closes; a process the tests SIGKILL (a
bridge, on purpose) leaves its own. On a developer's machine they piled up: 1,072 files and
149 MB after a day of suite runs. After a worker's last ROS 2 test, ``fastdds shm clean``
(the ROS 2 environment's own tool) removes the segments no live process holds; the other
worker's are in use and stay.
"""

from __future__ import annotations

import subprocess
from collections.abc import Iterator

import pytest
from ros2_support import ROS2_PYTHON, ros2_missing


@pytest.fixture(scope="session", autouse=True)
def _no_zombie_segments_left() -> Iterator[None]:
    yield
    fastdds = ROS2_PYTHON.parent / "fastdds"
    if ros2_missing() is None and fastdds.exists():
        subprocess.run([str(fastdds), "shm", "clean"], capture_output=True, timeout=60, check=False)
