"""``anunnaki check`` on an assurance criteria file (``anunnaki: assurance/1``).

The criteria's format, and every claim they develop against the goal model they name; a
criteria file used to be refused as "not a goal model".
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from anunnaki.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = [
    ROOT / "examples" / "rover" / "assurance.yaml",
    ROOT / "examples" / "uav" / "assurance.yaml",
]


@pytest.mark.parametrize("criteria", EXAMPLES, ids=lambda p: p.parent.name)
def test_the_shipped_criteria_check_clean(
    criteria: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["check", str(criteria)]) == 0
    out = capsys.readouterr().out
    assert out.startswith("ok: ") and "evidence items for" in out and "goals" in out


def _copy(tmp_path: Path, edit: tuple[str, str]) -> Path:
    """The rover's criteria beside a copy of their goal model, with one text edit."""
    rover = ROOT / "examples" / "rover"
    (tmp_path / "goals-lm.yaml").write_text(
        (rover / "goals-lm.yaml").read_text(encoding="utf-8"), encoding="utf-8"
    )
    text = (rover / "assurance.yaml").read_text(encoding="utf-8")
    assert edit[0] in text
    out = tmp_path / "assurance.yaml"
    out.write_text(text.replace(edit[0], edit[1], 1), encoding="utf-8")
    return out


def test_a_claim_the_goal_model_lacks_is_named_with_its_line_and_a_guess(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    criteria = _copy(tmp_path, ("\n  G6:", "\n  G66:"))
    lines = criteria.read_text(encoding="utf-8").splitlines()
    line = next(i for i, ln in enumerate(lines, 1) if ln.startswith("  G66:"))
    assert main(["check", str(criteria), "--json"]) == 1
    (finding,) = json.loads(capsys.readouterr().out)["findings"]
    assert finding["element"] == "evidence.G66" and finding["line"] == line
    assert finding["path"] == str(criteria) and "no goal or obstacle" in finding["message"]
    assert "G6" in finding["hint"]


def test_a_malformed_item_is_a_finding_with_the_file_not_a_traceback(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    criteria = _copy(tmp_path, ("    - kind:", "    - knd:"))
    assert main(["check", str(criteria)]) == 1
    captured = capsys.readouterr()
    assert str(criteria) in captured.out and "error" in captured.out
    assert "Traceback" not in captured.out + captured.err


def test_criteria_are_checked_alone(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rover = ROOT / "examples" / "rover"
    assert main(["check", str(rover / "assurance.yaml"), str(rover / "binding-lm.yaml")]) == 2
    assert "checked alone" in capsys.readouterr().out
