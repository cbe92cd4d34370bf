"""The two file forms: the examples, every element in both, lines, and form-specific errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from anunnaki.errors import ModelFileError
from anunnaki.tactics import (
    ChangeModeAction,
    EndpointReference,
    ExpressionCondition,
    ExpressionReference,
    GoalReference,
    GoalState,
    NotifyAction,
    PublishAction,
    RequestAction,
    SourceRef,
    SwapModelAction,
    Tactic,
    TacticSet,
    dump_tactics_xml,
    dump_tactics_yaml,
    load_tactics,
    parse_tactics_xml,
    parse_tactics_yaml,
)

ROVER = Path(__file__).resolve().parents[2] / "examples" / "rover"

FAIL_SAFE = TacticSet(
    name="rover",
    tactics=[
        Tactic(
            name="fail-safe",
            description="Hand the rover to a human when detection can no longer be trusted.",
            priority=100,
            cooldown=30,
            preconditions=[GoalState(goal="G3", state="unsatisfied")],
            actions=[
                ChangeModeAction(service="set_mode", mode="manual"),
                NotifyAction(
                    channel="email",
                    to="operator@example.com",
                    subject="Rover switched to manual",
                    message="Object detection is degraded; the rover is now in manual mode.",
                ),
            ],
            postconditions=[GoalState(goal="G3", state="satisfied")],
            deadline=5,
        )
    ],
)


def test_both_rover_examples_hold_the_papers_fail_safe_tactic() -> None:
    from_xml = load_tactics(ROVER / "tactics.xml")
    from_yaml = load_tactics(ROVER / "tactics.yaml")
    assert from_xml == from_yaml
    assert from_xml.tactic("fail-safe") == FAIL_SAFE.tactics[0]
    assert [t.name for t in from_xml.by_priority()] == [
        "collision-stop",
        "fail-safe",
        "warn-pedestrians",
    ]
    assert from_xml.source == SourceRef(str(ROVER / "tactics.xml"), 5)
    assert from_yaml.tactics[0].source == SourceRef(str(ROVER / "tactics.yaml"), 7)
    # What `anunnaki check` compares with the rover's goal model and platform binding.
    assert from_xml.referenced_goals()["G3"] == [
        GoalReference("tactics[fail-safe].preconditions[0]", 9),
        GoalReference("tactics[fail-safe].postconditions[0]", 16),
    ]
    assert from_yaml.referenced_endpoints()[0] == EndpointReference(
        "service", "set_mode", {"mode": "manual"}, "tactics[fail-safe].actions[0]", 14
    )
    assert from_xml.expressions() == []


ALL_YAML = """\
anunnaki: tactics/1
name: everything
tactics:
  - name: all-actions
    description: |
      Every action type,
      and both precondition forms.
    priority: -3
    preconditions:
      - goal: G3
        state: unsatisfied
      - expression: "A4.category >= 1 and A2.rate < 5.0"
      - goal: G7
        state: unknown
    actions:
      - type: publish
        topic: /rover/buzzer
        payload:
          on: true
          volume: 3
          gain: 0.5
          pattern: " beep "
          label: loud
          steps: [1, 2.5, null, {a: b}]
          nothing: null
      - type: request
        service: /rover/lights
        payload: {level: 2}
        timeout: 0.5
      - type: request
        service: /rover/reset
      - type: change_mode
        service: /rover/set_mode
        mode: manual
      - type: swap_model
        domain: dark
      - type: swap_model
        lec: planner
        model: planner-v2
        service: /models/swap
      - type: notify
        channel: email
        to: operator@example.com
        subject: Rover switched to manual
        message: Detection is degraded.
      - type: notify
        channel: webhook
        to: https://hooks.example.com/rover?x=1&y=2
        message: '<b>"degraded"</b> & more'
      - type: notify
        channel: log
        message: plain log line
    postconditions:
      - goal: G3
        state: satisfied
    deadline: 2.5
    cooldown: 60
    requires_approval: true
    conflicts: [other]
  - name: other
    preconditions:
      - expression: A1.ok == 0
    actions:
      - type: notify
        channel: log
        to: utu.plan
        message: other
