"""A simulated run is one deterministic program (issue #30): benchmarks/determinism.py runs the
same launch twice, the second time beside a busy process, each ``anunnaki run --speed 0`` in a
process of its own, and finds the same report byte for byte and the same decision log; then
``anunnaki replay`` of the first run reproduces its decisions.

The full check (the rover demo's first 30 s and the whole UAV mission, three times each) is the
script's default; here shorter stretches of both, so the suite stays quick.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from bench_helpers import load, run


@pytest.mark.slow
@pytest.mark.timeout(600)
@pytest.mark.parametrize(("case", "until"), [("rover", 9.0), ("uav", 11.0)])
def test_a_run_repeats_itself_quiet_and_loaded(tmp_path: Path, case: str, until: float) -> None:
    out = tmp_path / "determinism.json"
    args = ["--cases", case, "--runs", "2", "--until", str(until), "--output", str(out)]
    run("determinism.py", *args, timeout=560)
    doc = load(out)
    assert set(doc["cases"]) == {case}
    c = doc["cases"][case]
    assert c["until"] == until and [r["beside_busy"] for r in c["runs"]] == [False, True]
    quiet, loaded = c["runs"]
    assert quiet["simulated_s"] == pytest.approx(until, abs=0.2)
    assert quiet["decisions"] > 0, "the stretch should decide something"
    assert loaded["log_sha256"] == quiet["log_sha256"]  # the same decisions at the same times
    assert loaded["report_sha256"] == quiet["report_sha256"]  # the same report, byte for byte
    assert c["identical_reports"] is True and c["identical_logs"] is True
    assert c["replay_exit_code"] == 0, c["replay"]  # `anunnaki replay` of the run


def test_the_case_studies_check_compares_runs_not_the_machine() -> None:
    """``--case-studies`` compares the managers benchmark's tables without what measures the
    machine (wall seconds, load averages, the date), and nothing else is left out."""
    from bench_helpers import script_module

    determinism = script_module("determinism.py", "determinism_bench")
    one = {
        "rover": {
            "runs": [{"seed": 0, "degraded_frames": 25, "wall_s": 25.1}],
            "settings": {"load_average": [[4.2, 6.7, 7.6]], "managers": ["utu"]},
        }
    }
    loaded = {
        "rover": {
            "runs": [{"seed": 0, "degraded_frames": 25, "wall_s": 40.3}],
            "settings": {"load_average": [[9.0, 8.1, 7.7]], "managers": ["utu"]},
        }
    }
    other = {"rover": {**loaded["rover"], "runs": [{"seed": 0, "degraded_frames": 26}]}}
    facts = determinism.run_facts
    assert facts(one) == facts(loaded)
    assert facts(one) != facts(other)
    assert facts(one)["rover"]["settings"] == {"managers": ["utu"]}
