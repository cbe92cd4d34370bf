"""benchmarks/determinism.py on the UAV: its first 11 s twice, the second beside a busy process,
give the same report and decision log, and ``anunnaki replay`` of the first reproduces it.

(The rover's stretch is tests/benchmarks/test_determinism_benchmark.py's: a file of its own
each, so that the suite's two workers, which share out files, can run them side by side.)
"""

from __future__ import annotations

from pathlib import Path

import pytest
from bench_helpers import check_repeats


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_the_uav_repeats_itself_quiet_and_loaded(tmp_path: Path) -> None:
    check_repeats(tmp_path, "uav", 11.0)
