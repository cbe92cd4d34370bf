"""The case of the shipped launches: the goal model argued as GSN, developed with evidence."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from anunnaki.assurance import Case, build_case, gsn_document, validate_gsn
from anunnaki.goals import load_goal_model

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"
ROVER = ROOT / "examples" / "rover" / "demo.yaml"
UAV = ROOT / "examples" / "uav" / "sim.yaml"


@pytest.fixture(scope="module")
def rover() -> Case:
    return build_case(ROVER, root=ROOT)


@pytest.fixture(scope="module")
def uav() -> Case:
    return build_case(UAV, root=ROOT)


def test_every_goal_becomes_a_gsn_goal_and_each_refinement_a_strategy(rover: Case) -> None:
    model = load_goal_model(
        ROOT / "examples/rover/goals-lm.yaml", ROOT / "examples/rover/binding-enlil.yaml"
    )
    for gid, g in model.goals.items():
        node = rover.nodes[gid]
        assert node.type == "goal"
        assert node.text == g.description
        assert node.leaf == (not g.children)
        if g.children:
            strategy = rover.nodes[f"S-{gid}"]
            assert f"S-{gid}" in node.supported_by
            assert strategy.supported_by == g.children
            assert strategy.refinement == g.refinement
    assert "any one of G4, G19, G11 suffices" in rover.nodes["S-G3"].text
    assert "all of G2, G12, G15 hold" in rover.nodes["S-G1"].text
    assert rover.root == "G1"


def test_agents_are_context_domain_properties_assumptions_obstacles_hazards(rover: Case) -> None:
    assert rover.nodes["C-A4"].type == "context"
    assert "Behavior oracle" in rover.nodes["C-A4"].text
    assert "C-A4" in rover.nodes["G20"].in_context_of
    assert rover.nodes["A-D1"].type == "assumption"
    assert "A-D1" in rover.nodes["G1"].in_context_of
    # O1 obstructs G4: argued through its detection and its resolutions G9, G11 (any one)
    assert "S-O1" in rover.nodes["G4"].supported_by
    hazard = rover.nodes["S-O1"]
    assert hazard.supported_by == ["G-O1-detected", "G-O1-resolved"]
    assert hazard.in_context_of == ["C-O1"]
    assert "A4.category >= 1" in rover.nodes["C-O1"].text
    resolutions = rover.nodes["S-O1-resolutions"]
    assert (resolutions.refinement, resolutions.supported_by) == ("or", ["G9", "G11"])


def _results(name: str) -> Any:
    return json.loads((RESULTS / name).read_text(encoding="utf-8"))


def _uav_utu() -> Any:
    return _results("case-studies.json")["cases"]["uav"]["summary"]["utu"]


def test_relax_tolerances_are_stated_as_acceptance_criteria(rover: Case, uav: Case) -> None:
    assert "C-G20-accept" in rover.nodes["G20"].in_context_of
    assert "held within the last 0.5 s" in rover.nodes["C-G20-accept"].text
    assert "A1.altitude between 25 and 35 m" in uav.nodes["C-G3-accept"].text
    assert "C-G3-accept" in uav.nodes["G3"].in_context_of
    # G15 (the battery forecast leaves the 5 % reserve): the criteria file's bound, checked
    (sn,) = [uav.nodes[s] for s in uav.nodes["G15"].supported_by if s.startswith("Sn-")]
    assert sn.evidence is not None
    measured = _uav_utu()["battery_at_landing"]["min"]
    assert sn.evidence.value == measured
    assert (sn.evidence.result, sn.status) == (
        ("pass", "supported") if measured >= 5 else ("fail", "failed")
    )


def test_a_leaf_without_evidence_is_undeveloped_and_never_supported(uav: Case) -> None:
    node = uav.nodes["G12"]  # the ground-station link: no measurement, no test named
    assert node.supported_by == [] and node.undeveloped
    assert node.status == "undeveloped"
    assert gsn_document(uav)["G12"]["undeveloped"] is True
    assert "supportedBy" not in gsn_document(uav)["G12"]
    # G1 is an AND over it (and fails on its own evidence besides)
    assert uav.nodes["S-G1"].status != "supported"


def test_tests_not_run_support_nothing(rover: Case) -> None:
    (sn,) = [rover.nodes[s] for s in rover.nodes["G7"].supported_by]
    assert sn.evidence is not None and sn.evidence.kind == "tests"
    assert (sn.evidence.result, sn.status, rover.nodes["G7"].status) == (
        "not run",
        "unverified",
        "unverified",
    )


def test_evidence_records_figure_criterion_result_command_and_hashes(rover: Case) -> None:
    by_model = {
        n.evidence.model: n
        for n in rover.solutions()
        if n.evidence is not None and n.evidence.kind == "detector"
    }
    default = by_model["rover-default"].evidence
    assert default is not None
    assert default.stage == "model learning"
    card = json.loads((ROOT / "examples/models/rover-default.json").read_text(encoding="utf-8"))
    f1 = card["metrics"]["test"]["f1"]
    assert default.value == f1
    assert f"held-out F1 {f1:.3f}" in default.figure
    assert f"{card['training']['test_images']} held-out test images" in default.figure
    assert default.criterion == "≥ 0.9" and default.result == ("pass" if f1 >= 0.9 else "fail")
    assert default.command.startswith("anunnaki evaluate-detector examples/models/rover.yaml")
    roles = {a.role: a for a in default.artefacts}
    assert roles["model:rover-default"].sha256 == card["sha256"]
    assert roles["model:rover-default"].path == "examples/models/rover-default.safetensors"
    assert {"sidecar:rover-default", "registry"} <= set(roles)
    stages = {n.evidence.stage for n in rover.solutions() if n.evidence is not None}
    assert stages == {"data management", "model learning", "model verification", "model deployment"}


def test_robustness_evidence_gives_seeds_spread_and_its_domain(rover: Case) -> None:
    (fog,) = [
        n.evidence
        for n in rover.solutions()
        if n.evidence is not None
        and n.evidence.kind == "robustness"
        and n.evidence.model == "rover-fog-enki"
    ]
    dom = _results("robustify.json")["domains"]["rover-fog"]
    enki, vs = dom["arms"]["enki"]["mPC"], dom["enki_vs_random"]["mPC"]
    assert fog.conditions == ["fog"]
    seeds = _results("robustify.json")["settings"]["seeds"]
    assert f"over {enki['n']} seeds {seeds}: {enki['mean']:.3f} ± {enki['std']:.3f}" in fog.figure
    assert f"spread {vs['spread']:.3f}: {vs['verdict']}" in fog.figure
    margin = dom["arms"]["shipped"]["mPC"]["mean"] - dom["arms"]["default"]["mPC"]["mean"]
    assert fog.value == pytest.approx(margin, abs=1e-4)
    assert fog.result == ("pass" if margin >= 0 else "fail")


def test_the_oracle_against_its_ceiling_and_its_false_alarms(rover: Case) -> None:
    ceiling = {
        n.evidence.conditions[0]: n.evidence
        for n in rover.solutions()
        if n.evidence is not None and n.evidence.kind == "oracle_ceiling" and n.evidence.conditions
    }
    measured = _results("oracle.json")["accuracy"]
    assert set(ceiling) == {k.split("/")[1] for k in measured if k.startswith("rover-default/")}
    for phen, ev in ceiling.items():
        value = measured[f"rover-default/{phen}"]["aims"]["interior_of_ceiling"]["value"]
        assert ev.value == value and ev.result == ("pass" if value >= 0.9 else "fail")
    (alarms,) = [
        n
        for n in rover.solutions()
        if n.evidence is not None and "false_alarms.with_close" in n.evidence.figure
    ]
    assert alarms.evidence is not None
    oracle = {a.role: a for a in alarms.evidence.artefacts}["oracle:rover-default"]
    # the results file names the oracle it measured: the same as the registry's today
    assert oracle.measured_sha256 == oracle.sha256
    assert alarms.status == "supported"


def test_the_uav_case_argues_the_delivery_on_the_campaign(uav: Case) -> None:
    """On 2026-11-27 Utu delivered in 0 of 10 seeds: G1 failed, G8 held through G10."""
    utu = _uav_utu()
    (delivered,) = [uav.nodes[s] for s in uav.nodes["G1"].supported_by if s.startswith("Sn-")]
    assert delivered.evidence is not None
    assert delivered.evidence.value == utu["delivered"]["mean"]
    if utu["delivered"]["mean"] < 0.8:
        assert delivered.status == "failed" and uav.nodes["G1"].status == "failed"
    # G8 is an OR: it holds through G10 (landed at home in every seed) whatever G15 says
    home = utu["landed_home"]["min"] == 1
    assert uav.nodes["G10"].status == ("supported" if home else "failed")
    if home:
        assert uav.nodes["S-G8"].status == "supported"


def test_coverage_counts_leaf_goals_with_supported_evidence(rover: Case, uav: Case) -> None:
    for case in (rover, uav):
        cov = case.coverage()
        leaves = case.leaf_goals()
        assert cov["leaf_goals"] == len(leaves)
        assert cov["supported"] == sum(n.status == "supported" for n in leaves)
        assert sum(len(ids) for ids in cov["by_status"].values()) == len(leaves)
    assert rover.coverage()["leaf_goals"] == 13 and uav.coverage()["leaf_goals"] == 9
    assert uav.coverage()["by_status"]["undeveloped"] == ["G12"]


def test_both_cases_keep_the_gsn_rules(rover: Case, uav: Case) -> None:
    for case in (rover, uav):
        assert validate_gsn(gsn_document(case)) == []


def test_goal_ids_without_the_g_prefix_get_one_and_the_case_keeps_the_rules() -> None:
    from anunnaki.assurance import case_from_model, propagate
    from anunnaki.goals import parse_goal_model

    model = parse_goal_model(
        """
