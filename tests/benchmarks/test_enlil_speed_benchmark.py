"""benchmarks/enlil_speed.py in its quick mode: each step as fast and as exact as its baseline."""

from __future__ import annotations

from pathlib import Path

import pytest
from bench_helpers import load, run


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_enlil_speed_benchmark(tmp_path: Path, tiny_rover: Path) -> None:
    data = tiny_rover
    out = tmp_path / "enlil_speed.json"
    args = ["--quick", "--data", str(data), "--output", str(out), "--evals", "2"]
    args += ["--frames", "32", "--fit-frames", "64"]
    args += ["--predict-calls", "20"]
    steps = "assess_fog,oracle_frames,oracle_fit,oracle_predict"
    run("enlil_speed.py", *args, "--steps", steps, timeout=600)
    doc = load(out)
    assert list(doc["steps"]) == ["assess_fog", "oracle_frames", "oracle_fit", "oracle_predict"]
    # the shipped oracle's predict: the same probabilities as before its speed-up
    assert doc["steps"]["oracle_predict"]["max_prob_diff"] < 1e-5
    assert doc["steps"]["oracle_predict"]["current_median_ms"] > 0
    # the baseline tree and this one compute the same archive figures and frames
    assert doc["steps"]["assess_fog"]["identical"] and doc["steps"]["oracle_frames"]["identical"]
    assert doc["steps"]["oracle_fit"]["fit_loss_max_rel_diff"] < 1e-3
    assert all(s["baseline_cpu_s"] > 0 and s["current_cpu_s"] > 0 for s in doc["steps"].values())
