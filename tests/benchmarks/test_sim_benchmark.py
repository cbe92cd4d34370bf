"""benchmarks/sim.py in its quick mode: rendering and platform rates of both platforms."""

from __future__ import annotations

from pathlib import Path

import pytest
from bench_helpers import load, run


@pytest.mark.slow
def test_sim_benchmark(tmp_path: Path) -> None:
    out = tmp_path / "sim.json"
    run("sim.py", "--frames", "4", "--repeats", "1", "--output", str(out))
    doc = load(out)
    assert doc["benchmark"] == "sim"
    assert set(doc["platforms"]) == {"rover", "uav"}
    for entry in doc["platforms"].values():
        assert entry["build_s"] > 0
        for size in ("128x128", "320x240"):
            assert entry[size]["render_fps"] > 0
            assert entry[size]["platform_fps"] > 0
