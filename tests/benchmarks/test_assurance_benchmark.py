"""benchmarks/assurance.py in its quick mode: coverage and build time of both cases."""

from __future__ import annotations

from pathlib import Path

from bench_helpers import load, run


def test_assurance_benchmark(tmp_path: Path) -> None:
    out = tmp_path / "assurance.json"
    run("assurance.py", "--quick", "--output", str(out))
    doc = load(out)
    assert doc["benchmark"] == "assurance"
    assert doc["settings"] == {"repeats": 1, "tests": False, "quick": True}
    assert set(doc["cases"]) == {"rover", "uav"}
    for case in doc["cases"].values():
        cov = case["coverage"]
        assert cov["leaf_goals"] > 0
        assert 0 <= cov["supported"] <= cov["leaf_goals"]
        assert cov["share"] == round(cov["supported"] / cov["leaf_goals"], 4)
        assert case["build_s"]["cli_median"] > case["build_s"]["in_process_median"] > 0
        assert "with_tests" not in case
    assert doc["aims"]["build_s"]["aim"] == 10.0
