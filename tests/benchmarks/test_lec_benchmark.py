"""benchmarks/lec.py in its quick mode: the detector's inference per size and batch; training."""

from __future__ import annotations

from pathlib import Path

import pytest
from bench_helpers import load, run


@pytest.mark.slow
def test_lec_benchmark(tmp_path: Path) -> None:
    out = tmp_path / "lec.json"
    # one torch thread, as the suite's processes (two spin beside the other worker)
    args = ["--runs", "2", "--warmup", "1", "--train-images", "8", "--threads", "1"]
    run("lec.py", *args, "--output", str(out))
    doc = load(out)["detector"]
    for size in ("128x128", "320x240"):
        for batch in ("batch1", "batch8"):
            figures = doc["results"][size][batch]
            assert 0 < figures["min_ms_per_frame"] <= figures["median_ms_per_frame"]
    assert doc["training"]["images_per_second"] > 0