"""

ALL_XML = """\
<?xml version="1.0" encoding="UTF-8"?>
<tactics name="everything">
  <tactic name="all-actions" priority="-3" cooldown="60" requires_approval="true">
    <description>
      Every action type,
      and both precondition forms.
    </description>
    <preconditions>
      <goal id="G3" state="unsatisfied"/>
      <!-- an expression, kept as written -->
      <expression>A4.category &gt;= 1 and A2.rate &lt; 5.0</expression>
      <goal id="G7" state="unknown"/>
    </preconditions>
    <actions>
      <publish topic="/rover/buzzer">
        <field name="on" type="bool">true</field>
        <field name="volume" type="int">3</field>
        <field name="gain" type="float">0.5</field>
        <field name="pattern" type="json">" beep "</field>
        <field name="label">loud</field>
        <field name="steps" type="json">[1, 2.5, null, {"a": "b"}]</field>
        <field name="nothing" type="json">null</field>
      </publish>
      <request service="/rover/lights" timeout="0.5">
        <field name="level" type="int">2</field>
      </request>
      <request service="/rover/reset"/>
      <change_mode service="/rover/set_mode" mode="manual"/>
      <swap_model domain="dark"/>
      <swap_model lec="planner" model="planner-v2" service="/models/swap"/>
      <notify channel="email" to="operator@example.com" subject="Rover switched to manual">
        Detection is degraded.
      </notify>
      <notify channel="webhook" to="https://hooks.example.com/rover?x=1&amp;y=2"
        >&lt;b&gt;"degraded"&lt;/b&gt; &amp; more</notify>
      <notify channel="log">plain log line</notify>
    </actions>
    <postconditions deadline="2.5">
      <goal id="G3" state="satisfied"/>
    </postconditions>
    <conflicts>
      <tactic name="other"/>
    </conflicts>
  </tactic>
  <tactic name="other">
    <preconditions><expression>A1.ok == 0</expression></preconditions>
    <actions><notify channel="log" to="utu.plan">other</notify></actions>
  </tactic>
