"""benchmarks/raindrop.py's quick mode: raindrops on all and on visible boxes, and the demo."""

from __future__ import annotations

from pathlib import Path

import pytest
from bench_helpers import load, run


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_quick_mode_writes_all_and_visible_figures(tiny_rover: Path, tmp_path: Path) -> None:
    pytest.importorskip("torch")
    out = tmp_path / "raindrop.json"
    run("raindrop.py", "--quick", "--data", str(tiny_rover), "--out", str(out), timeout=900)
    doc = load(out)
    assert doc["quick"] and doc["hidden_threshold"] == 0.5
    one, three = doc["contexts"]["one drop"], doc["contexts"]["three drops"]
    assert one["phenomenon"] == "raindrop"
    assert three["phenomenon"] == "raindrop+raindrop+raindrop"
    for row in (one, three):
        for model in ("rover-default", "rover-raindrop"):
            m = row[model]
            for key in ("f1", "f1_visible", "ceiling_f1", "hidden_share", "clean"):
                assert 0.0 <= m[key] <= 1.0, (model, key)
    (swapped,) = doc["demo"].values()  # quick: the run with rover-raindrop as the default
    assert swapped["phases"] and "f1" in swapped["phases"][0]
    assert swapped["phases"][0]["models"] == ["rover-raindrop"]
