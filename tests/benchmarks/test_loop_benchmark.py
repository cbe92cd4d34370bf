"""benchmarks/loop.py in its quick mode: the rate of each stage of the whole loop, for the
rover's loop and the UAV's."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from bench_helpers import load, run


def _stages_of(doc: dict[str, Any]) -> None:
    stages = doc["stages"]
    assert list(stages) == ["platform", "detector", "oracle", "utu"]
    for entry in stages.values():
        assert entry["runs"][0]["frames"] == 15  # 10 Hz camera over 1.5 simulated seconds
        assert entry["fps_median"] > 0
    assert all(entry["cpu_ms_per_frame_median"] > 0 for entry in stages.values())
    assert stages["platform"]["ratio_to_platform"] == 1.0
    assert doc["whole_loop_hz"] == stages["utu"]["fps_median"]
    assert doc["aim_met"] is (doc["whole_loop_hz"] >= doc["aim_hz"])


@pytest.mark.slow
def test_loop_benchmark(tmp_path: Path) -> None:
    out = tmp_path / "loop.json"
    run("loop.py", "--seconds", "1.5", "--repeats", "1", "--output", str(out), timeout=480)
    doc = load(out)
    _stages_of(doc)  # the rover's, at the top level
    assert doc["camera"] == "128x128 at 10 Hz"
    uav = doc["uav"]
    _stages_of(uav)
    assert uav["camera"] == "320x240 at 10 Hz" and uav["launch"].endswith("uav/sim.yaml")
    assert uav["scorer"] == "off"  # the launch's live scorer is not part of the loop
