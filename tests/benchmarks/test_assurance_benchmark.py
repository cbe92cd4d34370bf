"""benchmarks/assurance.py in its quick mode: coverage and build time of both cases."""

from __future__ import annotations

from pathlib import Path

from bench_helpers import load, run

ROOT = Path(__file__).resolve().parents[2]


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


def test_the_shipped_cases_are_reproducible(tmp_path: Path) -> None:
    """``--ship`` (make results): the same inputs give the same bytes; no time, no folder."""
    run("assurance.py", "--ship", str(tmp_path / "a"))
    run("assurance.py", "--ship", str(tmp_path / "b"))
    for name in ("rover", "uav"):
        files = sorted(p.name for p in (tmp_path / "a" / name).iterdir())
        assert files == ["case.gsn.yaml", "case.html", "case.json", "case.svg"]
        for f in files:
            a = (tmp_path / "a" / name / f).read_bytes()
            assert a == (tmp_path / "b" / name / f).read_bytes(), f"{name}/{f}"
            assert str(tmp_path).encode() not in a and str(ROOT).encode() not in a
        doc = load(tmp_path / "a" / name / "case.json")
        assert (doc["built"], doc["build_seconds"], doc["project_root"]) == ("", None, ".")
        # the committed case is in the same form (make results writes docs/assurance/)
        shipped = load(ROOT / "docs" / "assurance" / name / "case.json")
        assert (shipped["built"], shipped["project_root"]) == ("", ".")
