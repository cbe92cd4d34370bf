"""The criteria file: checked, and every mistake named with file, line and element."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from anunnaki.assurance import build_case, load_criteria
from anunnaki.errors import ModelFileError

ROOT = Path(__file__).resolve().parents[2]
UAV = ROOT / "examples" / "uav" / "sim.yaml"


def _criteria(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "assurance.yaml"
    path.write_text("anunnaki: assurance/1\nevidence:\n" + body, encoding="utf-8")
    return path


def test_the_shipped_criteria_files_load() -> None:
    for case in ("rover", "uav"):
        crit = load_criteria(ROOT / "examples" / case / "assurance.yaml")
        assert crit.case == case and crit.evidence


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("  G6:\n    - kind: detector\n", "give exactly one acceptance criterion"),
        ("  G6:\n    - kind: detector\n      at_least: 1\n      at_most: 2\n", "exactly one"),
        ("  G6:\n    - kind: sorcery\n      at_least: 1\n", "evidence.G6[0].kind"),
        ("  G6:\n    - kind: result\n      at_least: 1\n", "needs 'file'"),
        ("  G6:\n    - kind: tests\n      tests: [a]\n      at_least: 1\n", "drop the criterion"),
        ("  G6:\n    - kind: detector\n      at_least: 1\n      colour: red\n", "unknown field"),
    ],
)
def test_a_bad_item_is_refused_with_its_line(tmp_path: Path, body: str, message: str) -> None:
    path = _criteria(tmp_path, body)
    with pytest.raises(ModelFileError) as err:
        load_criteria(path)
    assert message in str(err.value)
    assert f"{path}:" in str(err.value)


def test_not_a_criteria_file(tmp_path: Path) -> None:
    path = tmp_path / "x.yaml"
    path.write_text("anunnaki: goal-model/1\n", encoding="utf-8")
    with pytest.raises(ModelFileError, match="not an assurance criteria file"):
        load_criteria(path)


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("  G66:\n    - kind: detector\n      at_least: 0.9\n", "did you mean 'G6'"),
        (
            "  G6:\n    - kind: detector\n      models: [uav-nope]\n      at_least: 0.9\n",
            "the launch's registry has no model 'uav-nope'",
        ),
        (
            "  G6:\n    - kind: result\n      file: benchmarks/results/case-studies.json\n"
            "      path: cases.uav.nope\n      text: t\n      at_least: 0\n",
            "has no 'cases.uav.nope'",
        ),
        (
            "  G6:\n    - kind: result\n      file: benchmarks/results/none.json\n"
            "      path: a\n      text: t\n      at_least: 0\n",
            "does not exist",
        ),
        ("  G7:\n    - kind: detector\n      relax: true\n", "no RELAX operator"),
        (
            "  G6:\n    - kind: result\n      file: benchmarks/results/case-studies.json\n"
            "      path: cases.uav.launch\n      text: t\n      at_least: 0\n",
            "not a number",
        ),
    ],
)
def test_evidence_that_cannot_be_found_names_the_item(
    tmp_path: Path, body: str, message: str
) -> None:
    path = _criteria(tmp_path, body)
    with pytest.raises(ModelFileError) as err:
        build_case(UAV, criteria=path, root=ROOT)
    assert message in str(err.value)
    assert str(path) in str(err.value) and "evidence.G" in str(err.value)


def test_tests_run_with_run_tests_support_or_fail_their_goal(tmp_path: Path) -> None:
    tests = tmp_path / "tests"
    tests.mkdir()
    (tests / "test_probe.py").write_text(
        "def test_holds():\n    assert True\n\n\ndef test_breaks():\n    assert False\n",
        encoding="utf-8",
    )
    path = _criteria(
        tmp_path,
        "  G7:\n    - kind: tests\n      tests: [tests/test_probe.py::test_holds]\n"
        "  G10:\n    - kind: tests\n      tests: [tests/test_probe.py::test_holds, "
        "tests/test_probe.py::test_breaks]\n",
    )
    unrun = build_case(UAV, criteria=path, root=tmp_path)
    assert unrun.nodes["Sn-G7-1"].status == "unverified"
    case = build_case(UAV, criteria=path, root=tmp_path, tests=True)
    assert case.nodes["Sn-G7-1"].status == "supported"
    assert case.nodes["G7"].status == "supported"
    sn = case.nodes["Sn-G10-1"]
    assert sn.status == "failed" and sn.evidence is not None
    assert sn.evidence.figure.startswith("1 of 2 tests pass")
    assert {a.role for a in sn.evidence.artefacts} == {"tests"}


def test_a_build_imports_no_ml_framework() -> None:
    code = (
        "import sys\nfrom anunnaki.assurance import build_case\n"
        f"build_case({str(ROOT / 'examples/rover/demo.yaml')!r}, root={str(ROOT)!r})\n"
        "print(sorted(m for m in ('torch', 'cv2', 'pybullet', 'fastapi') if m in sys.modules))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"


def test_criteria_for_another_goal_model_are_refused_or_left_out() -> None:
    launch = ROOT / "examples/rover/utu.yaml"  # the rover's goals.yaml, not goals-lm.yaml
    criteria = ROOT / "examples/rover/assurance.yaml"
    with pytest.raises(ModelFileError) as err:
        build_case(launch, criteria=criteria, root=ROOT)
    assert "the criteria develop goals-lm.yaml, but the launch's goal model is goals.yaml" in str(
        err.value
    )
    assert f"{criteria}: goal_model:" in str(err.value)
    # found beside the launch only: left out, and the case says so
    case = build_case(launch, root=ROOT)
    assert case.solutions() == []
    (note,) = case.notes
    assert note.startswith("examples/rover/assurance.yaml develops examples/rover/goals-lm.yaml")
    assert case.coverage()["supported"] == 0
