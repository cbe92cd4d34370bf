"""A simulated run is one deterministic program (issue #30): benchmarks/determinism.py runs the
same launch twice, the second time beside a busy process, each ``anunnaki run --speed 0`` in a
process of its own, and finds the same report byte for byte and the same decision log; then
``anunnaki replay`` of the first run reproduces its decisions.

The full check (the rover demo's first 30 s and the whole UAV mission, three times each) is the
script's default; here shorter stretches of both, so the suite stays quick: the rover's here,
the UAV's in tests/benchmarks/test_determinism_uav.py (a file of its own, so that the suite's
two workers, which share out files, can run the two side by side).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from bench_helpers import check_repeats


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_a_run_repeats_itself_quiet_and_loaded(tmp_path: Path) -> None:
    check_repeats(tmp_path, "rover", 9.0)


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
