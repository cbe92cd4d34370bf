"""benchmarks/ros1.py runs with tiny parameters and writes the figures docs/results.md quotes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from ros1_support import ROOT, need_ros


@pytest.mark.slow
def test_the_ros1_benchmark_writes_its_figures(tmp_path: Path) -> None:
    need_ros()
    out = tmp_path / "ros1.json"
    args = ["--small", "5", "--images", "2", "--stream", "6", "--output", str(out)]
    done = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "ros1.py"), *args],
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
        cwd=ROOT,
    )
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-4000:]
    doc = json.loads(out.read_text(encoding="utf-8"))
    assert doc["benchmark"] == "ros1"
    for part in ("small_message_round_trip", "image_320x240_round_trip"):
        assert {"direct", "bridged"} == set(doc[part])
        assert doc[part]["bridged"]["n"] > 0 and doc[part]["direct"]["n"] > 0
    stream = doc["image_320x240_stream"]["bridged"]
    assert stream["sent"] == 6 and 0 < stream["received"] <= 6
    assert set(doc["added_by_bridge"]) == {"small_median_ms", "image_median_ms"}
