"""The ``ros`` fixture: a ROS 1 master on a free port, torn down with all it started."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from ros1_support import RosSetup, need_ros


@pytest.fixture
def ros(tmp_path: Path) -> Iterator[RosSetup]:
    need_ros()
    setup = RosSetup(tmp_path / "ros_home")
    try:
        yield setup
    finally:
        setup.close()
