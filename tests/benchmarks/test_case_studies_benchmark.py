"""benchmarks/case_studies.py in its quick mode: the rover demo's first 14 s under each manager.

(The UAV's quick case is tests/benchmarks/test_case_studies_uav.py, a file of its own so
that the suite's two workers run them side by side; ``--merge`` is tested here.)

The shortened rover scenario (clear, then the HSL shift from about 8.4 s): Utu swaps in the
HSL model and its postcondition (G9: the oracle finds the robust model nominal in the shift)
holds; ``none`` leaves the default model degraded, so it drives more frames with a model in
category >= 1 (the documented measure: docs/whole-loop.md, "Managers compared").
"""

from __future__ import annotations

from pathlib import Path

import pytest
from bench_helpers import check_after_degraded, load, run, script_module


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_case_studies_benchmark(tmp_path: Path) -> None:
    out = tmp_path / "case-studies.json"
    run("case_studies.py", "--quick", "--cases", "rover", "--output", str(out), timeout=840)
    doc = load(out)
    assert doc["settings"] == {
        "seeds": 1,
        "until": None,
        "quick": True,
        "managers": ["utu", "none", "random"],
    }
    rover = doc["cases"]["rover"]
    assert rover["launch"] == "examples/rover/demo.yaml"
    assert rover["settings"]["until"] == 14.0 and rover["settings"]["scenario"] == "the launch's"
    runs = {r["manager"]: r for r in rover["runs"]}
    assert set(runs) == {"utu", "none", "random"}
    for r in runs.values():
        assert r["simulated_s"] == pytest.approx(14.0, abs=0.11) and r["frames"] >= 130
        assert [p["phase"] for p in r["onset_delays"]] == ["hsl"]
        assert r["distance_m"] > 0 and r["final_mode"] in ("autonomous", "manual", "stopped")
        # the misses' companion: metres driven autonomously, misses per 10 of them
        assert 0 <= r["autonomous_m"] <= r["distance_m"] + 0.05
        if r["autonomous_m"] > 0:
            # from the unrounded metres: within what rounding them to 0.01 m allows
            misses, metres = r["pedestrian_misses"], r["autonomous_m"]
            low, high = 10 * misses / (metres + 0.005), 10 * misses / max(metres - 0.005, 1e-9)
            assert low - 0.0005 <= r["misses_per_10_autonomous_m"] <= high + 0.0005, r
    utu, none = runs["utu"], runs["none"]
    # the adaptation happened, in the HSL phase, and its postcondition held
    swap = next(a for a in utu["adaptations"] if a["tactic"] == "swap-to-hsl-model")
    assert swap["postcondition"] == "ok", utu
    assert utu["onset_delays"][0]["delay_s"] is not None
    check_after_degraded(utu["onset_delays"][0])
    assert none["adaptations"] == [] and none["decisions"] == 0
    assert none["onset_delays"][0]["delay_s"] is None
    assert none["onset_delays"][0]["after_degraded_s"] is None
    assert (
        none["onset_delays"][0]["degraded_at"] is not None
    )  # the default model, left in the shift
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
        assert s["after_degraded_s"].keys() >= {"mean", "std", "min", "max", "p95"}


def _run(manager: str, seed: int, degraded: int) -> dict[str, object]:
    return {"manager": manager, "seed": seed, "degraded_frames": degraded, "onset_delays": []}


def test_merge_keeps_other_cases_and_other_managers_runs(tmp_path: Path) -> None:
    cs = script_module("case_studies.py", "case_studies_merge")
    measures = ("degraded_frames",)
    cs.measures_of = lambda case: measures  # the synthetic runs carry one measure
    out = tmp_path / "case-studies.json"

    def doc(
        manager: str, degraded: list[int], case: str = "uav", first: int = 0
    ) -> dict[str, object]:
        runs = [_run(manager, first + i, d) for i, d in enumerate(degraded)]
        return {
            "settings": {"managers": [manager]},
            "cases": {
                case: {
                    "runs": runs,
                    "summary": {manager: cs.summarise(runs, measures)},
                    "settings": {"managers": [manager]},
                }
            },
        }

    cs.write(doc("utu", [3, 5], case="rover"), out, merge=True)  # a new file: written as is
    cs.write(doc("random", [8, 9]), out, merge=True)
    cs.write(doc("utu", [1, 2]), out, merge=True)
    cs.write(doc("utu", [2, 4]), out, merge=True)  # the same seeds again: replaces their runs
    merged = load(out)
    assert merged["cases"]["rover"]["summary"]["utu"]["degraded_frames"]["mean"] == 4.0
    uav = merged["cases"]["uav"]
    assert [(r["manager"], r["seed"]) for r in uav["runs"]] == [
        ("utu", 0),
        ("utu", 1),
        ("random", 0),
        ("random", 1),
    ]
    assert uav["settings"]["managers"] == ["utu", "random"]
    assert uav["summary"]["utu"]["degraded_frames"]["mean"] == 3.0
    assert uav["summary"]["random"]["degraded_frames"]["mean"] == 8.5
    cs.write(doc("random", [10], first=2), out, merge=True)  # more seeds, from another process
    uav = load(out)["cases"]["uav"]
    assert [r["seed"] for r in uav["runs"] if r["manager"] == "random"] == [0, 1, 2]
    assert uav["settings"]["seeds"] == 3
    assert uav["summary"]["random"]["degraded_frames"]["mean"] == 9.0
    cs.write(doc("none", [7]), out, merge=False)  # without --merge the file is replaced
    assert set(load(out)["cases"]) == {"uav"}


def test_with_merge_each_run_is_saved_as_it_ends(tmp_path: Path) -> None:
    import argparse

    cs = script_module("case_studies.py", "case_studies_save")
    figures: dict[str, object] = {m: 2 for m in cs.measures_of(cs.CASES["rover"])}
    figures |= {"frames": 10, "wall_s": 1.0, "final_mode": "manual"}
    figures |= {"onset_delays": [{"delay_s": 0.5}]}

    def run_once(case: object, manager: str, seed: int, *rest: object) -> dict[str, object]:
        return {"manager": manager, "seed": seed, **figures}

    cs.run_once = run_once  # the runs themselves are the quick test's
    saved: list[dict[str, object]] = []
    args = argparse.Namespace(until=None, quick=False, first_seed=0)
    rover = cs.CASES["rover"]
    done = cs.run_case(rover, "rover", args, ["utu", "none"], 2, tmp_path, saved.append)
    assert [len(e["runs"]) for e in saved] == [1, 2, 3, 4]
    both = ["utu", "none"]
    assert [e["settings"]["managers"] for e in saved] == [["utu"], ["utu"], both, both]
    assert done["summary"]["none"]["degraded_frames"]["mean"] == 2.0
    assert done["summary"]["utu"]["onset_delay_s"]["p95"] == 0.5
