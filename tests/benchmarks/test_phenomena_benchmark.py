"""benchmarks/phenomena.py in its quick mode: every phenomenon's cost at both image sizes."""

from __future__ import annotations

from pathlib import Path

from bench_helpers import ROOT, load, run

from anunnaki.phenomena import PHENOMENA


def test_phenomena_benchmark(tmp_path: Path) -> None:
    output = tmp_path / "bench.json"
    run("phenomena.py", "--runs", "2", "--warmup", "0", "--output", str(output), timeout=120)
    report = load(output)
    assert set(PHENOMENA.names()) <= set(report["results"])
    for sizes in report["results"].values():
        assert set(sizes) == {"128x128", "320x240"}
        assert all(entry["median_ms"] > 0 for entry in sizes.values())
    doc = (ROOT / "docs" / "phenomena.md").read_text(encoding="utf-8")
    assert "benchmarks/results/phenomena.json" in doc
