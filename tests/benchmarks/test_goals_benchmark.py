"""benchmarks/goals.py in its quick mode: incremental evaluation beside the bare min/max rate."""

from __future__ import annotations

from pathlib import Path

from bench_helpers import load, run


def test_goals_benchmark(tmp_path: Path) -> None:
    out = tmp_path / "goals.json"
    run("goals.py", "--updates", "200", "--messages", "50", "--repeat", "1", "--output", str(out))
    doc = load(out)
    assert doc["benchmark"] == "goals"
    assert doc["model"]["goals"] > 1000 and doc["model"]["depth"] == 5
    assert doc["runs"] == {"updates": 200, "messages": 50, "repeat": 1}
    rates = ("incremental_updates_per_s", "messages_per_s", "baseline_bare_minmax_updates_per_s")
    assert all(doc[key] > 0 for key in rates)
    assert doc["incremental_over_baseline"] > 0 and doc["aim_over_baseline"] == 0.6
    assert 0 < doc["full_evaluation_ms"]["min"] <= doc["full_evaluation_ms"]["median"]