anunnaki: goal-model/1
name: toy
root: Safe
agents:
  - {id: A1, topics: [{topic: /toy, attributes: [seen, stopped]}]}
goals:
  - {id: Safe, refinement: and, children: [Sees, Sn1]}
  - {id: Sees, utility: A1.seen, agents: [A1]}
  - {id: Sn1, utility: A1.stopped, agents: [A1]}
obstacles:
  - {id: Blind, obstructs: [Sees], condition: A1.seen == false, resolutions: [Sn1]}
"""
    )
    case = case_from_model(model)
    propagate(case)
    assert case.root == "G-Safe"
    assert case.nodes["S-Safe"].supported_by == ["G-Sees", "G-Sn1"]
    assert case.nodes["G-Sn1"].type == "goal" and case.nodes["G-Sn1"].source == "Sn1"
    assert case.nodes["S-Blind-resolutions"].supported_by == ["G-Sn1"]
    assert "S-Blind" in case.nodes["G-Sees"].supported_by
    assert validate_gsn(gsn_document(case)) == []
    assert case.coverage()["by_status"] == {"undeveloped": ["G-Sees", "G-Sn1"]}


def test_a_launch_already_loaded_gives_the_same_case(uav: Case) -> None:
    from anunnaki.launch import load_launch

    again = build_case(UAV, root=ROOT, loaded=load_launch(UAV)).to_json()
    first = uav.to_json()
    for when in ("built", "build_seconds"):  # the clock's, not the case's
        again.pop(when, None)
        first.pop(when, None)
    assert again == first
