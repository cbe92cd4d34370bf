"""benchmarks/enlil_search.py in its quick mode: Enlil's search beside random and Sobol."""

from __future__ import annotations

from pathlib import Path

import pytest
from bench_helpers import load, run


@pytest.mark.slow
def test_enlil_search_benchmark(tmp_path: Path, tiny_rover: Path) -> None:
    out = tmp_path / "enlil_search.json"
    args = ["--data", str(tiny_rover), "--budget", "6", "--checkpoints", "3,6"]
    run("enlil_search.py", *args, "--batch-images", "2", "--workers", "1", "--out", str(out))
    doc = load(out)
    assert doc["budget"] == 6 and doc["phenomenon"] == "hsl" and doc["aim"] == 1.5
    assert set(doc["searches"]) == {"enlil", "random", "sobol"}
    for search in doc["searches"].values():
        assert set(search["cells"]) == {"3", "6"}
        assert sum(search["counts"].values()) == 6  # every evaluation has a category
    assert set(doc["enlil_over_random_category1_cells"]) == {"3", "6"}