</tactics>
"""


def _everything() -> TacticSet:
    return TacticSet(
        name="everything",
        tactics=[
            Tactic(
                name="all-actions",
                description="Every action type,\nand both precondition forms.",
                priority=-3,
                preconditions=[
                    GoalState(goal="G3", state="unsatisfied"),
                    ExpressionCondition(expression="A4.category >= 1 and A2.rate < 5.0"),
                    GoalState(goal="G7", state="unknown"),
                ],
                actions=[
                    PublishAction(
                        topic="/rover/buzzer",
                        payload={
                            "on": True,
                            "volume": 3,
                            "gain": 0.5,
                            "pattern": " beep ",
                            "label": "loud",
                            "steps": [1, 2.5, None, {"a": "b"}],
                            "nothing": None,
                        },
                    ),
                    RequestAction(service="/rover/lights", payload={"level": 2}, timeout=0.5),
                    RequestAction(service="/rover/reset"),
                    ChangeModeAction(service="/rover/set_mode", mode="manual"),
                    SwapModelAction(domain="dark"),
                    SwapModelAction(lec="planner", model="planner-v2", service="/models/swap"),
                    NotifyAction(
                        channel="email",
                        to="operator@example.com",
                        subject="Rover switched to manual",
                        message="Detection is degraded.",
                    ),
                    NotifyAction(
                        channel="webhook",
                        to="https://hooks.example.com/rover?x=1&y=2",
                        message='<b>"degraded"</b> & more',
                    ),
                    NotifyAction(channel="log", message="plain log line"),
                ],
                postconditions=[GoalState(goal="G3", state="satisfied")],
                deadline=2.5,
                cooldown=60,
                requires_approval=True,
                conflicts=["other"],
            ),
            Tactic(
                name="other",
                preconditions=[ExpressionCondition(expression="A1.ok == 0")],
                actions=[NotifyAction(channel="log", to="utu.plan", message="other")],
            ),
        ],
    )


def test_every_action_and_precondition_form_reads_the_same_in_both_forms() -> None:
    from_yaml = parse_tactics_yaml(ALL_YAML, source="all.yaml")
    from_xml = parse_tactics_xml(ALL_XML, source="all.xml")
    expected = _everything()
    assert from_yaml == expected
    assert from_xml == expected
    payload = from_xml.tactics[0].actions[0]
    assert isinstance(payload, PublishAction)
    assert [type(v) for v in payload.payload.values()] == [
        bool,
        int,
        float,
        str,
        str,
        list,
        type(None),
    ]


def test_every_form_survives_dumping_in_both_forms() -> None:
    expected = _everything()
    for text in (dump_tactics_xml(expected), ALL_XML):
        assert parse_tactics_yaml(dump_tactics_yaml(parse_tactics_xml(text))) == expected
    for text in (dump_tactics_yaml(expected), ALL_YAML):
        assert parse_tactics_xml(dump_tactics_xml(parse_tactics_yaml(text))) == expected


def test_elements_remember_their_lines_in_both_forms() -> None:
    from_yaml = parse_tactics_yaml(ALL_YAML, source="all.yaml")
    from_xml = parse_tactics_xml(ALL_XML, source="all.xml")
    assert from_yaml.expressions() == [
        ExpressionReference(
            "A4.category >= 1 and A2.rate < 5.0", "tactics[all-actions].preconditions[1]", 12
        ),
        ExpressionReference("A1.ok == 0", "tactics[other].preconditions[0]", 62),
    ]
    assert [r.line for r in from_xml.expressions()] == [11, 46]
    assert from_yaml.referenced_goals()["G7"] == [
        GoalReference("tactics[all-actions].preconditions[2]", 13)
    ]
    assert from_xml.referenced_goals()["G3"] == [
        GoalReference("tactics[all-actions].preconditions[0]", 9),
        GoalReference("tactics[all-actions].postconditions[0]", 39),
    ]
    endpoints = from_xml.referenced_endpoints()
    assert [(e.kind, e.name, e.line) for e in endpoints] == [
        ("topic", "/rover/buzzer", 15),
        ("service", "/rover/lights", 24),
        ("service", "/rover/reset", 27),
        ("service", "/rover/set_mode", 28),
        ("service", "/lm_manager/swap", 29),
        ("service", "/models/swap", 30),
    ]
    assert [e.payload for e in endpoints[3:]] == [
        {"mode": "manual"},
        {"lec": "detector", "domain": "dark"},
        {"lec": "planner", "model": "planner-v2"},
    ]
    assert [e.line for e in from_yaml.referenced_endpoints()] == [16, 26, 30, 32, 35, 37]
    tactic = from_yaml.tactic("all-actions")
    assert tactic.source == SourceRef("all.yaml", 4)
    assert tactic.actions[6].source == SourceRef("all.yaml", 41)
    assert from_xml.tactic("other").actions[0].source == SourceRef("all.xml", 47)


def test_load_tactics_picks_the_form_by_extension_or_content(tmp_path: Path) -> None:
    cases = {
        "t.XML": ALL_XML,
        "t.yml": ALL_YAML,
        "t.tactics": "\ufeff" + ALL_XML,
        "t": "\n  " + ALL_XML.split("\n", 1)[1],
        "t.txt": ALL_YAML,
        "t.yaml": "\ufeff" + ALL_YAML,
    }
    for name, text in cases.items():
        (tmp_path / name).write_text(text, encoding="utf-8")
        loaded = load_tactics(tmp_path / name)
        assert loaded == _everything(), name
        assert loaded.source.path == str(tmp_path / name)
    (tmp_path / "wrong.xml").write_text(ALL_YAML, encoding="utf-8")
    with pytest.raises(ModelFileError, match=r"wrong\.xml:1: malformed XML"):
        load_tactics(tmp_path / "wrong.xml")
    with pytest.raises(ModelFileError, match="cannot read file"):
        load_tactics(tmp_path / "missing.yaml")


def test_text_without_a_source_is_named_input() -> None:
    with pytest.raises(ModelFileError, match=r"^<input>:1: malformed XML"):
        parse_tactics_xml("<tactics>")
    with pytest.raises(ModelFileError, match=r"^<input>:2: tactics: Input should be a valid list"):
        parse_tactics_yaml("anunnaki: tactics/1\ntactics: 5\n")
    assert parse_tactics_xml("<tactics/>").source == SourceRef(None, 1)


def _xml_error(body: str) -> str:
    with pytest.raises(ModelFileError) as info:
        parse_tactics_xml(body, source="t.xml")
    return str(info.value)


def _tactic_xml(inner: str, attrs: str = "") -> str:
    return f'<tactics>\n<tactic name="t"{attrs}>\n{inner}\n</tactic>\n</tactics>\n'


GOOD_PRE = '<preconditions><goal id="G3" state="unsatisfied"/></preconditions>'


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        (
            "<tactics><x/></tactics>",
            "t.xml:1: <x> is not allowed inside <tactics> (hint: <tactics>",
        ),
        ('<tactics xmlns="urn:x"/>', "XML namespaces are not used"),
        ("<tactics>stray</tactics>", "t.xml:1: unexpected text in <tactics>"),
        ('<tactics><tactic priority="1"/></tactics>', "<tactic> needs the attribute 'name'"),
        (
            _tactic_xml(GOOD_PRE + GOOD_PRE),
            "t.xml:3: tactics[t]: <preconditions> appears twice in one <tactic>",
        ),
        (_tactic_xml("<description><b>x</b></description>"), "<b> is not allowed inside"),
        (
            _tactic_xml('<preconditions><goal id="G3"/></preconditions>'),
            "needs the attribute 'state'",
        ),
        (
            _tactic_xml("<preconditions><expression a='1'>x</expression></preconditions>"),
            "unknown attribute 'a' on <expression> (hint: <expression> takes no attributes)",
        ),
        (
            _tactic_xml('<preconditions/>\n<actions><notify channel="log">x</notify></actions>'),
            "t.xml:3: tactics[t].preconditions: List should have at least 1 item",
        ),
        (
            _tactic_xml(
                '<preconditions>\n<goal id="G3" state="unknown">\ntext</goal></preconditions>'
            ),
            "t.xml:5: tactics[t].preconditions[0]: unexpected text in <goal>",
        ),
        (
            _tactic_xml("<conflicts><tactic/></conflicts>"),
            "<tactic> needs the attribute 'name'",
        ),
        (
            _tactic_xml("", ' priority="high"'),
            "t.xml:2: tactics[t].priority: Input should be a valid integer",
        ),
    ],
)
def test_xml_structure_errors(body: str, expected: str) -> None:
    assert expected in _xml_error(body)


@pytest.mark.parametrize(
    ("field", "expected"),
    [
        ('<field name="n" type="int">1.5</field>', "'1.5' is not a valid int (hint: e.g. 42)"),
        ('<field name="n" type="int">' + "9" * 5000 + "</field>", "integer too long"),
        ('<field name="n" type="float">nan</field>', "'nan' is not a valid float"),
        ('<field name="n" type="float">1e999</field>', "'1e999' is not a valid float"),
        (
            '<field name="n" type="bool">yes</field>',
            "'yes' is not a valid bool (hint: true or false)",
        ),
        ('<field name="n" type="json">NaN</field>', "invalid JSON: NaN is not allowed"),
        ('<field name="n" type="json">' + "[" * 100_000 + "</field>", "invalid JSON"),
        (
            '<field name="n" type="json">' + "[" * 20 + "]" * 20 + "</field>",
            "actions[0].payload.n: payload nested deeper than 16 levels",
        ),
        (
            '<field name="n" type="list">1</field>',
            "unknown field type 'list' (hint: field types: str, int",
        ),
        ('<field name="n">1</field><field name="n">2</field>', "payload field 'n' is given twice"),
        ('<field type="int">1</field>', "<field> needs the attribute 'name'"),
        ("<value>1</value>", "<value> is not allowed inside <publish>"),
        ('<field name="">1</field>', "payload key '' is empty"),
    ],
)
def test_xml_payload_field_errors(field: str, expected: str) -> None:
    body = _tactic_xml(GOOD_PRE + f'<actions><publish topic="/a">{field}</publish></actions>')
    message = _xml_error(body)
    assert message.startswith("t.xml:3: tactics[t].actions[0]"), message
    assert expected in message


def test_xml_hostile_and_oversized_input_is_refused_before_parsing() -> None:
    with pytest.raises(ModelFileError, match="over the limit of 4000000"):
        parse_tactics_xml("<tactics>" + " " * 4_000_000 + "</tactics>")
    with pytest.raises(ModelFileError, match="cannot encode"):
        parse_tactics_xml("<tactics name='\ud800'/>")
    entity = '<!DOCTYPE t [<!ENTITY e "x">]>\n<tactics name="&e;"/>'
    with pytest.raises(ModelFileError, match=r"^<input>:1: refused: a DTD"):
        parse_tactics_xml(entity)
    deep = "<tactics>" + "<a>" * 40 + "</a>" * 40 + "</tactics>"
    with pytest.raises(ModelFileError, match="nested deeper than 32"):
        parse_tactics_xml(deep)


def test_yaml_specific_errors() -> None:
    with pytest.raises(ModelFileError, match=r"^<input>:1: a tactics file is a YAML mapping"):
        parse_tactics_yaml("- a\n")
    with pytest.raises(ModelFileError, match="the file is empty"):
        parse_tactics_yaml("")
    with pytest.raises(ModelFileError, match=r"^<input>:2: tactics\[0\]: cannot read value"):
        parse_tactics_yaml("anunnaki: tactics/1\ntactics: [" + "1" * 5000 + "]\n")
    with pytest.raises(
        ModelFileError, match=r":3: tactics\[0\]\.name: Input should be a valid string"
    ):
        parse_tactics_yaml("anunnaki: tactics/1\ntactics:\n  - name: 2024-01-01\n")
    with pytest.raises(ModelFileError, match="an action is a mapping with a 'type'") as info:
        parse_tactics_yaml(
            "anunnaki: tactics/1\ntactics:\n  - name: t\n"
            "    preconditions: [{goal: G1, state: unknown}]\n    actions: [notify]\n"
        )
    assert "valid action types" in str(info.value)
    with pytest.raises(ModelFileError, match="the action has no 'type'"):
        parse_tactics_yaml(
            "anunnaki: tactics/1\ntactics:\n  - name: t\n"
            "    preconditions: [{goal: G1, state: unknown}]\n    actions: [{topic: /a}]\n"
        )


def test_several_problems_report_the_first_in_the_file() -> None:
    text = (
        "anunnaki: tactics/1\n"
        "tactics:\n"
        "  - name: t\n"
        "    preconditions: [{goal: G1, state: bad}]\n"
        "    actions: []\n"
        "    deadline: 0\n"
    )
    with pytest.raises(ModelFileError) as info:
        parse_tactics_yaml(text)
    assert info.value.line == 4
    assert "(and 2 more problems)" in info.value.message
