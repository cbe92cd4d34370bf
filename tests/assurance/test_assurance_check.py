"""Stale evidence: an artefact whose sha256 changed since the figure was measured."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from anunnaki.assurance import build_case, check_case, read_case, write_case
from anunnaki.cli.main import main

ROOT = Path(__file__).resolve().parents[2]

CRITERIA = """\
anunnaki: assurance/1
case: uav-copy
evidence:
  G6:
    - kind: detector
      models: [uav-default]
      at_least: 0.9
  G10:
    - kind: result
      file: benchmarks/results/case-studies.json
      path: cases.uav.summary.utu.landed_home.min
      text: landed at home under Utu, every seed
      equals: 1
      rests_on: [tactics]
"""


@pytest.fixture
def project(tmp_path: Path) -> Path:
    """A copy of the UAV's launch, its models and the results file the criteria read."""
    shutil.copytree(ROOT / "examples" / "uav", tmp_path / "examples" / "uav")
    models = tmp_path / "examples" / "models"
    models.mkdir()
    for f in (ROOT / "examples" / "models").glob("uav*"):
        shutil.copy(f, models / f.name)
    (tmp_path / "benchmarks" / "results").mkdir(parents=True)
    shutil.copy(ROOT / "benchmarks/results/case-studies.json", tmp_path / "benchmarks/results")
    (tmp_path / "examples/uav/assurance.yaml").write_text(CRITERIA, encoding="utf-8")
    return tmp_path


def _build(project: Path, **kw: object) -> object:
    return build_case(project / "examples/uav/sim.yaml", root=project, **kw)  # type: ignore[arg-type]


def test_a_model_changed_after_the_build_makes_its_evidence_stale(project: Path) -> None:
    case = _build(project)
    write_case(case, project / "case")  # type: ignore[arg-type]
    assert case.nodes["Sn-G6-1"].status == "supported"  # type: ignore[attr-defined]
    # G6 is obstructed by O1, whose detection has no evidence here: undeveloped, not supported
    assert case.nodes["G6"].status == "undeveloped"  # type: ignore[attr-defined]
    assert check_case(read_case(project / "case")) == []

    weights = project / "examples/models/uav-default.safetensors"
    original = weights.read_bytes()
    weights.write_bytes(original + b"\0")  # re-trained, as far as any hash can tell
    again = read_case(project / "case")
    changes = check_case(again)
    assert [(c.node, c.role) for c in changes] == [("Sn-G6-1", "model:uav-default")]
    sn = again.nodes["Sn-G6-1"]
    assert sn.status == "stale"
    assert sn.evidence is not None and "uav-default.safetensors changed" in (
        sn.evidence.stale or ""
    )
    assert again.nodes["G6"].status == "stale"  # stale outranks undeveloped below it

    weights.write_bytes(original)  # put back: nothing is stale
    assert check_case(read_case(project / "case")) == []


def test_a_fresh_build_on_changed_weights_is_stale_at_once(project: Path) -> None:
    """The sidecar records the weights its F1 was measured on."""
    weights = project / "examples/models/uav-default.safetensors"
    weights.write_bytes(weights.read_bytes() + b"\0")
    case = _build(project)
    sn = case.nodes["Sn-G6-1"]  # type: ignore[attr-defined]
    assert sn.status == "stale"
    assert "measured on 7bea1b958f97" in sn.evidence.stale


def test_a_rebuild_over_the_prior_case_finds_what_changed_since(project: Path) -> None:
    write_case(_build(project), project / "case")  # type: ignore[arg-type]
    tactics = project / "examples/uav/tactics.yaml"
    tactics.write_text(tactics.read_text(encoding="utf-8") + "# edited\n", encoding="utf-8")
    # the campaign's results file is unchanged, but the tactics it ran are not
    case = _build(project, prior=read_case(project / "case"))
    sn = case.nodes["Sn-G10-1"]  # type: ignore[attr-defined]
    assert sn.status == "stale"
    assert "tactics.yaml changed since the figure was measured" in sn.evidence.stale
    assert case.nodes["Sn-G6-1"].status == "supported"  # type: ignore[attr-defined]
    # without the prior case there is nothing to compare with
    assert _build(project).nodes["Sn-G10-1"].status == "supported"  # type: ignore[attr-defined]


def test_cli_check_exits_1_on_a_stale_artefact_and_names_it(
    project: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(project)
    out = project / "case"
    code = main(["assurance", "build", "examples/uav/sim.yaml", "--out", str(out)])
    assert code == 1  # G1 has no evidence here: not supported
    assert {p.name for p in out.iterdir()} == {
        "case.json",
        "case.gsn.yaml",
        "case.svg",
        "case.html",
    }
    assert main(["assurance", "check", str(out)]) == 0
    capsys.readouterr()
    (project / "benchmarks/results/case-studies.json").write_text("{}", encoding="utf-8")
    assert main(["assurance", "check", str(out), "--update"]) == 1
    text = capsys.readouterr().out
    assert "stale Sn-G10-1: results benchmarks/results/case-studies.json" in text
    assert "claims no longer supported: " in text and "G10" in text
    assert read_case(out).nodes["Sn-G10-1"].status == "stale"
    assert "STALE" in (out / "case.html").read_text(encoding="utf-8")


def test_cli_check_of_a_folder_without_a_case_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["assurance", "check", str(tmp_path)]) == 2
    assert "no assurance case here" in capsys.readouterr().err


def test_a_changed_goal_model_is_reported_as_the_argument_to_rebuild(
    project: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(project)
    out = project / "case"
    main(["assurance", "build", "examples/uav/sim.yaml", "--out", str(out)])
    goals = project / "examples/uav/goals.yaml"
    goals.write_text(goals.read_text(encoding="utf-8") + "# edited\n", encoding="utf-8")
    changes = check_case(read_case(out))
    assert [(c.node, c.role) for c in changes] == [("(argument)", "goal_model")]
    capsys.readouterr()
    assert main(["assurance", "check", str(out)]) == 1
    text = capsys.readouterr().out
    assert "the argument: goal_model examples/uav/goals.yaml was " in text
    assert "build it again (examples/uav/sim.yaml)" in text


def test_a_case_built_elsewhere_is_checked_against_the_working_folder(
    project: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    case = _build(project)
    case.project_root = "/nowhere/the/clone/it/was/built/in"  # type: ignore[attr-defined]
    write_case(case, project / "case")  # type: ignore[arg-type]
    monkeypatch.chdir(project)
    assert check_case(read_case(project / "case")) == []
    monkeypatch.chdir(project / "examples")  # the artefacts are not found from here
    assert {c.now for c in check_case(read_case(project / "case"))} == {None}


def test_a_prior_case_of_another_launch_is_not_compared(project: Path) -> None:
    prior = _build(project)
    prior.launch = "examples/rover/demo.yaml"  # type: ignore[attr-defined]
    tactics = project / "examples/uav/tactics.yaml"
    tactics.write_text(tactics.read_text(encoding="utf-8") + "# edited\n", encoding="utf-8")
    case = _build(project, prior=prior)
    assert case.nodes["Sn-G10-1"].status == "supported"  # type: ignore[attr-defined]
