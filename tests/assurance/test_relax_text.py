"""A RELAX-ed goal's acceptance criterion: the bound its own operator and threshold imply."""

from __future__ import annotations

from pathlib import Path

import pytest

from anunnaki.assurance import acceptance
from anunnaki.goals import History, build_operator, load_goal_model

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def uav():  # type: ignore[no-untyped-def]
    return load_goal_model(ROOT / "examples/uav/goals.yaml", ROOT / "examples/uav/binding.yaml")


@pytest.fixture(scope="module")
def rover():  # type: ignore[no-untyped-def]
    return load_goal_model(
        ROOT / "examples/rover/goals-lm.yaml", ROOT / "examples/rover/binding-enlil.yaml"
    )


def test_as_many_as_possible_holds_from_where_the_utility_meets_the_threshold() -> None:
    # the paper's power goal, kept beside the forecast's (examples/uav/goals-g11.yaml)
    paper = load_goal_model(
        ROOT / "examples/uav/goals-g11.yaml", ROOT / "examples/uav/binding.yaml"
    )
    g11 = paper.goals["G11"]
    acc = acceptance(g11)
    assert acc is not None
    assert (acc.at_least, acc.at_most) == (30.0, None)
    assert acc.text.startswith("A3.level ≥ 30 % (RELAX AS MANY AS POSSIBLE (target 40 %, ")
    op = build_operator(g11.relax)
    assert op.utility(30.0) >= g11.threshold > op.utility(29.99)  # type: ignore[union-attr]


def test_close_to_gives_a_band_or_one_side(uav, rover) -> None:  # type: ignore[no-untyped-def]
    band = acceptance(uav.goals["G3"])
    assert band is not None and (band.at_least, band.at_most) == (25.0, 35.0)
    assert "between 25 and 35 m" in band.text
    rate = acceptance(rover.goals["G6"])
    assert rate is not None and (rate.at_least, rate.at_most) == (4.75, None)
    assert "rate(A3) ≥ 4.75 Hz" in rate.text


def test_eventually_holds_while_the_gap_is_within_tolerance(rover) -> None:  # type: ignore[no-untyped-def]
    g20 = rover.goals["G20"]
    acc = acceptance(g20)
    assert acc is not None and acc.at_most == 0.5  # "at most 0.5 s", as G20 says
    assert "A4.category == 0 held within the last 0.5 s" in acc.text
    op = build_operator(g20.relax)
    history = History([(0.0, True), (1.0, False)])
    assert op.utility_at(history, None, 1.5) >= 0.5 > op.utility_at(history, None, 1.51)  # type: ignore[union-attr]


def test_a_crisp_goal_states_no_relax_criterion(rover) -> None:  # type: ignore[no-untyped-def]
    assert acceptance(rover.goals["G7"]) is None
