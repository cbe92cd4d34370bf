"""The benchmarks' quick modes: one test file per script of ``benchmarks/``, named after it.

Each script runs with tiny parameters into a temporary file and must write the figures the
docs quote (``docs/results.md``), with the structure they are read in. The figures themselves
are not judged here: they are measured by hand on a quiet machine (no timed assertions in
tests). One file per script lets the suite's workers (``--dist loadfile``) share them out.
``benchmarks/ros1.py``'s test stays beside the ROS 1 tests (``tests/ros1``), whose helpers
start and find ROS; ``ros1_node.py`` is that benchmark's ROS side, no benchmark of its own.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from bench_helpers import ROOT


@pytest.fixture(scope="session")
def tiny_rover(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A rendered rover dataset of 4 frames per split (read only), for the Enlil benchmarks."""
    pytest.importorskip("pybullet")
    data = tmp_path_factory.mktemp("rover") / "data"
    subprocess.run(
        [
            sys.executable, "-m", "anunnaki", "make-dataset", "rover", "--out", str(data),
            "--train-layouts", "0", "--val-layouts", "1", "--test-layouts", "2",
            "--per-layout", "4", "--workers", "1",
        ],
        check=True, capture_output=True, cwd=ROOT, timeout=300,
    )  # fmt: skip
    return data
