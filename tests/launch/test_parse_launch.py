"""``parse_launch``: a launch file given as text; its errors name the ``source`` it came from."""

from __future__ import annotations

from pathlib import Path

import pytest

from anunnaki.errors import ModelFileError
from anunnaki.launch import parse_launch

ROVER = Path(__file__).parents[2] / "examples" / "rover"
HEAD = "anunnaki: launch/1\nutu: {goal_model: goals.yaml, binding: binding.yaml}\n"
SOURCE = "site/rover-launch.yaml"


@pytest.mark.parametrize(
    ("text", "line", "element", "message"),
    [
        ("anunnaki: launch/2\nutu: x\n", 1, None, "not a launch file"),
        (HEAD + "nodes: [monitor, planner]\n", 3, "nodes", "planner"),
        (HEAD + "bus:\n  kind: zenoh\n  listen: [localhost]\n", 5, "bus.listen", "endpoint"),
        (HEAD + "nodes: [plan, plan]\n", 3, "nodes", "twice"),
        (HEAD + "managed: {kind: crystal_ball}\n", 3, "managed.kind", "crystal_ball"),
        (
            "anunnaki: launch/1\nutu:\n  goal_model: goals.yaml\n  binding: binding.yaml\n"
            "  rate: -1\n",
            5,
            "utu.rate",
            "rate",
        ),
    ],
)
def test_errors_name_the_source_line_and_element(
    text: str, line: int, element: str | None, message: str
) -> None:
    with pytest.raises(ModelFileError) as err:
        parse_launch(text, source=SOURCE, base=ROVER)
    e = err.value
    assert (e.path, e.line) == (SOURCE, line), str(e)
    assert str(e).startswith(f"{SOURCE}:{line}:"), str(e)
    if element is not None:
        assert e.element is not None and e.element.startswith(element), str(e)
    assert message in str(e)
    assert "<launch>" not in str(e)


def test_malformed_yaml_names_the_source() -> None:
    with pytest.raises(ModelFileError) as err:
        parse_launch(HEAD + "nodes: [monitor\n", source=SOURCE, base=ROVER)
    assert err.value.path == SOURCE and err.value.line is not None


def test_a_utu_configuration_as_text_is_refused_with_the_way_out() -> None:
    text = "anunnaki: utu/1\ngoal_model: goals.yaml\nbinding: binding.yaml\n"
    with pytest.raises(ModelFileError) as err:
        parse_launch(text, source=SOURCE, base=ROVER)
    assert (err.value.path, err.value.line) == (SOURCE, 1)
    assert err.value.hint is not None and "load_launch" in err.value.hint


def test_the_default_source_is_named_when_none_is_given() -> None:
    with pytest.raises(ModelFileError) as err:
        parse_launch(HEAD + "nodes: [monitor, planner]\n", base=ROVER)
    assert str(err.value).startswith("<launch>:3:")
