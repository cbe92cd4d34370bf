"""The tactics model: defaults, validation, helpers, and where elements were written."""

from __future__ import annotations

import re
from typing import Any

import pytest
from pydantic import ValidationError

from anunnaki.tactics import (
    ChangeModeAction,
    EndpointReference,
    ExpressionCondition,
    GoalState,
    NotifyAction,
    PublishAction,
    RequestAction,
    SourceRef,
    SwapModelAction,
    Tactic,
    TacticSet,
    parse_tactics_yaml,
)

PRE = [GoalState(goal="G3", state="unsatisfied")]
ACT = [ChangeModeAction(service="/rover/set_mode", mode="manual")]


def tactic(name: str = "t", **fields: Any) -> Tactic:
    fields.setdefault("preconditions", PRE)
    fields.setdefault("actions", ACT)
    return Tactic(name=name, **fields)


def test_defaults() -> None:
    t = tactic()
    assert (t.description, t.priority, t.postconditions) == ("", 0, [])
    assert (t.deadline, t.cooldown, t.requires_approval, t.conflicts) == (5.0, 0.0, False, [])
    request = RequestAction(service="/a")
    assert (request.payload, request.timeout) == ({}, 2.0)
    swap = SwapModelAction(domain="fog")
    assert (swap.lec, swap.model, swap.service) == ("detector", None, "/lm_manager/swap")
    note = NotifyAction(channel="log", message="m")
    assert (note.to, note.subject) == (None, "")
    assert t.source == SourceRef(None, None)


def test_models_are_frozen_and_forbid_unknown_fields() -> None:
    t = tactic()
    with pytest.raises(ValidationError, match="frozen"):
        t.priority = 3  # type: ignore[misc]
    with pytest.raises(ValidationError, match="Extra inputs"):
        Tactic.model_validate({"name": "t", "preconditions": [], "actions": [], "bogus": 1})


def test_where_an_element_was_written_is_not_part_of_what_it_is() -> None:
    text = (
        "anunnaki: tactics/1\n\n\ntactics:\n  - name: t\n"
        "    preconditions: [{goal: G3, state: unsatisfied}]\n"
        "    actions: [{type: change_mode, service: /rover/set_mode, mode: manual}]\n"
    )
    loaded = parse_tactics_yaml(text, source="a.yaml")
    built = TacticSet(tactics=[tactic()])
    assert loaded == built
    assert loaded.tactics[0].source == SourceRef("a.yaml", 5)
    assert built.tactics[0].source == SourceRef(None, None)
    assert "source" not in loaded.model_dump()["tactics"][0]
    copy = loaded.model_copy()
    assert copy.source == SourceRef("a.yaml", 1)


def test_priority_order_and_lookup() -> None:
    ts = TacticSet(
        tactics=[tactic("low", priority=-1), tactic("a", priority=5), tactic("b", priority=5)]
    )
    assert [t.name for t in ts.by_priority()] == ["a", "b", "low"]
    assert ts.tactic("low").priority == -1
    with pytest.raises(KeyError, match="known: low, a, b"):
        ts.tactic("nope")


def test_conflicts_are_symmetric_and_must_name_tactics_of_the_set() -> None:
    ts = TacticSet(tactics=[tactic("a", conflicts=["b"]), tactic("b"), tactic("c")])
    assert ts.in_conflict("a", "b") and ts.in_conflict("b", "a")
    assert not ts.in_conflict("a", "c")
    with pytest.raises(ValidationError, match="conflicts with 'zz', which is not a tactic"):
        TacticSet(tactics=[tactic("a", conflicts=["zz"])])
    with pytest.raises(ValidationError, match="lists itself"):
        tactic("a", conflicts=["a"])
    with pytest.raises(ValidationError, match="'b' appears twice in 'conflicts'"):
        tactic("a", conflicts=["b", "b"])
    with pytest.raises(ValidationError, match="tactic name 'a' is used twice"):
        TacticSet(tactics=[tactic("a"), tactic("a")])


