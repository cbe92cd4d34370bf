"""benchmarks/bus_pingpong.py: the bus latency benchmark runs and writes its figures (tiny run)."""

from __future__ import annotations

from pathlib import Path

import pytest
from bench_helpers import load, run

pytest.importorskip("zenoh")


@pytest.mark.slow
def test_bus_pingpong_writes_results(tmp_path: Path) -> None:
    out = tmp_path / "bus.json"
    args = ["--rounds", "20", "--warmup", "5", "--repeats", "1", "--out", str(out)]
    run("bus_pingpong.py", *args, timeout=120)
    doc = load(out)
    assert set(doc["results"]) == {"inproc", "zenoh", "zenoh-2proc"}
    for setup in doc["results"].values():
        for kind in ("pubsub_rtt_us", "request_reply_us"):
            figures = setup[kind]
            assert figures["n"] == 20
            assert 0 < figures["p50"] <= figures["p90"] <= figures["p99"]
