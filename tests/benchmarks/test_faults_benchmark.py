"""benchmarks/faults.py, shortened: one kill -9 per deployment and the hostile corpus.

What must hold is asserted (counts and outcomes, never times): nothing the platform
published well before the kill is missing from knowledge, nothing printed is missing from
it, the run replays identically, the platform is stopped one way or another, and the corpus
raises no traceback, kills no loop and changes no decision.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from bench_helpers import load, run

pytest.importorskip("zenoh")


@pytest.mark.slow
def test_faults_benchmark_shortened(tmp_path: Path) -> None:
    out = tmp_path / "faults.json"
    args = ["--quick", "--victims", "analyze", "manager", "--skip", "flood"]
    args += ["--corpus", "processes", "--deadline", "1.5", "--output", str(out)]
    run("faults.py", *args, timeout=360)
    doc = load(out)

    trials = doc["kill_trials"]
    assert [(t["deployment"], t["victim"]) for t in trials] == [
        ("processes", "analyze"),
        ("one-process", "manager"),
        ("by-hand", "analyze"),
    ]
    for t in trials:
        assert "error" not in t, t
        assert t["inputs_expected"] > 0
        if t["deployment"] == "by-hand":  # no launch: a survivor run-stops, once
            assert t["decisions_printed"] == 0  # nodes by hand print no decisions
            assert (t["failsafe_command"], t["platform_stops"]) == ("stop", 1), t
        else:
            assert t["decisions_printed"] > 0  # a hand-over happened
        assert (t["lost_inputs"], t["lost_decisions"]) == (0, 0), t
        if t["deployment"] != "processes" or t["replay_identical"]:
            assert t["replay_identical"], t.get("replay_note")
        else:
            # Known (docs/results.md, "Faults"): under heavy load a per-node run may record
            # its start-up hand-over a step later than a replay of the same inputs makes it.
            # Anything else is a regression.
            assert t["replay_note"].startswith("diverged at decision #0"), t["replay_note"]
        # Stopped: by Utu's fail-safe or run-stop, or else by the platform's own guard.
        assert t["failsafe_command"] in ("set_mode manual", "stop", "/utu/run_stop", None)
        assert t["failsafe_command"] is not None or t["guard_ms"] is not None, t

    corpus = doc["corpus"]
    (per_node,) = corpus["deployments"]
    assert per_node["deployment"] == "processes"
    assert per_node["sent"] == 45
    assert (per_node["tracebacks"], per_node["loop_deaths"], per_node["steered"]) == (0, 0, 0)
    assert per_node["refused"] >= 30  # every malformed one at least (6 on each of 5 topics)