def test_a_goal_is_named_once_per_condition_list() -> None:
    with pytest.raises(ValidationError, match="goal G3 appears twice in the preconditions"):
        tactic(preconditions=[*PRE, GoalState(goal="G3", state="satisfied")])
    with pytest.raises(ValidationError, match="goal G1 appears twice in the postconditions"):
        tactic(postconditions=[GoalState(goal="G1", state="satisfied")] * 2)


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (lambda: tactic(preconditions=[]), "at least 1 item"),
        (lambda: tactic(actions=[]), "at least 1 item"),
        (lambda: tactic(name="  "), "must not be empty"),
        (lambda: tactic(name="a\nb"), "control character U+000A"),
        (lambda: tactic(deadline=0), "greater than 0"),
        (lambda: tactic(deadline=float("inf")), "finite number"),
        (lambda: tactic(cooldown=-1), "greater than or equal to 0"),
        (lambda: GoalState(goal="3G", state="satisfied"), "'3G' is not a goal id"),
        (lambda: GoalState(goal="G3", state="broken"), "'satisfied', 'unsatisfied' or"),
        (lambda: ExpressionCondition(expression="  \n "), "must not be empty"),
        (lambda: PublishAction(topic="rover/x", payload={}), "not a ROS-style name"),
        (lambda: PublishAction(topic="/a//b", payload={}), "not a ROS-style name"),
        (lambda: PublishAction(topic="/a"), "Field required"),  # type: ignore[call-arg]
        (lambda: PublishAction(topic="/a", payload={"x": float("nan")}), "nan is not allowed"),
        (lambda: PublishAction(topic="/a", payload={"x": [1, {"y": "\x00"}]}), "U+0000"),
        (lambda: PublishAction(topic="/a", payload={"": 1}), "payload key '' is empty"),
        (lambda: RequestAction(service="/a", timeout=0), "greater than 0"),
        (lambda: ChangeModeAction(mode="manual"), "Field required"),  # type: ignore[call-arg]
        (lambda: ChangeModeAction(service="/a", mode="two words"), "without spaces"),
        (SwapModelAction, "say what to swap to"),
        (lambda: SwapModelAction(model="m", domain="fog"), "not both"),
        (lambda: NotifyAction(channel="sms", message="m"), "'email', 'webhook' or 'log'"),
        (lambda: NotifyAction(channel="email", message="m"), "needs 'to'"),
        (lambda: NotifyAction(channel="email", to="ops", message="m"), "not an e-mail address"),
        (lambda: NotifyAction(channel="webhook", message="m"), "needs 'to': an http(s) URL"),
        (lambda: NotifyAction(channel="webhook", to="ftp://x", message="m"), "not an http(s)"),
        (lambda: NotifyAction(channel="log", message=" "), "must not be empty"),
        (
            lambda: NotifyAction(channel="log", subject="a\r\nBcc: x@y.z", message="m"),
            "control character U+000D",
        ),
    ],
)
def test_invalid_values_are_refused(build: Any, message: str) -> None:
    with pytest.raises(ValidationError, match=re.escape(message)):
        build()


def test_text_is_stripped_and_dedented_like_a_docstring() -> None:
    t = tactic(description="\n    First line.\n      indented\n\n    last\n  ")
    assert t.description == "First line.\n  indented\n\nlast"
    assert tactic(description=t.description).description == t.description
    assert tactic(name="  spaced name ").name == "spaced name"


def test_payloads_keep_their_json_types() -> None:
    payload = {"b": True, "i": 1, "f": 1.0, "s": "1", "n": None, "l": [1, "x"], "d": {"k": 0}}
    action = PublishAction(topic="/a", payload=payload)
    assert action.payload == payload
    assert [type(v) for v in action.payload.values()] == [
        bool,
        int,
        float,
        str,
        type(None),
        list,
        dict,
    ]


def test_references_of_tactics_built_in_code_have_no_lines() -> None:
    t = tactic(
        "swap",
        preconditions=[ExpressionCondition(expression="A4.category >= 1"), *PRE],
        actions=[
            SwapModelAction(model="m1"),
            NotifyAction(channel="log", message="swapped"),
            PublishAction(topic="/rover/buzzer", payload={"on": True}),
            RequestAction(service="/x", payload={"a": [1]}),
        ],
        postconditions=[GoalState(goal="G3", state="satisfied")],
    )
    assert [(e.expression, e.element, e.line) for e in t.expressions()] == [
        ("A4.category >= 1", "tactics[swap].preconditions[0]", None)
    ]
    assert list(t.referenced_goals()) == ["G3"]
    assert [g.element for g in t.referenced_goals()["G3"]] == [
        "tactics[swap].preconditions[1]",
        "tactics[swap].postconditions[0]",
    ]
    assert t.referenced_endpoints() == [
        EndpointReference(
            "service",
            "/lm_manager/swap",
            {"lec": "detector", "model": "m1"},
            "tactics[swap].actions[0]",
            None,
        ),
        EndpointReference("topic", "/rover/buzzer", {"on": True}, "tactics[swap].actions[2]", None),
        EndpointReference("service", "/x", {"a": [1]}, "tactics[swap].actions[3]", None),
    ]
    ts = TacticSet(tactics=[t, tactic("other")])
    assert len(ts.referenced_endpoints()) == 4
    assert [g.element for g in ts.referenced_goals()["G3"]][-1] == "tactics[other].preconditions[0]"
    assert len(ts.expressions()) == 1
