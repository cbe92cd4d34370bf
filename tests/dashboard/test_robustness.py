"""Malformed messages: whatever arrives on the topics it reads, the dashboard keeps serving.

Garbage and ill-typed payloads (ints too large for a float, NaN, wrong types, unknown goal
ids, a queue that is no list, decisions with bad fields) are published on every topic the
dashboard consumes. It must raise nothing in its bus callbacks, keep answering, show the
valid messages that follow, and keep no more than its bounds however many arrive.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from typing import Any

import pytest
from dashboard_helpers import ROVER, Web, png, wait_for

from anunnaki.bus import Bus, InprocHub, open_bus
from anunnaki.dashboard import Dashboard, DashboardState
from anunnaki.dashboard._app import dumps
from anunnaki.dashboard._checks import MAX_ACTIONS, MAX_ASSESSORS, _num
from anunnaki.goals import load_goal_model
from anunnaki.messages import Clock, Detections, Image, body_of
from anunnaki.tactics import load_tactics
from anunnaki.topics import DECISIONS as DECISIONS_TOPIC

HUGE = 10**400  # an int no float can hold: float(HUGE) raises OverflowError


@pytest.fixture
def state() -> DashboardState:
    model = load_goal_model(ROVER / "goals.yaml", ROVER / "binding.yaml")
    return DashboardState(model, load_tactics(ROVER / "tactics.yaml"), clock=lambda: 10.0)


def ids(state: DashboardState) -> set[str]:
    return {*state.model.goals, *state.model.obstacles}


def valid_analysis(state: DashboardState, t: float, unsatisfied: str = "G4") -> dict[str, Any]:
    nodes = {n: [1.0, "satisfied"] for n in ids(state)}
    nodes[unsatisfied] = [0.0, "unsatisfied"]
    return {
        "t": t,
        "nodes": nodes,
        "violated": [unsatisfied],
        "tactics": ["fail-safe"],
        "queue": [{"tactic": "fail-safe", "priority": 100, "state": "pending"}],
    }  # no flags: over the bus, /utu/execute/status sets them (on another thread)


# -- the state, called directly ---------------------------------------------------------------
def test_num_rejects_what_no_float_holds() -> None:
    assert _num(HUGE) is None
    assert _num(-HUGE) is None
    assert _num(math.nan) is None
    assert _num(math.inf) is None
    assert _num(True) is None
    assert _num("1.0") is None
    assert _num(3) == 3.0
    assert _num(0.25) == 0.25


def test_analysis_with_bad_fields_is_applied_whole_or_field_by_field(
    state: DashboardState,
) -> None:
    calls: list[int] = []
    state.add_listener(lambda: calls.append(state.version))
    state.take_analysis(valid_analysis(state, 1.0))
    # A time no float holds used to raise after the nodes were applied (half a message,
    # and no listener told); now the well-typed fields are applied, the bad one ignored.
    body = valid_analysis(state, HUGE, unsatisfied="G7")
    body["nodes"]["G9"] = [HUGE, "satisfied"]  # a node this goal model does not have
    body["nodes"]["G5"] = [math.nan, "bogus"]
    body["nodes"]["G6"] = "unsatisfied"  # not a pair
    state.take_analysis(body)
    snap = state.snapshot()
    assert snap["goals"]["G7"] == [0.0, "unsatisfied"]
    assert snap["goals"]["G5"] == [None, "unknown"]  # NaN: no utility; odd status: unknown
    assert snap["goals"]["G6"] == [1.0, "satisfied"]  # the malformed entry left it alone
    assert "G9" not in snap["goals"]
    assert snap["analysis"]["violated"] == ["G7"]
    assert snap["analysis"]["t"] == 1.0  # the time that could not be read was not taken
    assert calls[-1] == state.version  # the listeners heard of the change
    assert json.loads(dumps(snap))  # the page can be sent what is kept


def test_analysis_fields_of_the_wrong_type_keep_what_was_shown(state: DashboardState) -> None:
    state.take_analysis(valid_analysis(state, 1.0))
    before = state.snapshot()["analysis"]
    state.take_analysis(
        {
            "t": "soon",
            "nodes": ["G1", "G2"],
            "violated": "G4",
            "tactics": {"fail-safe": 1},
            "queue": "fail-safe",
            "paused": "yes",
            "run_stopped": 1,
            "warming_up": None,
            "postconditions": [1, 2],
        }
    )
    assert state.snapshot()["analysis"] == before
    state.take_analysis(
        {
            "queue": [
                1,
                "x",
                {"tactic": 5},
                {"tactic": "fail-safe", "priority": HUGE, "state": ["pending"]},
            ],
            "violated": ["G1", 7, None, "G2"],
        }
    )
    analysis = state.snapshot()["analysis"]
    assert analysis["queue"] == [
        {"tactic": "fail-safe", "priority": None, "state": "unknown", "deadline": None}
    ]
    assert analysis["violated"] == ["G1", "G2"]
    for junk in (None, 5, "state", [1, 2], {"nodes": None}):
        state.take_analysis(junk)  # type: ignore[arg-type]
    state.take_analysis(valid_analysis(state, 2.0, unsatisfied="G3"))
    snap = state.snapshot()
    assert snap["goals"]["G3"] == [0.0, "unsatisfied"]
    assert snap["analysis"]["violated"] == ["G3"]


def test_unknown_node_ids_and_assessors_do_not_accumulate(state: DashboardState) -> None:
    for i in range(200):
        nodes = {f"X{i}-{j}": [1.0, "satisfied"] for j in range(50)}
        state.take_analysis({"t": float(i), "nodes": nodes})
        state.take_assessment(f"/utu/oracle/o{i}", {"category": 1, "assessor": f"oracle-{i}"})
    snap = state.snapshot()
    assert set(snap["goals"]) == ids(state)  # only the goal model's nodes, ever
    assert len(snap["oracle"]) == MAX_ASSESSORS
    assert "oracle-199" in {o["assessor"] for o in snap["oracle"]}  # the latest kept
    assert "oracle-0" not in {o["assessor"] for o in snap["oracle"]}  # the oldest gone


def test_bad_decisions_are_skipped_or_cleaned_and_never_hide_good_ones(
    state: DashboardState,
) -> None:
    state.take_decisions(
        [
            1,
            "started",
            {"kind": 5, "t": 1.0},
            {"t": 1.0},  # no kind
            {"t": HUGE, "kind": "paused", "tactic": None, "data": {"caller": "alice"}},
            {"t": "later", "kind": "started", "tactic": ["fail-safe"], "data": [1, 2]},
            {"t": 2.0, "kind": "note", "data": {"n": {1: "a", "b": 2}}},  # no JSON key order
            {"t": 3.0, "kind": "started", "tactic": "fail-safe", "data": {"deadline": HUGE}},
        ]
    )
    rows = state.snapshot()["decisions"]
    assert [(d["kind"], d["t"], d["tactic"]) for d in rows] == [
        ("paused", None, None),  # the time no float holds: shown without a time
        ("started", None, None),  # the ill-typed tactic and data dropped
        ("started", 3.0, "fail-safe"),
    ]
    assert rows[0]["data"] == {"caller": "alice"}
    assert rows[1]["data"] == {}
    (run,) = state.snapshot()["executions"]
    assert (run["tactic"], run["deadline"]) == ("fail-safe", None)
    # The decision that used to be lost (its key kept, its row never built) de-duplicates
    # like any other, and a later good decision still arrives.
    state.take_decisions(
        [{"t": HUGE, "kind": "paused", "tactic": None, "data": {"caller": "alice"}}]
    )
    state.take_decisions([{"t": 4.0, "kind": "postcondition_ok", "tactic": "fail-safe"}])
    snap = state.snapshot()
    assert [d["kind"] for d in snap["decisions"]] == [
        "paused",
        "started",
        "started",
        "postcondition_ok",
    ]
    assert snap["executions"][0]["result"] == "postcondition_ok"


def test_decisions_stay_bounded(state: DashboardState) -> None:
    small = DashboardState(state.model, state.tactics, clock=lambda: 0.0, decisions=50)
    small.take_decisions([{"t": 0.0, "kind": "started", "tactic": "fail-safe"}])
    for i in range(40):
        small.take_decisions(
            [{"t": float(i * 10 + j), "kind": "action", "tactic": "fail-safe"} for j in range(10)]
        )
    assert len(small.snapshot()["decisions"]) == 50
    assert len(small._log._keys) <= 4 * 50
    (run,) = small.snapshot()["executions"]
    assert len(run["actions"]) == MAX_ACTIONS  # 400 actions of one run: the first 100 kept


def test_assessments_inputs_and_models_of_the_wrong_type(state: DashboardState) -> None:
    oracle = "/utu/oracle/output"
    for body in (
        {"category": HUGE},
        {"category": "1"},
        {"category": True},
        {"category": 1.0},
        {"category": 7},
        {"confidence": 0.5},
    ):
        state.take_assessment(oracle, body)
    assert state.snapshot()["oracle"] == []
    state.take_assessment(
        oracle,
        {
            "category": 2,
            "confidence": HUGE,
            "context": "fog",
            "assessor": ["x"],
            "model_id": 5,
            "frame_seq": HUGE,
        },
    )
    (row,) = state.snapshot()["oracle"]
    assert (row["assessor"], row["category"], row["confidence"]) == (oracle, 2, None)
    assert (row["context"], row["model_id"], row["frame_seq"]) == ({}, None, None)
    state.take_input("/rover/ultrasonic", {"range": HUGE}, 10.0)
    state.take_input("/rover/ultrasonic", {"range": "far"}, 10.0)
    state.take_input("/rover/status", {"mode": [1], "bumper": {"a": HUGE}}, 10.0)
    state.take_input("/rover/status", "autonomous", 10.0)  # type: ignore[arg-type]
    state.take_active_model({"lec": 1, "model": HUGE, "domain": ["fog"]})
    state.take_detections({"frame_seq": HUGE, "boxes": "x"})
    state.take_detections({"frame_seq": 3, "boxes": [[1, 2], "x", [1, 2, 3, HUGE]], "scores": 5})
    snap = state.snapshot()
    assert snap["camera"]["active"] == {
        "lec": None,
        "model": None,
        "domain": None,
        "source": "lm_manager",
    }
    assert snap["camera"]["detections"]["boxes"] == [[1.0, 2.0, 3.0, 0.0]]
    assert snap["camera"]["detections"]["scores"] == []
    explained = state.explain("G13")
    assert explained is not None
    assert explained["text"]  # the evaluator still explains after the garbage
    assert json.loads(dumps(snap))


# -- over the bus, with the server answering ---------------------------------------------------
@pytest.fixture
def served() -> Iterator[tuple[Dashboard, Bus]]:
    hub = InprocHub()
    with (
        open_bus("inproc", hub=hub, name="dashboard") as bus,
        open_bus("inproc", hub=hub, name="garbage") as pub,
    ):
        model = load_goal_model(ROVER / "goals.yaml", ROVER / "binding.yaml")
        tactics = load_tactics(ROVER / "tactics.yaml")
        with Dashboard(model, tactics, bus=bus, port=0, clock="sim", seed=False) as dash:
            yield dash, pub


def test_garbage_on_every_topic_keeps_the_dashboard_serving(
    served: tuple[Dashboard, Bus], caplog: pytest.LogCaptureFixture
) -> None:
    dash, pub = served
    state = dash.state
    client = Web(dash.url)
    garbage: dict[str, list[Any]] = {
        "/utu/analyze/state": [
            {"t": HUGE, "nodes": {"G1": [HUGE, "satisfied"]}},
            {"nodes": {f"X{i}": [1.0, "satisfied"] for i in range(300)}, "queue": "x"},
            {"nodes": "G1", "violated": 5, "tactics": "fail-safe", "paused": "no"},
            {"queue": [1, {"tactic": HUGE}], "run_stopped": [True]},
        ],
        "/utu/plan/start": [{"queue": "fail-safe"}, {"queue": [None, {"tactic": 3}]}, {}],
        "/utu/execute/status": [{"paused": "yes", "run_stopped": HUGE}, {"paused": [1]}],
        DECISIONS_TOPIC: [
            {"decisions": "all of them"},
            {"decisions": [1, None, {"kind": 5}, {"kind": "started", "t": HUGE, "data": 3}]},
        ],
        "/rover/ultrasonic": [{"range": HUGE}, {"range": "far"}, {"range": [1, 2]}],
        "/rover/status": [{"mode": HUGE, "bumper": "no", "buzzer": {"on": [1]}}],
        "/utu/oracle/output": [{"category": HUGE}, {"category": "2"}, {"confidence": 1}],
        "/utu/oracle/other": [
            {"category": 1, "confidence": HUGE, "context": ["fog"], "assessor": {"a": 1}}
        ],
        "/rover/camera/image": [{"encoding": "png", "data": "not bytes"}, {"seq": HUGE}],
        "/lec/detector/detections": [{"frame_seq": HUGE}, {"frame_seq": "1", "boxes": 5}],
        "/lm_manager/active": [{"model": HUGE, "domain": ["fog"]}, {"lec": None}],
        "/clock": [{"time": "noon"}, {"time": HUGE}],
    }
    # The decisions topic only rings a bell: the rows come from Utu's knowledge service,
    # which here answers garbage first, then the one valid decision.
    replies = [
        {"decisions": "all of them"},
        {"decisions": [1, None, {"kind": 5}, {"kind": "started", "t": HUGE, "data": 3}]},
    ]

    def query(message: Any) -> dict[str, Any]:
        if replies:
            return replies.pop(0)
        valid = {"id": 1, "t": 12.0, "kind": "started", "tactic": "fail-safe"}
        return {"decisions": [valid] if (body_of(message).get("after") or 0) < 1 else []}

    pub.service("/utu/knowledge/query", query)
    for topic, bodies in garbage.items():
        for body in bodies:
            pub.publish(topic, body)
    # Then valid messages on the same topics (each topic's messages arrive in order).
    pub.publish("/clock", Clock(time=12.0))
    pub.publish("/rover/ultrasonic", {"range": 0.5})
    analysis = valid_analysis(state, 12.0)
    del analysis["queue"]  # the queue comes from /utu/plan/start, below
    pub.publish("/utu/analyze/state", analysis)
    pub.publish("/utu/execute/status", {"paused": True, "run_stopped": False})
    pub.publish(
        DECISIONS_TOPIC,
        {"decisions": [{"id": 1, "t": 12.0, "kind": "started", "tactic": "fail-safe"}]},
    )
    pub.publish("/utu/oracle/output", {"category": 1, "confidence": 0.9, "context": {"lux": 3}})
    pub.publish("/lm_manager/active", {"lec": "detector", "model": "centernet-fog"})
    pub.publish(
        "/rover/camera/image",
        Image(encoding="png", width=8, height=8, data=png(8, 8, (1, 2, 3)), seq=4),
    )
    pub.publish(
        "/lec/detector/detections",
        Detections(frame_seq=4, model_id="centernet-fog", width=8, height=8),
    )

    def shown() -> dict[str, Any] | None:
        snap = client.get("/api/snapshot").json()
        ok = (
            snap["goals"].get("G4") == [0.0, "unsatisfied"]
            and snap["analysis"]["paused"] is True
            and [(d["t"], d["tactic"]) for d in snap["decisions"]][-1:] == [(12.0, "fail-safe")]
            and any(o["category"] == 1 and o["context"] == {"lux": 3} for o in snap["oracle"])
            and snap["camera"]["active"]["model"] == "centernet-fog"
            and (snap["camera"].get("detections") or {}).get("frame_seq") == 4
            and (snap["camera"].get("frame") or {}).get("seq") == 4  # frames: another thread
            and any(m["last"] == {"range": 0.5} for m in snap["monitor"])
        )
        return snap if ok else None

    snap = wait_for(shown, what="the valid messages after the garbage")
    # The queue has two sources (analysis, plan) on two threads: set it once both are done.
    pub.publish("/utu/plan/start", {"queue": [{"tactic": "fail-safe", "priority": 100}]})
    queue = [{"tactic": "fail-safe", "priority": 100, "state": "unknown", "deadline": None}]
    wait_for(
        lambda: client.get("/api/snapshot").json()["analysis"]["queue"] == queue,
        what="the plan's queue",
    )
    # Nothing the dashboard does on the bus raised (the bus logs a callback that raises).
    raised = [r.getMessage() for r in caplog.records if "callback raised" in r.getMessage()]
    assert raised == []
    dropped = [r.getMessage() for r in caplog.records if "malformed" in r.getMessage()]
    assert dropped  # typed topics (frames, detections, clock): the bus drops what is not one
    # Bounded, and still answering every route.
    assert set(snap["goals"]) == ids(state)
    assert len(snap["oracle"]) <= MAX_ASSESSORS
    assert snap["analysis"]["t"] == 12.0
    assert client.get("/api/explain/G13").status_code == 200
    assert client.get("/api/frame/4").content == png(8, 8, (1, 2, 3))
    assert client.get("/").status_code == 200
