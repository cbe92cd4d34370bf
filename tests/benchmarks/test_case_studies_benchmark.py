"""benchmarks/case_studies.py in its quick mode: the rover demo's first 14 s under each manager.

The shortened rover scenario (clear, then the HSL shift from about 8.4 s): Utu swaps in the
HSL model and its postcondition (G9: the oracle finds the robust model nominal in the shift)
holds; ``none`` leaves the default model degraded, so it drives more frames with a model in
category >= 1 (the documented measure: docs/whole-loop.md, "Managers compared").
"""

from __future__ import annotations

from pathlib import Path

import pytest
from bench_helpers import load, run


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_case_studies_benchmark(tmp_path: Path) -> None:
    out = tmp_path / "case-studies.json"
    run("case_studies.py", "--quick", "--output", str(out), timeout=840)
    doc = load(out)
    assert doc["settings"] == {
        "seeds": 1,
        "until": 14.0,
        "quick": True,
        "managers": ["utu", "none", "random"],
    }
    rover = doc["cases"]["rover"]
    assert rover["launch"] == "examples/rover/demo.yaml"
    runs = {r["manager"]: r for r in rover["runs"]}
    assert set(runs) == {"utu", "none", "random"}
    for r in runs.values():
        assert r["simulated_s"] == pytest.approx(14.0, abs=0.11) and r["frames"] >= 130
        assert [p["phase"] for p in r["onset_delays"]] == ["hsl"]
        assert r["distance_m"] > 0 and r["final_mode"] in ("autonomous", "manual", "stopped")
        # the misses' companion: metres driven autonomously, misses per 10 of them
        assert 0 <= r["autonomous_m"] <= r["distance_m"] + 0.05
        if r["autonomous_m"] > 0:
            expected = 10 * r["pedestrian_misses"] / r["autonomous_m"]
            assert r["misses_per_10_autonomous_m"] == pytest.approx(expected, abs=0.01)
    utu, none = runs["utu"], runs["none"]
    # the adaptation happened, in the HSL phase, and its postcondition held
    swap = next(a for a in utu["adaptations"] if a["tactic"] == "swap-to-hsl-model")
    assert swap["postcondition"] == "ok", utu
    assert utu["onset_delays"][0]["delay_s"] is not None
    assert none["adaptations"] == [] and none["decisions"] == 0
    assert none["onset_delays"][0]["delay_s"] is None
    # none is worse on the documented measure
    assert none["degraded_frames"] > utu["degraded_frames"], (none, utu)
    summary = rover["summary"]
    assert set(summary) == {"utu", "none", "random"}
    for s in summary.values():
        assert set(s) >= {
            "degraded_frames",
            "pedestrian_misses",
            "misses_per_10_autonomous_m",
            "autonomous_m",
            "collisions",
            "false_alarms",
        }
        assert s["onset_delay_s"].keys() >= {"mean", "std", "min", "max", "p95"}
