"""benchmarks/dashboard.py in its quick mode: the browser's frame rate and time to red."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from bench_helpers import load, run


@pytest.mark.slow
def test_dashboard_benchmark(tmp_path: Path) -> None:
    chromium = os.environ.get("ANUNNAKI_CHROMIUM", "/usr/bin/chromium")
    if not Path(chromium).exists() and os.environ.get("ANUNNAKI_REQUIRE_BROWSER") != "1":
        pytest.skip(f"no Chromium at {chromium}: run scripts/setup-browser.sh")
    out = tmp_path / "dashboard.json"
    run("dashboard.py", "--seconds", "3", "--out", str(out))
    doc = load(out)
    assert doc["setup"]["goals"] == 300
    raf = doc["raf_interval_ms"]
    assert raf["n"] > 10 and 0 < raf["p50"] <= raf["p95"] <= raf["max"]
    assert doc["violation_to_red_ms"]["n"] >= 1
    assert doc["camera_frames_drawn_per_s"] > 0
    # the assurance case pane: the same violation turns the claim G1 red there too
    case = doc["case"]
    assert case["nodes"] > 300 and case["aim_p95_ms"] == 100
    assert case["violation_to_claim_red_ms"]["n"] >= 1
