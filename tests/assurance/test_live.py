"""The case against a running goal model: domain-bound evidence, violated and degraded goals."""

from __future__ import annotations

from pathlib import Path

import pytest

from anunnaki.assurance import Case, build_case, evaluate
from anunnaki.goals import NodeState

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def rover() -> Case:
    return build_case(ROOT / "examples/rover/demo.yaml", root=ROOT)


@pytest.fixture(scope="module")
def uav() -> Case:
    return build_case(ROOT / "examples/uav/sim.yaml", root=ROOT)


def _state(gid: str, status: bool | None, utility: float | None) -> NodeState:
    return NodeState(gid, "goal", utility, status)


def test_without_live_state_the_evidence_decides_as_at_build(rover: Case) -> None:
    live = evaluate(rover, {})
    for n in rover:
        if n.type in ("goal", "strategy", "solution"):
            assert live[n.id].status == n.status, n.id


def test_clean_f1_supports_the_default_model_only_in_clear_weather(rover: Case) -> None:
    clear = evaluate(rover, {}, active_model="rover-default", perceived="clear")
    assert clear["G16"].status == "supported"
    fog = evaluate(rover, {}, active_model="rover-default", perceived="fog")
    # the detector's F1 was measured on clean frames: in fog it supports nothing
    assert fog["G16"].status == "undeveloped"
    assert "measured in clear, not in fog" in fog["G16"].reason


def test_a_robust_model_is_supported_in_its_own_domain_and_not_for_another_model(
    rover: Case,
) -> None:
    right = evaluate(rover, {}, active_model="rover-fog-enki", perceived="fog")
    assert right["G9"].status == "supported"
    held = [sid for sid in rover.nodes["G9"].supported_by if right[sid].status == "supported"]
    # its robustness on fog, its data; not its clean F1, not the other models' figures
    kinds = {(rover.nodes[s].evidence.kind, rover.nodes[s].evidence.model) for s in held}  # type: ignore[union-attr]
    assert kinds == {("robustness", "rover-fog-enki"), ("data", "rover-fog-enki")}
    wrong = evaluate(rover, {}, active_model="rover-default", perceived="fog")
    assert wrong["G9"].status == "undeveloped"
    assert "is not the active model (rover-default)" in wrong["G9"].reason


def test_an_unsatisfied_goal_is_violated_whatever_its_evidence(rover: Case) -> None:
    ok = evaluate(rover, {"G20": _state("G20", True, 1.0)})
    assert ok["G20"].status == "supported"
    bad = evaluate(rover, {"G20": _state("G20", False, 0.2)})
    assert bad["G20"].status == "violated"
    assert (bad["S-G19"].status, bad["G19"].status) == ("violated", "violated")
    # G3 is an OR: G19 violated leaves it to its other alternatives (G11: unverified here)
    assert bad["G3"].status == rover.nodes["G3"].status != "violated"


def test_a_relaxed_goal_within_its_tolerance_is_degraded(rover: Case, uav: Case) -> None:
    live = evaluate(rover, {"G20": _state("G20", True, 0.6)})
    assert live["G20"].status == "degraded"
    assert "utility 0.60" in live["G20"].reason
    full = evaluate(rover, {"G20": _state("G20", True, 1.0)})
    assert full["G20"].status == "supported"
    crisp = evaluate(uav, {"G10": _state("G10", True, 0.6)})
    assert crisp["G10"].status == "supported"  # crisp: no RELAX tolerance to be within


def test_the_evaluators_states_feed_it_directly(rover: Case) -> None:
    """What a live pane does: the running goal model's states in, the case's statuses out."""
    from anunnaki.goals import Evaluator, load_goal_model

    model = load_goal_model(
        ROOT / "examples/rover/goals-lm.yaml", ROOT / "examples/rover/binding-enlil.yaml"
    )
    ev = Evaluator(model)
    status = {"mode": "autonomous", "buzzer": False, "bumper": False, "lights": False}
    ev.observe("/rover/status", status, now=1.0)
    assert evaluate(rover, ev.states())["G5"].status == rover.nodes["G5"].status == "supported"
    ev.observe("/rover/status", {**status, "bumper": True}, now=2.0)  # a contact: G5 fails
    live = evaluate(rover, ev.states(), active_model="rover-default", perceived="clear")
    assert live["G5"] == evaluate(rover, {"G5": ev.state("G5")})["G5"]
    assert live["G5"].status == "violated"
    assert live["G5"].reason == "the goal model finds it unsatisfied"
