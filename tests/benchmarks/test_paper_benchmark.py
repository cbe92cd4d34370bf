"""benchmarks/paper.py: the paper-vs-ours page regenerates, from measurements and files only.

The quick setting runs the rover's rows with the project's own commands on a rendered dataset
of 4 frames per split (the UAV's rows are the same code on another registry; rendering its
dataset here would cost minutes). The figures are not judged; that every one of ours comes
from a measurement (or a file the page names), that the paper's figures are cited, that a
rerun measures nothing again, and what the page says without and with the managers' JSON are.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest
from bench_helpers import run, script_module


@pytest.fixture(scope="module")
def bench() -> Any:
    return script_module("paper.py", "paper_bench")


def _case_studies(path: Path) -> None:
    spread = {"mean": 2.0, "std": 0.5, "min": 1.0, "max": 3.0}
    summary = {
        "degraded_frames": spread,
        "onset_delay_s": {**spread, "p95": 3.0},
        "phases_without_adaptation": 1,
        "phases": 4,
    }
    doc = {
        "date": "2026-11-27 12:00:00",
        "settings": {"seeds": 2, "quick": True},
        "cases": {
            "rover": {
                "launch": "examples/rover/sim.yaml",
                "summary": {"utu": summary, "none": summary},
            }
        },
    }
    path.write_text(json.dumps(doc), encoding="utf-8")


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_quick_page_regenerates_from_measurements(tiny_rover: Path, tmp_path: Path) -> None:
    pytest.importorskip("torch")
    page = tmp_path / "docs" / "results-paper.md"
    work = tmp_path / "work"
    args = [
        "--quick", "--platforms", "rover", "--rover-data", str(tiny_rover),
        "--work", str(work), "--page", str(page),
        "--case-studies", str(tmp_path / "case-studies.json"),
        "--threads", "1",  # as the suite's processes (two spin beside the other worker)
    ]  # fmt: skip
    run("paper.py", *args, timeout=900)
    text = page.read_text(encoding="utf-8")
    assert "benchmarks/paper.py" in text and "Quick setting" in text
    # the paper's figures, each with its section
    for figure, section in (
        ("96.8 %", "§4.1.1"),
        ("2.0 % → 60.7 %", "§4.1.3"),
        ("83.0 %", "§4.1.2"),
    ):
        assert re.search(rf"\| {re.escape(figure)} \| {re.escape(section)}", text), figure
    # ours: the figures the work folder's measurements hold, nothing else
    figures = json.loads((work / "figures.json").read_text(encoding="utf-8"))["figures"]
    assert len(figures) == 6 and all(0.0 <= f["ours"] <= 1.0 for f in figures)
    # raindrops like for like: the paper's one drop, and three drops with visible boxes
    one, three = (f for f in figures if "raindrops" in f["label"])
    assert one["phenomenon"] == "raindrop" and one["paper"] == 0.05
    assert three["phenomenon"] == "raindrop+raindrop+raindrop" and three["paper"] is None
    for row in (one, three):
        assert 0.0 <= row["visible"] <= 1.0 and 0.0 <= row["ceiling"] <= 1.0
        assert 0.0 <= row["visible_robust"] <= 1.0
    assert "visible boxes" in text and "The ceiling" in text
    hsl = next(f for f in figures if "HSL variations" in f["label"])
    assert hsl["robust_model"] == "rover-hsl" and hsl["phenomenon"] == "hsl"
    assert f"{100 * hsl['ours_robust']:.1f} % (`rover-hsl`)" in text
    assert "has not been run" in text and "benchmarks/case_studies.py" in text
    assert (tmp_path / "docs" / "images" / "results-paper-rover.png").stat().st_size > 1000
    assert "](images/results-paper-rover.png)" in text
    # a rerun reuses every measurement, and shows the managers' table once the JSON is there
    _case_studies(tmp_path / "case-studies.json")
    run("paper.py", *args, timeout=900)
    again = page.read_text(encoding="utf-8")
    assert "(0 measurements made, 9 reused" in again
    assert "| degraded_frames | 2.00 ± 0.50 [1–3] | 2.00 ± 0.50 [1–3] |" in again
    assert "| phases not adapted | 1/4 | 1/4 |" in again


def test_a_domain_without_its_model_says_so(bench: Any) -> None:
    fig = next(f for f in bench.PAPER if f.domain == "rain_brightness")
    row = {"ours": 0.25, "phenomenon": "rain+brightness", "model": "uav-default",
           "robust_absent": "no 'rain_brightness' model in examples/models/uav.yaml"}  # fmt: skip
    line = bench.figure_table([(fig, row)], bench.QUICK)[-1]
    assert "27.0 % → 42.0 %" in line and "25.0 %" in line
    assert "not shipped (no 'rain_brightness' model in examples/models/uav.yaml)" in line


def test_every_paper_figure_is_cited(bench: Any) -> None:
    assert len(bench.PAPER) == 10
    assert all(f.cite.startswith("§4.") for f in bench.PAPER if f.paper is not None)
    # ours without a paper figure: the three-drop row, which says the paper has none
    (extra,) = (f for f in bench.PAPER if f.paper is None)
    assert extra.cite.startswith("none") and "three" in extra.label
    assert {f.what for f in bench.PAPER} == {"clean", "domain", "oracle"}


def test_the_managers_table_has_a_row_per_uav_measure(bench: Any, tmp_path: Path) -> None:
    spread = {"mean": 0.5, "std": 0.5, "min": 0.0, "max": 1.0}
    uav = {"delivered": spread, "battery_at_landing": spread, "landings": "home ×1, forced ×1"}
    path = tmp_path / "case-studies.json"
    doc = {
        "date": "2026-11-27 12:00:00",
        "settings": {"seeds": 10},
        "cases": {
            "uav": {
                "launch": "examples/uav/sim.yaml",
                "summary": {"utu": uav, "none": uav},
                "settings": {"seeds": 2, "date": "2026-11-27 14:00:00"},
            }
        },
    }
    path.write_text(json.dumps(doc), encoding="utf-8")
    lines = bench.managers_section(path)
    assert "**uav** (`examples/uav/sim.yaml`; 2 seed(s), 2026-11-27 14:00:00)" in lines
    assert "| delivered | 0.50 ± 0.50 [0–1] | 0.50 ± 0.50 [0–1] |" in lines
    assert "| battery_at_landing | 0.50 ± 0.50 [0–1] | 0.50 ± 0.50 [0–1] |" in lines
    assert "| landings | home ×1, forced ×1 | home ×1, forced ×1 |" in lines
