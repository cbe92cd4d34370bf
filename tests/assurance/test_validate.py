"""The GSN export keeps the rules of the GSN Community Standard v3 (core notation)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from anunnaki.assurance import build_case, validate_gsn, validate_gsn_file, write_case

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("launch", ["examples/rover/demo.yaml", "examples/uav/sim.yaml"])
def test_the_written_yaml_validates(launch: str, tmp_path: Path) -> None:
    files = write_case(build_case(ROOT / launch, root=ROOT), tmp_path)
    assert validate_gsn_file(files["gsn"]) == []
    doc = yaml.safe_load(files["gsn"].read_text(encoding="utf-8"))
    types = {k: k.split("-")[0] for k in doc}
    assert {"G1", "S-G1", "C-launch", "J-evidence", "A-D1"} <= set(doc)
    # gsn2x's attributes only; undeveloped never beside supportedBy
    for el in doc.values():
        assert set(el) <= {"text", "supportedBy", "inContextOf", "undeveloped", "classes"}
        assert not ("undeveloped" in el and "supportedBy" in el)
    assert any(t.startswith("Sn") for t in types.values())


def _good() -> dict[str, Any]:
    return {
        "G1": {"text": "top", "supportedBy": ["S1"], "inContextOf": ["C1", "A1", "J1"]},
        "S1": {"text": "over", "supportedBy": ["G2", "G3"]},
        "G2": {"text": "leaf", "supportedBy": ["Sn1"]},
        "G3": {"text": "open", "undeveloped": True},
        "Sn1": {"text": "evidence"},
        "C1": {"text": "ctx"},
        "A1": {"text": "assumed"},
        "J1": {"text": "because"},
    }


def test_a_well_formed_argument_has_no_problem() -> None:
    assert validate_gsn(_good()) == []


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        (lambda d: d["G3"].pop("undeveloped"), "G3: neither supported nor marked undeveloped"),
        (lambda d: d["G2"].update(undeveloped=True), "G2: both supported and marked undeveloped"),
        (lambda d: d["Sn1"].update(supportedBy=["G3"]), "Sn1 (solution) cannot be supported by G3"),
        (lambda d: d["C1"].update(supportedBy=["G3"]), "C1 (context) cannot be supported"),
        (
            lambda d: d["S1"].update(supportedBy=["G2", "Sn1"]),
            "S1 (strategy) cannot be supported by Sn1",
        ),
        (lambda d: d["G2"].update(inContextOf=["G3"]), "G2: inContextOf G3 (goal)"),
        (lambda d: d["Sn1"].update(inContextOf=["C1"]), "Sn1 (solution) cannot have inContextOf"),
        (lambda d: d["G3"].update(undeveloped=None, supportedBy=["S1"]), "cycle through S1"),
        (lambda d: d.update(X9={"text": "?"}), "X9: the id starts with no GSN prefix"),
        (lambda d: d["G2"].update(text=" "), "G2: no text"),
        (lambda d: d.update(G4={"text": "loose", "undeveloped": True}), "2 top-level goals"),
        (lambda d: d.update(C2={"text": "unused"}), "nothing refers to: C2"),
        (lambda d: d["G2"].update(supportedBy=["Sn9"]), "G2: supportedBy names 'Sn9'"),
        (lambda d: d["G2"].update(colour="red"), "G2: unknown attributes ['colour']"),
    ],
)
def test_each_rule_is_checked(change: Any, expected: str) -> None:
    doc = _good()
    change(doc)
    problems = validate_gsn(doc)
    assert any(expected in p for p in problems), problems


def test_a_repeated_id_in_the_file_is_a_problem(tmp_path: Path) -> None:
    path = tmp_path / "case.gsn.yaml"
    path.write_text("G1:\n  text: a\n  undeveloped: true\nG1:\n  text: b\n", encoding="utf-8")
    (problem,) = validate_gsn_file(path)
    assert "duplicate key 'G1'" in problem
