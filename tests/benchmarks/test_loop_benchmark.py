"""benchmarks/loop.py in its quick mode: the rate of each stage of the whole loop."""

from __future__ import annotations

from pathlib import Path

import pytest
from bench_helpers import load, run


@pytest.mark.slow
def test_loop_benchmark(tmp_path: Path) -> None:
    out = tmp_path / "loop.json"
    run("loop.py", "--seconds", "1.5", "--repeats", "1", "--output", str(out))
    doc = load(out)
    stages = doc["stages"]
    assert list(stages) == ["platform", "detector", "oracle", "utu"]
    for entry in stages.values():
        assert entry["runs"][0]["frames"] == 15  # 10 Hz camera over 1.5 simulated seconds
        assert entry["fps_median"] > 0
    assert stages["platform"]["ratio_to_platform"] == 1.0
    assert doc["whole_loop_hz"] == stages["utu"]["fps_median"]
    assert doc["aim_met"] is (doc["whole_loop_hz"] >= doc["aim_hz"])
