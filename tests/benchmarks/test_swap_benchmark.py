"""benchmarks/swap.py in its quick mode: model swaps, cold and cached, lose and reorder no frame."""

from __future__ import annotations

from pathlib import Path

import pytest
from bench_helpers import load, run


@pytest.mark.slow
def test_swap_benchmark(tmp_path: Path) -> None:
    out = tmp_path / "swap.json"
    run("swap.py", "--rounds", "2", "--output", str(out))
    doc = load(out)
    for mode in ("cold", "cached"):
        result = doc["results"][mode]
        assert result["swaps"] == 2
        assert result["frames"] == result["detections"] > 0
        assert result["every_frame_once_in_order"] is True
        assert result["monotone_switches"] is True
        assert result["first_detection_ms"]["n"] == 2
