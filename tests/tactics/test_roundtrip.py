"""XML and YAML hold the same tactics: dumping and loading in either form loses nothing."""

from __future__ import annotations

import json
from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from anunnaki.tactics import (
    ChangeModeAction,
    ExpressionCondition,
    GoalState,
    NotifyAction,
    PublishAction,
    RequestAction,
    SwapModelAction,
    Tactic,
    TacticSet,
    dump_tactics_xml,
    dump_tactics_yaml,
    parse_tactics_xml,
    parse_tactics_yaml,
)

# Any character a text file can hold, except control characters (tab and newline aside).
_chars = st.characters(codec="utf-8", exclude_categories=("Cc", "Cs", "Cn"))
text = st.text(st.one_of(_chars, st.sampled_from("\n\t <>&\"'")), max_size=12)
line = st.text(st.one_of(_chars, st.sampled_from(" <>&\"'")), max_size=12)
word = st.text(
    st.characters(codec="utf-8", exclude_categories=("Cc", "Cs", "Cn", "Zs", "Zl", "Zp")),
    min_size=1,
    max_size=8,
)
goal_id = st.from_regex(r"[A-Za-z][A-Za-z0-9_\-]{0,6}", fullmatch=True)
ros_name = st.lists(
    st.from_regex(r"[A-Za-z0-9_]{1,5}", fullmatch=True), min_size=1, max_size=3
).map(lambda parts: "/" + "/".join(parts))
seconds = st.floats(min_value=0.001, max_value=1e6, allow_nan=False, allow_infinity=False)
payload_key = st.text(st.one_of(_chars, st.just(" ")), min_size=1, max_size=6)
scalar = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(10**20), max_value=10**20),
    st.floats(allow_nan=False, allow_infinity=False),
    text,
)
payload = st.dictionaries(
    payload_key,
    st.recursive(
        scalar,
        lambda inner: st.lists(inner, max_size=3) | st.dictionaries(payload_key, inner, max_size=3),
        max_leaves=6,
    ),
    max_size=3,
)
goal_state = st.builds(
    GoalState, goal=goal_id, state=st.sampled_from(["satisfied", "unsatisfied", "unknown"])
)
expression = st.builds(ExpressionCondition, expression=text.filter(lambda s: s.strip() != ""))
action = st.one_of(
    st.builds(PublishAction, topic=ros_name, payload=payload),
    st.builds(RequestAction, service=ros_name, payload=payload, timeout=seconds),
    st.builds(ChangeModeAction, service=ros_name, mode=word),
    st.builds(SwapModelAction, lec=word, model=word, service=ros_name),
    st.builds(SwapModelAction, domain=word),
    st.builds(
        NotifyAction,
        channel=st.just("email"),
        to=st.just("ops@example.com"),
        subject=line,
        message=text.filter(lambda s: s.strip() != ""),
    ),
    st.builds(
        NotifyAction,
        channel=st.just("webhook"),
        to=st.just("https://hooks.example.com/x?a=1&b=2"),
        message=st.just("m"),
    ),
    st.builds(NotifyAction, channel=st.just("log"), to=st.none() | word, message=st.just("m")),
)


def _unique_goals(conditions: list[Any]) -> list[Any]:
    seen: set[str] = set()
    out = []
    for cond in conditions:
        if isinstance(cond, GoalState):
            if cond.goal in seen:
                continue
            seen.add(cond.goal)
        out.append(cond)
    return out


tactic_names = st.lists(line.map(str.strip).filter(bool), min_size=0, max_size=3, unique=True)
preconditions = st.lists(goal_state | expression, min_size=1, max_size=3).map(_unique_goals)
postconditions = st.lists(goal_state, max_size=2).map(_unique_goals)
actions = st.lists(action, min_size=1, max_size=3)
priorities = st.integers(-1000, 1000)
cooldowns = st.just(0.0) | seconds
set_names = st.none() | line.map(str.strip).filter(bool)


@st.composite
def tactic_sets(draw: st.DrawFn) -> TacticSet:
    names = draw(tactic_names)
    tactics = []
    for name in names:
        others = [n for n in names if n != name]
        tactics.append(
            Tactic(
                name=name,
                description=draw(text),
                priority=draw(priorities),
                preconditions=draw(preconditions) or [GoalState(goal="G1", state="unknown")],
                actions=draw(actions),
                postconditions=draw(postconditions),
                deadline=draw(seconds),
                cooldown=draw(cooldowns),
                requires_approval=draw(st.booleans()),
                conflicts=draw(st.lists(st.sampled_from(others), unique=True)) if others else [],
            )
        )
    return TacticSet(name=draw(set_names), tactics=tactics)


def _canonical(ts: TacticSet) -> str:
    # ``==`` cannot tell True from 1 or 1.0 from 1; JSON can.
    return json.dumps(ts.model_dump(mode="json"), sort_keys=True)


def _same(a: TacticSet, b: TacticSet) -> None:
    assert a == b
    assert _canonical(a) == _canonical(b)


@settings(max_examples=30, deadline=None, database=None)
@given(tactic_sets())
def test_round_trips_between_xml_and_yaml(ts: TacticSet) -> None:
    yaml_text = dump_tactics_yaml(ts)
    from_yaml = parse_tactics_yaml(yaml_text)  # YAML → model
    _same(from_yaml, ts)
    from_xml = parse_tactics_xml(dump_tactics_xml(from_yaml))  # YAML → XML → model
    _same(from_xml, ts)
    # XML → YAML writes the very text that was just read back equal.
    assert dump_tactics_yaml(from_xml) == yaml_text
