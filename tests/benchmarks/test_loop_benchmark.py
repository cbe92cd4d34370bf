"""benchmarks/loop.py in its quick mode: the rate of each stage of the whole loop in one
process, and of the loop with one process per component, for the rover's loop and the UAV's,
both with the learned enlil oracle as agent A4."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from bench_helpers import load, run

FRAMES = 15  # 10 Hz camera over 1.5 simulated seconds


def _stages_of(doc: dict[str, Any]) -> None:
    stages = doc["stages"]
    assert list(stages) == ["platform", "detector", "oracle", "utu"]
    for entry in stages.values():
        assert entry["runs"][0]["frames"] == FRAMES
        assert entry["fps_median"] > 0
    assert all(entry["cpu_ms_per_frame_median"] > 0 for entry in stages.values())
    assert stages["platform"]["ratio_to_platform"] == 1.0
    assert doc["whole_loop_hz"] == stages["utu"]["fps_median"]
    assert doc["aim_met"] is (doc["whole_loop_hz"] >= doc["aim_hz"])


def _processes_of(doc: dict[str, Any]) -> None:
    """Frames flowed through every process, and Utu, in its own, took the oracle's verdicts."""
    split = doc["processes"]
    (one,) = split["runs"]
    assert one["frames"] == FRAMES
    flow = one["flow"]
    assert list(flow) == ["platform", "detector", "oracle", "utu"]
    assert flow["platform"]["frames"] == FRAMES
    # In lockstep every frame reached the detector and the oracle in their processes and was
    # handled before the next: no wait ran out (each allows 10 s; a lost acknowledgement
    # once made every frame wait them all out, and the run 12 times slower).
    assert one["lockstep_timeouts"] == 0
    for name, out in (("detector", "detections"), ("oracle", "assessments")):
        assert 0 < flow[name][out] <= flow[name]["frames"] == FRAMES
    assert flow["detector"]["detections"] == FRAMES
    # Utu's process took in the oracle's verdicts (on A4's topic) from across the bus.
    assert 0 < flow["utu"]["oracle_verdicts"] <= flow["oracle"]["assessments"]
    assert flow["utu"]["inputs"] > flow["utu"]["oracle_verdicts"]  # and the platform's topics
    # torch only where a network runs (the platform's and Utu's processes do not load it)
    threads = one["torch_threads"]
    assert threads["platform"] is None and threads["utu"] is None, threads
    assert threads["detector"] >= 1 and threads["oracle"] >= 1, threads
    by = one["cpu_ms_per_frame_by_process"]
    assert set(by) == set(flow) and all(v > 0 for v in by.values())
    assert one["cpu_ms_per_frame"] == pytest.approx(sum(by.values()), abs=0.2)
    assert doc["processes_hz"] == split["fps_median"] > 0
    assert doc["aim_met_processes"] is (doc["processes_hz"] >= doc["aim_hz"])
    assert split["ratio_to_one_process"] == pytest.approx(
        split["fps_median"] / doc["whole_loop_hz"], abs=1e-3
    )


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_loop_benchmark(tmp_path: Path) -> None:
    out = tmp_path / "loop.json"
    run("loop.py", "--seconds", "1.5", "--repeats", "1", "--output", str(out), timeout=840)
    doc = load(out)
    assert doc["layouts"] == ["one_process", "processes"]
    _stages_of(doc)  # the rover's, at the top level
    _processes_of(doc)
    assert doc["camera"] == "128x128 at 10 Hz" and doc["aim_hz"] == 20
    assert doc["launch"].endswith("rover/demo.yaml") and doc["oracle"] == "enlil"
    uav = doc["uav"]
    _stages_of(uav)
    _processes_of(uav)
    assert uav["camera"] == "320x240 at 10 Hz" and uav["launch"].endswith("uav/sim.yaml")
    assert uav["oracle"] == "enlil" and uav["aim_hz"] == 10
    assert uav["scorer"] == "off"  # the launch's live scorer is not part of the loop
