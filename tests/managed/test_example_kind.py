"""docs/architecture.md's example: a managed-system kind in one module and one entry point.

``examples/managed/toy_robot.py`` is installed here as a third party would install it (a
distribution whose entry point names the class in group ``anunnaki.managed``), found by
:data:`anunnaki.managed.MANAGED`, named by ``examples/managed/toy.yaml`` and run against Utu.
"""

from __future__ import annotations

import io
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from anunnaki.check import check_files
from anunnaki.errors import ModelFileError
from anunnaki.launch import load_launch, run_launch
from anunnaki.managed import MANAGED

ROOT = Path(__file__).parents[2]
EXAMPLE = ROOT / "examples" / "managed"


@pytest.fixture
def installed(install_distribution: Callable[..., Path]) -> Iterator[type]:
    """The toy robot's module (the example's) and its distribution's entry point, as pip would."""
    entry_points = {"anunnaki.managed": {"toy_robot": "toy_robot:ToyRobotKind"}}
    install_distribution("toy-robot", entry_points, path=(EXAMPLE,))
    MANAGED.load_entry_points(force=True)
    try:
        yield MANAGED.factory("toy_robot")
    finally:
        MANAGED.unregister("toy_robot")


def test_the_entry_point_registers_the_kind(installed: type) -> None:
    assert installed.__name__ == "ToyRobotKind" and "toy_robot" in MANAGED.names()


def test_its_goal_model_checks_clean() -> None:
    result = check_files(EXAMPLE / "goals.yaml", EXAMPLE / "binding.yaml", EXAMPLE / "tactics.yaml")
    assert [f.render() for f in result.findings] == [] and result.exit_code == 0


def test_the_toy_robot_gets_its_buzzer_from_utu(installed: type) -> None:
    launch = load_launch(EXAMPLE / "toy.yaml")
    assert isinstance(launch.managed, installed)
    out = io.StringIO()
    result = run_launch(launch, speed=4, out=out, handle_signals=False)
    log = out.getvalue()
    assert "managed: toy robot 3 m from the wall at 0.5 m/s" in log
    assert result.reason == "the toy robot arrived"
    started = [d.t for d in result.decisions if (d.kind, d.tactic) == ("started", "warn")]
    verified = [d.t for d in result.decisions if (d.kind, d.tactic) == ("postcondition_ok", "warn")]
    # 1 m from the wall at t = 4 s: warned after that, never before, and the buzzer was heard
    assert started and started[0] > 4.0, log
    assert verified and verified[0] >= started[0], log


def test_its_options_are_checked_with_file_and_line(installed: type, tmp_path: Path) -> None:
    text = (EXAMPLE / "toy.yaml").read_text().replace("approach: 0.5", "approach: -1")
    for name in ("goals", "binding", "tactics"):
        text = text.replace(f" {name}.yaml", f" {EXAMPLE / name}.yaml")
    bad = tmp_path / "toy.yaml"
    bad.write_text(text)
    with pytest.raises(ModelFileError, match=r"greater than 0") as err:
        load_launch(bad)
    assert str(err.value).startswith(f"{bad}:23: managed.approach: ")


def test_the_architecture_page_shows_the_example_as_it_is() -> None:
    page = (ROOT / "docs" / "architecture.md").read_text()
    shown = page.split("<!-- examples/managed/toy_robot.py -->", 1)[1]
    block = shown.split("```python\n", 1)[1].split("```", 1)[0]
    assert block == (EXAMPLE / "toy_robot.py").read_text()
