"""Every malformed file under tests/data/bad/{goals,bindings,traces} fails with its message.

Each ``name.ext`` has ``name.ext.expected`` holding text the error must contain (file name
and line included). The error is always a ModelFileError — never another exception — and
``anunnaki check`` on a bad goal model exits 1 or 2 with the same message, no traceback.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from anunnaki.cli.main import main
from anunnaki.errors import ModelFileError
from anunnaki.goals import Evaluator, load_binding, load_goal_model, parse_goal_model
from anunnaki.trace import read_trace

BAD = Path(__file__).parent / "data" / "bad"
EXAMPLE_MODEL = """\
anunnaki: goal-model/1
name: host
agents: [{id: A1}]
goals: [{id: G1, utility: A1.x == 1}]
"""


def cases(kind: str) -> list[Path]:
    return sorted(p for p in (BAD / kind).iterdir() if not p.name.endswith(".expected"))


def expected(path: Path) -> str:
    return path.with_name(path.name + ".expected").read_text(encoding="utf-8").strip()


@pytest.mark.parametrize("path", cases("goals"), ids=lambda p: p.name)
def test_bad_goal_model(path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ModelFileError) as info:
        Evaluator(load_goal_model(path))
    message = str(info.value)
    assert expected(path) in message
    assert path.name in message
    code = main(["check", str(path)])
    out = capsys.readouterr()
    assert code in (1, 2)
    printed = re.sub(r": (error|warning): ", ": ", out.out + out.err)
    assert expected(path) in printed
    assert "Traceback" not in out.out + out.err


@pytest.mark.parametrize("path", cases("bindings"), ids=lambda p: p.name)
def test_bad_binding(path: Path) -> None:
    with pytest.raises(ModelFileError) as info:
        binding = load_binding(path)
        parse_goal_model(EXAMPLE_MODEL, binding=binding)
    assert expected(path) in str(info.value)


@pytest.mark.parametrize("path", cases("traces"), ids=lambda p: p.name)
def test_bad_trace(path: Path) -> None:
    with pytest.raises(ModelFileError) as info:
        read_trace(path)
    assert expected(path) in str(info.value)
