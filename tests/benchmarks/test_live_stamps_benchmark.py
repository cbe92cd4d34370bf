"""benchmarks/live_stamps.py: the rover replayed live on sim time, against the deterministic
run (issue #30). Quick mode: one run on threads at 50×, where every input is stamped with the
instant it was published in, so the fail-safe never comes before the light dims at t=25.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from bench_helpers import ROOT, load, run

RESULTS = ROOT / "benchmarks" / "results" / "live-stamps-issue30.json"


@pytest.mark.slow
def test_one_live_run_on_threads_decides_no_earlier_than_the_deterministic_run(
    tmp_path: Path,
) -> None:
    out = tmp_path / "live.json"
    run("live_stamps.py", "--label", "quick", "--runs", "1", "--cases", "threads-50x",
        "--output", str(out))  # fmt: skip
    entry = load(out)["entries"]["quick"]
    reference = entry["deterministic"]
    assert [tuple(d) for d in reference[:2]] == [
        (25.0, "selected", "fail-safe"),
        (25.0, "started", "fail-safe"),
    ]
    case = entry["cases"]["threads-50x"]
    assert case["mode"] == "threads" and case["speed"] == 50.0 and case["runs"] == 1
    row = case["rows"][0]
    assert row["story"] and row["failsafe_t"] >= 25.0, row
    for live, exact in zip(row["decisions"], reference, strict=True):
        assert live[0] >= exact[0], row


def test_the_committed_figures_hold_what_docs_results_md_quotes() -> None:
    entries = load(RESULTS)["entries"]
    assert {"before", "after", "after-busy"} <= set(entries)
    after = entries["after"]["cases"]
    for name in ("threads-10x", "threads-50x", "processes-10x"):
        assert after[name]["exact"] == after[name]["runs"] == 5
        assert after[name]["failsafe_t_min"] == 25.0
    assert entries["before"]["cases"]["threads-50x"]["failsafe_t_min"] == 13.6
