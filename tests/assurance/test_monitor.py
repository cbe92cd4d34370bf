"""The case evaluated live: statuses per Utu step, top claims' support in the decision log."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from anunnaki import topics
from anunnaki.assurance import (
    Case,
    CaseMonitor,
    LiveCase,
    build_case,
    goal_states,
    perceived_of,
    top_claims,
)
from anunnaki.bus import Executor, open_bus
from anunnaki.errors import ModelFileError

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def rover() -> Case:
    return build_case(ROOT / "examples/rover/demo.yaml", root=ROOT)


def _analysis(t: float, **goals: tuple[float, str]) -> dict[str, Any]:
    # G15 (the detector's model is fit for the condition) is an OR: the default model (G16)
    # or a robust one (G17); the default runs, so G17 is unsatisfied throughout
    nodes = {"G17": [0.0, "unsatisfied"]} | {g: list(v) for g, v in goals.items()}
    return {"t": t, "root": "G1", "nodes": nodes}


def _fog() -> dict[str, Any]:
    return {"category": 2, "confidence": 0.9, "context": {"phenomenon": "fog"}, "model_id": "m"}


def test_helpers_read_the_analysis_and_the_assessment(rover: Case) -> None:
    states = goal_states({"G1": [1.0, "satisfied"], "G2": [0.0, "unsatisfied"], "G3": [None, "x"]})
    assert (states["G1"].status, states["G2"].status, states["G3"].status) == (True, False, None)
    assert perceived_of({"context": {"phenomenon": "fog", "params": {}}}) == "fog"
    assert perceived_of({"context": {}}) == "clear"
    assert perceived_of({"category": 0}) is None
    assert top_claims(rover) == ["G1", "G2", "G12", "G15"]


def test_support_lost_and_regained_is_recorded_once_per_instant(rover: Case) -> None:
    rows: list[tuple[float, str, Any, dict[str, Any]]] = []
    live = LiveCase(
        rover, record=lambda t, kind, tactic, **data: rows.append((t, kind, tactic, data))
    )
    live.take_active_model({"model": "rover-default", "domain": None})
    live.take_assessment({"context": {"phenomenon": "clear"}})
    live.take_analysis(_analysis(0.0, G15=(1.0, "satisfied")))
    assert live.statuses["G15"].status == "supported"
    assert rows == []  # recorded when the instant ends
    live.take_assessment(_fog())
    changed = live.take_analysis(_analysis(0.05, G15=(1.0, "satisfied")))
    assert changed["G15"].status == "undeveloped"  # the clean F1 does not hold in fog
    # the first instant's statuses, every top claim once
    assert [(r[0], r[3]["claim"], r[3]["support"]) for r in rows] == [
        (0.0, c, "initial") for c in ("G1", "G2", "G12", "G15")
    ]
    assert rows[3][3]["status"] == "supported" and rows[0][1] == "assurance"
    rows.clear()
    # lost and regained within one instant: not recorded
    live.take_analysis(_analysis(0.1, G15=(0.0, "unsatisfied")))
    live.take_assessment({"context": {"phenomenon": "clear"}})
    live.take_analysis(_analysis(0.1, G15=(1.0, "satisfied")))
    # the instant 0.05 ended in fog: G15 lost, with its reason
    assert len(rows) == 1
    t, _, _, data = rows[0]
    assert (t, data["claim"], data["support"], data["was"]) == (0.05, "G15", "lost", "supported")
    assert data["status"] == "undeveloped" and "measured in clear, not in fog" in data["reason"]
    assert data["perceived"] == "fog" and data["active_model"] == "rover-default"
    rows.clear()
    live.take_analysis(_analysis(0.15, G15=(1.0, "satisfied")))
    assert [(r[0], r[3]["support"], r[3]["status"]) for r in rows] == [
        (0.1, "regained", "supported")
    ]
    rows.clear()
    live.take_analysis(_analysis(0.2, G15=(0.0, "unsatisfied")))
    live.flush()  # the run ends
    assert [(r[0], r[3]["support"], r[3]["status"]) for r in rows] == [(0.2, "lost", "violated")]
    assert rows[0][3]["reason"] == "the goal model finds it unsatisfied"


def test_the_monitor_publishes_on_change_and_answers_queries(rover: Case) -> None:
    ex = Executor()
    rows: list[dict[str, Any]] = []
    seen: list[dict[str, Any]] = []
    with open_bus("inproc", executor=ex) as bus:
        live = LiveCase(rover, record=lambda t, kind, tactic, **data: rows.append(data))
        monitor = CaseMonitor(live, bus, svg="<svg/>")
        bus.subscribe(topics.ASSURANCE_STATE, lambda s: seen.append(s.message.to_body()))
        bus.publish(topics.ACTIVE_MODEL, {"model": "rover-default"})
        bus.publish(topics.ORACLE_OUTPUT, {**_fog(), "category": 0})
        bus.publish(topics.ANALYSIS, _analysis(1.0, G15=(1.0, "satisfied")))
        bus.publish(topics.ANALYSIS, _analysis(1.05, G15=(1.0, "satisfied")))  # no change
        bus.publish(topics.ANALYSIS, _analysis(1.1, G20=(0.0, "unsatisfied")))
        ex.spin_until_idle()
        # the first state, then changes: an unchanged analysis publishes nothing
        assert [s["t"] for s in seen] == [1.0, 1.1]
        assert "svg" not in seen[0]
        assert seen[0]["nodes"]["G15"][0] == "undeveloped"
        assert seen[1]["nodes"]["G20"] == ["violated", "the goal model finds it unsatisfied"]
        assert seen[0]["perceived"] == "fog" and seen[1]["seq"] > seen[0]["seq"]
        reply: list[Any] = []
        fut = bus.request_start(topics.ASSURANCE_QUERY, {"svg": True})
        fut.add_done_callback(reply.append)
        ex.spin_until_idle()
        body = reply[0].result().to_body()
        assert body["svg"] == "<svg/>" and body["nodes"] == seen[1]["nodes"]
        assert body["kinds"]["S-G15"] == "strategy" and next(iter(body["nodes"])) == "G1"
        assert [r["support"] for r in rows] == ["initial"] * 4
        monitor.close()
    assert [r["claim"] for r in rows[4:]] == []  # G20 is not a top claim; G15 did not change


def test_a_launch_gets_a_live_case_only_where_its_criteria_develop_it(tmp_path: Path) -> None:
    from anunnaki.assurance import load_live_case

    said: list[str] = []
    case = load_live_case(ROOT / "examples/rover/demo.yaml", warn=said.append)
    assert case is not None and case.solutions() and said == []
    # utu.yaml runs goals.yaml; the assurance.yaml beside it develops goals-lm.yaml: no case
    assert load_live_case(ROOT / "examples/rover/utu.yaml", warn=said.append) is None
    assert said == []
    assert load_live_case(tmp_path / "launch.yaml") is None  # no criteria beside it
    with pytest.raises(ModelFileError, match="no assurance case here"):
        load_live_case(None, tmp_path)
