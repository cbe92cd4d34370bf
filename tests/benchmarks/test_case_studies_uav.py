"""benchmarks/case_studies.py in its quick mode on the UAV: a short delivery under Utu and none.

(``random`` is the rover's quick test's: its choice among the tactics does not depend on the
platform, and a UAV run costs a minute of the suite.)

The quick UAV mission (``CASES["uav"].quick``: 26 s at most, out 48 m east, fog from 3 s, a
36 % battery draining 1.5 %/s more from 2 s): under Utu the fog swap happens and its
postcondition holds, the battery forecast at home (G15) fails at about 5 s and
``return-home`` brings the UAV home with about a fifth of its battery; under ``none`` the
battery obstacle is not handled: the UAV delivers, flies on below O2's 20 % and the empty
battery forces it down before home (the documented measures: docs/uav.md, "Managers
compared").
"""

from __future__ import annotations

from pathlib import Path

import pytest
from bench_helpers import check_after_degraded, load, run


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_case_studies_uav_quick(tmp_path: Path) -> None:
    out = tmp_path / "case-studies.json"
    args = ["--quick", "--cases", "uav", "--managers", "utu,none", "--output", str(out)]
    run("case_studies.py", *args, timeout=840)
    doc = load(out)
    uav = doc["cases"]["uav"]
    assert set(doc["cases"]) == {"uav"} and uav["launch"] == "examples/uav/sim.yaml"
    assert uav["settings"]["scenario"] == "quick" and uav["settings"]["until"] is None
    runs = {r["manager"]: r for r in uav["runs"]}
    assert set(runs) == {"utu", "none"}
    for r in runs.values():
        assert [p["phase"] for p in r["onset_delays"]] == ["fog"]
        assert r["landing"] in ("home", "elsewhere", "forced", "airborne", "ground")
        assert "collisions" not in r and "pedestrian_misses" not in r  # rover measures
    utu, none = runs["utu"], runs["none"]
    # the adaptations happened and their postconditions held
    outcome = {a["tactic"]: a["postcondition"] for a in utu["adaptations"]}
    assert outcome.get("swap-to-robust-model") == "ok", utu
    assert outcome.get("return-home") == "ok", utu
    assert utu["onset_delays"][0]["delay_s"] is not None
    check_after_degraded(utu["onset_delays"][0])
    assert utu["false_alarms"] == 0
    # the run ends at the touch-down: at home, with battery in hand
    assert utu["landing"] == "home" and utu["landed_home"] == 1
    assert utu["battery_at_landing"] >= 10.0 and utu["low_battery_s"] == 0.0
    assert utu["mission_time_s"] == pytest.approx(utu["simulated_s"], abs=0.5)
    # none is worse on the documented measure: the battery obstacle is not handled
    assert none["adaptations"] == [] and none["decisions"] == 0
    assert none["delivered"] == 1  # what Utu trades away
    assert none["landing"] in ("forced", "elsewhere"), none
    assert none["battery_at_landing"] < utu["battery_at_landing"]
    assert none["low_battery_s"] > utu["low_battery_s"]
    assert none["degraded_frames"] > utu["degraded_frames"]
    summary = uav["summary"]
    assert set(summary) == {"utu", "none"}
    for s in summary.values():
        assert set(s) >= {"delivered", "battery_at_landing", "mission_time_s", "false_alarms"}
        assert s["onset_delay_s"].keys() >= {"mean", "std", "min", "max", "p95"}
        assert s["after_degraded_s"].keys() >= {"mean", "std", "min", "max", "p95"}
    assert summary["utu"]["landings"] == "home ×1"
