"""The latency benchmark runs and writes its figures (tiny run; the real one is by hand)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("zenoh")
SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "bus_pingpong.py"


@pytest.mark.slow
def test_bus_pingpong_writes_results(tmp_path: Path) -> None:
    out = tmp_path / "bus.json"
    result = subprocess.run(
        [sys.executable, str(SCRIPT), "--rounds", "20", "--warmup", "5", "--repeats", "1",
         "--out", str(out)],
        capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    doc = json.loads(out.read_text())
    assert set(doc["results"]) == {"inproc", "zenoh", "zenoh-2proc"}
    for setup in doc["results"].values():
        for kind in ("pubsub_rtt_us", "request_reply_us"):
            figures = setup[kind]
            assert figures["n"] == 20
            assert 0 < figures["p50"] <= figures["p90"] <= figures["p99"]
