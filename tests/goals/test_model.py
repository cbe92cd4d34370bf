"""Loading and resolving goal models: bindings, endpoints, roots, findings, and RELAX end to end."""

from __future__ import annotations

from pathlib import Path

import pytest

from anunnaki.errors import ModelFileError
from anunnaki.goals import (
    Binding,
    Evaluator,
    GoalModel,
    load_binding,
    load_goal_model,
    parse_binding,
    parse_goal_model,
)

EXAMPLES = Path(__file__).parents[2] / "examples"
ROVER = EXAMPLES / "rover"

SMALL = """\
anunnaki: goal-model/1
name: small
agents:
  - id: A1
    topics: [{topic: /inline/a1, attributes: [x, mode]}]
  - id: A2
goals:
  - id: G1
    refinement: and
    children: [G2, G3]
  - id: G2
    utility: A1.x >= 1
    agents: [A1]
  - id: G3
    utility: A2.ok == true
    agents: [A2]
endpoints:
  - name: /inline/stop
    kind: service
  - name: /shared/mode
    kind: service
    payload: {mode: string}
"""

BINDING = """\
anunnaki: binding/1
platform: lab
agents:
  A1:
    staleness: 0.5
    topics:
      - topic: /lab/a1
        attributes: {x: data.value, mode: control_mode}
      - topic: /lab/a1_extra
        attributes: [temperature]
  A2:
    topics:
      - topic: /lab/a2
        attributes: [ok]
endpoints:
  - name: /lab/buzzer
    kind: topic
    payload: {on: boolean}
  - name: /shared/mode
    kind: service
    payload: {mode: {type: string, enum: [auto, manual]}}
"""


def findings(model: GoalModel) -> list[str]:
    return [f.render() for f in model.findings]


def model_text(goals: str, *, head: str = "", extra: str = "") -> str:
    return (
        "anunnaki: goal-model/1\nname: t\n"
        + head
        + "agents:\n  - {id: A1, topics: [{topic: /a, attributes: [x, y, p, e]}]}\n"
        + "goals:\n"
        + goals
        + extra
    )


# -- the load APIs --------------------------------------------------------------------------


def test_load_goal_model_takes_a_binding_path_or_a_loaded_binding() -> None:
    by_path = load_goal_model(ROVER / "goals.yaml", ROVER / "binding.yaml")
    binding = load_binding(ROVER / "binding.yaml")
    assert isinstance(binding, Binding)
    assert binding.platform == "rover-sim"
    by_object = load_goal_model(ROVER / "goals.yaml", binding)
    as_str = load_goal_model(str(ROVER / "goals.yaml"), str(ROVER / "binding.yaml"))
    for m in (by_path, by_object, as_str):
        assert m.name == "rover"
        assert m.root == "G1"
        assert m.path == str(ROVER / "goals.yaml")
        assert m.binding is not None
        assert m.binding.path == str(ROVER / "binding.yaml")
        assert m.agents["A3"].topics[0].topic == "/rover/ultrasonic"
        assert m.findings == []
    assert by_object.binding is binding


def test_parse_goal_model_names_its_source_in_errors() -> None:
    model = parse_goal_model(SMALL, source="small.yaml", binding=parse_binding(BINDING))
    assert model.path == "small.yaml"
    with pytest.raises(
        ModelFileError, match=r"^small\.yaml:15: goals\[G3\]\.agents: unknown agent 'A2'"
    ):
        parse_goal_model(SMALL.replace("  - id: A2\n", ""), source="small.yaml")


def test_strict_loading_raises_the_first_error_and_lenient_loading_collects_them() -> None:
    text = SMALL.replace("A1.x >= 1", "A1.nope >= 1").replace("[G2, G3]", "[G2, G3, G9]")
    with pytest.raises(ModelFileError) as info:
        parse_goal_model(text, source="m.yaml")
    assert str(info.value).startswith("m.yaml:10: goals[G1].children: unknown child goal 'G9'")
    model = parse_goal_model(text, source="m.yaml", strict=False)
    assert findings(model) == [
        "m.yaml:10: error: goals[G1].children: unknown child goal 'G9' (hint: known: G1, G2, G3)",
        "m.yaml:12: error: goals[G2].utility: unknown attribute 'A1.nope' in 'A1.nope >= 1' "
        "(hint: A1 publishes: mode, x)",
        "m.yaml:6: error: agents[A2]: agent 'A2' publishes no topic, so what G3 read can "
        "never be observed (hint: bind A2 to a topic: pass the platform binding file, or give "
        "the agent 'topics:' in the goal model)",
    ]
    assert [f.severity for f in model.errors()] == ["error"] * 3


def test_a_shape_error_raises_even_when_lenient() -> None:
    with pytest.raises(
        ModelFileError, match=r"m\.yaml:10: goals\[G1\]\.threshold: Input should be less than"
    ):
        parse_goal_model(
            SMALL.replace("    refinement: and\n", "    refinement: and\n    threshold: 2\n"),
            source="m.yaml",
            strict=False,
        )


# -- bindings ---------------------------------------------------------------------------


def test_the_binding_replaces_inline_topics_and_staleness() -> None:
    inline = parse_goal_model(SMALL, strict=False)
    assert inline.agents["A1"].topics[0].topic == "/inline/a1"
    assert inline.agents["A1"].attributes == {
        "x": ("/inline/a1", "x"),
        "mode": ("/inline/a1", "mode"),
    }
    assert inline.agents["A1"].staleness == 2.0  # the model's default

    bound = parse_goal_model(SMALL, binding=parse_binding(BINDING))
    a1 = bound.agents["A1"]
    assert [t.topic for t in a1.topics] == ["/lab/a1", "/lab/a1_extra"]
    assert a1.primary_topic == "/lab/a1"  # what rate(A1) would measure
    assert a1.staleness == 0.5
    assert a1.attributes == {
        "x": ("/lab/a1", "data.value"),
        "mode": ("/lab/a1", "control_mode"),
        "temperature": ("/lab/a1_extra", "temperature"),
    }
    assert bound.agents["A2"].staleness == 2.0

    ev = Evaluator(bound)
    ev.observe("/inline/a1", {"x": 5}, 0.0)  # the inline topic is no longer read
    assert ev.value("A1.x") is None
    ev.observe("/lab/a1", {"data": {"value": 5}, "control_mode": "auto"}, 0.0)
    ev.observe("/lab/a2", {"ok": True}, 0.0)
    assert ev.value("A1.x") == 5
    assert ev.root.status is True


def test_one_goal_model_serves_two_platforms() -> None:
    sim = load_goal_model(ROVER / "goals.yaml", ROVER / "binding.yaml")
    ros = load_goal_model(ROVER / "goals.yaml", ROVER / "binding-ros.yaml")
    assert sim.spec == ros.spec
    assert sim.agents["A1"].attributes["mode"] == ("/rover/status", "mode")
    assert ros.agents["A1"].attributes["mode"] == ("/rover/controller/state", "control_mode")
    assert ros.agents["A2"].attributes["seq"] == ("/camera/image_info", "header.seq")
    # no binding: the rover's agents publish nothing, which lenient loading reports
    bare = load_goal_model(ROVER / "goals.yaml", strict=False)
    assert {f.element for f in bare.errors()} == {f"agents[A{i}]" for i in range(1, 5)}


def test_endpoints_merge_and_an_override_is_a_warning() -> None:
    model = parse_goal_model(SMALL, binding=parse_binding(BINDING, source="lab.yaml"))
    assert list(model.endpoints) == ["/inline/stop", "/shared/mode", "/lab/buzzer"]
    assert model.endpoints["/shared/mode"].payload["mode"].enum == ["auto", "manual"]
    assert model.endpoints["/lab/buzzer"].payload["on"].type == "boolean"
    assert findings(model) == [
        "lab.yaml:19: warning: endpoints[/shared/mode]: endpoint /shared/mode overrides the "
        "goal model's"
    ]
    # the same endpoint declared identically is no override
    same = BINDING.replace("{mode: {type: string, enum: [auto, manual]}}", "{mode: string}")
    assert parse_goal_model(SMALL, binding=parse_binding(same)).findings == []


def test_a_binding_maps_logical_endpoints_over_the_goal_models() -> None:
    inline = SMALL.replace(
        "  - name: /shared/mode\n", "  - name: /shared/mode\n    logical: mode\n"
    )
    inline = inline.replace(
        "  - name: /inline/stop\n", "  - name: /inline/stop\n    logical: stop\n"
    )
    lab = BINDING + "  - name: /lab/halt\n    logical: stop\n    kind: service\n"
    model = parse_goal_model(inline, binding=parse_binding(lab, source="lab.yaml"))
    assert model.logical == {"stop": "/lab/halt", "mode": "/shared/mode"}
    assert "/inline/stop" not in model.endpoints  # the platform put 'stop' elsewhere
    stop = model.endpoint("stop")
    assert stop is not None and stop.name == "/lab/halt"
    assert model.endpoint("/lab/buzzer") is model.endpoints["/lab/buzzer"]
    assert model.endpoint("horn") is None
    assert model.endpoint_name("stop") == "/lab/halt"
    # without the binding the goal model's own mapping holds
    assert parse_goal_model(inline, strict=False).endpoint_name("stop") == "/inline/stop"


def test_a_logical_name_mapped_twice_is_an_error() -> None:
    twice = BINDING.replace("    kind: topic\n", "    logical: horn\n    kind: topic\n")
    twice += "  - name: /lab/horn\n    logical: horn\n    kind: topic\n"
    model = parse_goal_model(SMALL, binding=parse_binding(twice, source="lab.yaml"), strict=False)
    assert (
        "lab.yaml:24: error: endpoints[/lab/horn].logical: logical endpoint 'horn' is mapped "
        "twice (/lab/buzzer and /lab/horn) (hint: map each logical name to one topic or "
        "service)"
    ) in findings(model)
    assert model.endpoint_name("horn") == "/lab/buzzer"  # the first one stands


def test_an_endpoint_declared_twice_is_an_error() -> None:
    twice = BINDING + "  - name: /lab/buzzer\n    kind: service\n"
    model = parse_goal_model(SMALL, binding=parse_binding(twice, source="lab.yaml"), strict=False)
    assert findings(model) == [
        "lab.yaml:19: warning: endpoints[/shared/mode]: endpoint /shared/mode overrides the "
        "goal model's",
        "lab.yaml:22: error: endpoints[/lab/buzzer]: endpoint /lab/buzzer is declared twice "
        "(hint: declare each topic or service once)",
    ]
    assert model.endpoints["/lab/buzzer"].kind == "topic"  # the first one stands
    inline = SMALL + "  - name: /inline/stop\n    kind: topic\n"
    model = parse_goal_model(inline, source="m.yaml", binding=parse_binding(BINDING), strict=False)
    assert [f.render() for f in model.errors()] == [
        "m.yaml:23: error: endpoints[/inline/stop]: endpoint /inline/stop is declared twice "
        "(hint: declare each topic or service once)"
    ]


def test_a_binding_agent_the_model_does_not_declare_is_an_error() -> None:
    extra = BINDING.replace("endpoints:\n", "  A9:\n    topics: [{topic: /x}]\nendpoints:\n", 1)
    model = parse_goal_model(SMALL, binding=parse_binding(extra, source="lab.yaml"), strict=False)
    assert (
        "lab.yaml:15: error: agents.A9: binding names agent 'A9', which the goal model does "
        "not declare (hint: declared agents: A1, A2)"
    ) in findings(model)


def test_topic_routes_lists_who_reads_each_topic() -> None:
    model = load_goal_model(ROVER / "goals.yaml", ROVER / "binding-ros.yaml")
    routes = model.topic_routes()
    assert routes["/rover/controller/state"] == [
        (
            "A1",
            {
                "mode": "control_mode",
                "buzzer": "buzzer_on",
                "bumper": "bumper_pressed",
                "lights": "lights_on",
            },
        )
    ]
    assert routes["/utu/oracle/output"] == [
        ("A4", {"category": "category", "confidence": "confidence"})
    ]
    assert set(routes) == {
        "/rover/controller/state",
        "/camera/image_info",
        "/ultrasonic/range",
        "/utu/oracle/output",
    }


def test_two_agents_may_share_a_topic() -> None:
    text = (
        "anunnaki: goal-model/1\nname: t\nagents:\n"
        "  - {id: A1, topics: [{topic: /s, attributes: {a: left}}]}\n"
        "  - {id: A2, topics: [{topic: /s, attributes: {a: right}}]}\n"
        "goals: [{id: G1, utility: A1.a > A2.a}]\n"
    )
    model = parse_goal_model(text)
    assert model.topic_routes() == {"/s": [("A1", {"a": "left"}), ("A2", {"a": "right"})]}
    ev = Evaluator(model)
    ev.observe("/s", {"left": 2, "right": 1}, 0.0)
    assert ev.root.status is True


def test_topics_under_srv_are_reserved_for_services() -> None:
    with pytest.raises(ModelFileError, match="the first part '/srv' is reserved for services"):
        parse_binding(BINDING.replace("/lab/a2", "/srv/a2"))
    with pytest.raises(ModelFileError, match=r"endpoints\[/srv/beep\]: .*reserved"):
        parse_binding(BINDING.replace("- name: /lab/buzzer", "- name: /srv/beep"))
    # a service may live there, and a topic merely starting with 'srv' is fine
    parse_binding(BINDING.replace("/shared/mode", "/srv/mode").replace("/lab/a2", "/srvx/a2"))


# -- the root ---------------------------------------------------------------------------


def test_root_explicit() -> None:
    model = parse_goal_model(
        model_text(
            "  - {id: G1, utility: A1.x == 1}\n  - {id: G2, utility: A1.y == 1}\n",
            head="root: G2\n",
        ),
        strict=False,
    )
    assert model.root == "G2"
    # G1 is then outside the tree: a warning, not an error
    assert [f.severity for f in model.findings] == ["warning"]
    assert "goal 'G1' is not under the root goal G2" in model.findings[0].message


def test_root_is_the_single_goal_that_refines_nothing() -> None:
    model = parse_goal_model(
        model_text(
            "  - {id: G2, utility: A1.x == 1}\n"
            "  - {id: G1, refinement: or, children: [G2, G3]}\n"
            "  - {id: G3, utility: A1.y == 1}\n"
        )
    )
    assert model.root == "G1"
    assert model.parents == {"G2": ["G1"], "G3": ["G1"]}


def test_resolution_goals_are_not_root_candidates() -> None:
    model = parse_goal_model(
        model_text(
            "  - {id: G9, utility: A1.y == 1}\n  - {id: G1, utility: A1.x == 1}\n",
            extra="obstacles:\n  - {id: O1, obstructs: [G1], condition: A1.p == 1, "
            "resolutions: [G9]}\n",
        )
    )
    assert model.root == "G1"
    assert model.findings == []
    assert model.obstructed_by == {"G1": ["O1"]}


def test_several_tops_are_an_error_and_an_unknown_root_falls_back() -> None:
    two = model_text("  - {id: G1, utility: A1.x == 1}\n  - {id: G2, utility: A1.y == 1}\n")
    model = parse_goal_model(two, source="m.yaml", strict=False)
    assert findings(model) == [
        "m.yaml:5: error: goals: several goals refine nothing (G1, G2); which is the root? "
        "(hint: add 'root: G1' at the top, or make the others children)"
    ]
    unknown = parse_goal_model(
        model_text("  - {id: G1, utility: A1.x == 1}\n", head="root: G7\n"), strict=False
    )
    assert unknown.root == "G1"
    assert unknown.errors()[0].message == "root goal 'G7' is not defined"


# -- ids, cycles and other findings -------------------------------------------------------


def test_duplicate_ids_across_sections_are_errors() -> None:
    text = model_text(
        "  - {id: G1, utility: A1.x == 1}\n  - {id: A1, utility: A1.y == 1}\n",
        head="root: G1\n",
        extra="obstacles:\n  - {id: G1, obstructs: [G1], condition: A1.p == 1}\n",
    )
    model = parse_goal_model(text, source="m.yaml", strict=False)
    errors = [f.render() for f in model.errors()]
    assert errors == [
        "m.yaml:8: error: goals[A1]: duplicate id 'A1' (first defined in agents at line 5) "
        "(hint: ids must be unique across agents, goals, obstacles and domain properties)",
        "m.yaml:10: error: obstacles[G1]: duplicate id 'G1' (first defined in goals at line 7) "
        "(hint: ids must be unique across agents, goals, obstacles and domain properties)",
    ]


def test_a_cycle_is_reported_and_the_model_still_evaluates_leniently() -> None:
    text = model_text(
        "  - {id: G1, refinement: and, children: [G2, G3]}\n"
        "  - {id: G2, refinement: or, children: [G4, G1]}\n"
        "  - {id: G3, utility: A1.x == 1}\n"
        "  - {id: G4, utility: A1.y == 1}\n",
        head="root: G1\n",
    )
    with pytest.raises(ModelFileError, match="refinement cycle G1 -> G2 -> G1"):
        parse_goal_model(text)
    model = parse_goal_model(text, source="m.yaml", strict=False)
    assert findings(model) == [
        "m.yaml:8: error: goals[G2].children: refinement cycle G1 -> G2 -> G1 "
        "(hint: a goal may not (indirectly) refine itself)"
    ]
    assert model.goals["G2"].children == ["G4"]  # the edge that closes the cycle is cut
    ev = Evaluator(model)
    ev.observe("/a", {"x": 1, "y": 1}, 0.0)
    assert ev.root.status is True
    ev.observe("/a", {"x": 1, "y": 0}, 0.1)
    assert ev.root.status is False


def test_a_goal_refining_itself_is_a_cycle() -> None:
    text = model_text(
        "  - {id: G1, refinement: and, children: [G1, G2]}\n  - {id: G2, utility: A1.x == 1}\n"
    )
    model = parse_goal_model(text, strict=False)
    assert [f.message for f in model.errors()] == ["refinement cycle G1 -> G1"]


def test_a_resolution_that_depends_on_the_goal_it_rescues_is_refused_by_the_evaluator() -> None:
    text = model_text(
        "  - {id: G1, utility: A1.x == 1}\n",
        extra="obstacles:\n"
        "  - {id: O1, obstructs: [G1], condition: A1.p == 1, resolutions: [G1]}\n",
    )
    model = parse_goal_model(text)
    with pytest.raises(ModelFileError, match="dependencies form a cycle through G1"):
        Evaluator(model)


@pytest.mark.parametrize(
    ("goals", "extra", "expected"),
    [
        (
            "  - {id: G1, refinement: and, children: [G2], threshold: 0.5}\n"
            "  - {id: G2, utility: A1.x == 1}\n",
            "",
            "warning: goals[G1].threshold: 'threshold' is ignored on a refined goal",
        ),
        (
            "  - {id: G1, refinement: or, children: [G2, G2]}\n  - {id: G2, utility: A1.x == 1}\n",
            "",
            "warning: goals[G1].children: child goal 'G2' is listed twice",
        ),
        (
            "  - {id: G1, utility: A1.x == 1}\n",
            "obstacles:\n  - {id: O1, obstructs: [G1], condition: \"'fog'\"}\n",
            "error: obstacles[O1].condition: condition ''fog'' is a string",
        ),
        (
            "  - {id: G1, utility: \"'manual'\"}\n",
            "",
            "error: goals[G1].utility: utility ''manual'' is a string",
        ),
        (
            "  - {id: G1, utility: A1.x == 1}\n",
            "obstacles:\n  - {id: O1, obstructs: [G1]}\n",
            "error: obstacles[O1]: obstacle without a condition",
        ),
        (
            "  - {id: G1, utility: A1.x == 1, agents: [A7]}\n",
            "",
            "error: goals[G1].agents: unknown agent 'A7'",
        ),
        (
            "  - {id: G1, utility: A1.x == 1}\n",
            "obstacles:\n  - {id: O1, obstructs: [G1], condition: A1.p, resolutions: [G8]}\n",
            "error: obstacles[O1].resolutions: unknown resolution goal 'G8'",
        ),
        (
            "  - {id: G1, utility: 0.5 + 0.5}\n",
            "",
            "warning: goals[G1]: leaf goal without a responsible agent",
        ),
    ],
)
def test_findings_on_questionable_models(goals: str, extra: str, expected: str) -> None:
    model = parse_goal_model(model_text(goals, extra=extra), source="m.yaml", strict=False)
    assert any(
        f.render().startswith("m.yaml:") and expected in f.render() for f in model.findings
    ), findings(model)


@pytest.mark.parametrize("agent", ["A-1", "rate", "true", "min"])
def test_an_agent_id_that_expressions_cannot_name_is_a_warning(agent: str) -> None:
    text = (
        "anunnaki: goal-model/1\nname: t\nagents:\n"
        f"  - {{id: '{agent}', topics: [{{topic: /a, attributes: [x]}}]}}\n"
        "  - {id: A2, topics: [{topic: /b, attributes: [x]}]}\n"
        "goals: [{id: G1, utility: A2.x == 1, agents: [A2]}]\n"
    )
    model = parse_goal_model(text, source="m.yaml", strict=False)
    assert findings(model) == [
        f"m.yaml:4: warning: agents[{agent}]: agent id '{agent}' cannot be named in expressions "
        "(hint: use letters, digits and '_' only, and none of the words and, or, not, in, has, "
        "no, true, false, rate, min, max, abs)"
    ]


def test_the_examples_load_without_findings() -> None:
    for name in ("rover", "uav"):
        model = load_goal_model(EXAMPLES / name / "goals.yaml", EXAMPLES / name / "binding.yaml")
        assert model.findings == []


# -- RELAX end to end through the evaluator ----------------------------------------------

MAY_OR = """\
anunnaki: goal-model/1
name: may-or
root: G1
agents:
  - {id: A2, topics: [{topic: /lidar, attributes: [ok]}]}
  - {id: A3, topics: [{topic: /sonar, attributes: [quality]}]}
goals:
  - id: G1
    refinement: and
    children: [G2, G3]
  - id: G2
    description: MAY the lidar work OR the sonar give a good echo
    relax: {operator: may_or, alternatives: ["A2.ok == true", "A3.quality"]}
    threshold: 0.5
  - id: G3
    description: avoid both range sensors failing at once
    objective: avoid
    relax: {operator: may_or, alternatives: ["A2.ok == false and A3.quality < 0.2", "false"]}
    threshold: 1.0
"""


def test_may_or_alternatives_are_evaluated_end_to_end() -> None:
    model = parse_goal_model(MAY_OR)
    assert [str(model.expressions[("G2", f"alternative{i}")].text) for i in range(2)] == [
        "A2.ok == true",
        "A3.quality",
    ]
    ev = Evaluator(model)
    g2 = lambda: (ev.state("G2").utility, ev.state("G2").status)  # noqa: E731
    assert g2() == (None, None)
    ev.observe("/sonar", {"quality": 0.3}, 0.0)
    assert g2() == (None, None)  # max(?, 0.3): the lidar could still be fine
    ev.observe("/lidar", {"ok": False}, 0.1)
    assert g2() == (pytest.approx(0.3), False)  # fuzzy OR = max(0, 0.3), under 0.5
    ev.observe("/sonar", {"quality": 0.7}, 0.2)
    assert g2() == (pytest.approx(0.7), True)
    assert ev.root.status is True
    ev.observe("/sonar", {"quality": 0.1}, 0.3)
    assert ev.state("G3").utility == 0.0  # avoid: both failing -> 1 - 1
    assert ev.root.status is False
    ev.observe("/lidar", {"ok": True}, 0.4)
    assert g2() == (1.0, True)
    assert ev.root.status is True
    ev.tick(10.0)  # both silent past their staleness: unknown again
    assert g2() == (None, None)


def temporal_model(relax: str) -> GoalModel:
    return parse_goal_model(
        "anunnaki: goal-model/1\nname: temporal\nstaleness: 100\n"
        "agents:\n  - {id: A1, topics: [{topic: /a, attributes: [p, e]}]}\n"
        "goals:\n"
        "  - id: G1\n    utility: A1.p == true\n"
        f"    relax: {relax}\n    threshold: 0.5\n    agents: [A1]\n"
    )


def replay(
    relax: str, steps: list[tuple[float, bool, bool]], at: float
) -> tuple[float | None, bool | None]:
    ev = Evaluator(temporal_model(relax))
    for t, p, e in steps:
        ev.tick(t)
        ev.observe("/a", {"p": p, "e": e}, t)
    ev.tick(at)
    state = ev.state("G1")
    return state.utility, state.status


BEFORE = '{operator: before, event: "A1.e == true", tolerance: 2}'
UNTIL = '{operator: until, event: "A1.e == true", tolerance: 1}'
AFTER = '{operator: after, event: "A1.e == true", within: 0, tolerance: 2}'


def test_temporal_relax_compiles_its_event_expression() -> None:
    model = temporal_model(BEFORE)
    assert model.expressions[("G1", "event")].text == "A1.e == true"
    assert model.relax["G1"].kind == "temporal"
    with pytest.raises(ModelFileError, match=r"goals\[G1\]\.relax: unknown attribute 'A1.q'"):
        temporal_model(BEFORE.replace("A1.e", "A1.q"))


@pytest.mark.parametrize(
    ("relax", "first", "second", "expected"),
    [
        # BEFORE: P held before E -> 1; E first and P 2 s late (tolerance 2) -> 0
        (
            BEFORE,
            [(1.0, True, False), (3.0, True, True)],
            [(1.0, False, True), (3.0, True, True)],
            ((1.0, True), (0.0, False)),
        ),
        # UNTIL: P held until E, lapsed after -> 1; P lapsed 1 s before E (tolerance 1) -> 0
        (
            UNTIL,
            [(5.0, True, True), (6.0, False, True)],
            [(5.0, False, False), (6.0, False, True)],
            ((1.0, True), (0.0, False)),
        ),
        # AFTER: P already held when E came -> 1; P came 2 s after E (tolerance 2) -> 0
        (
            AFTER,
            [(1.0, True, False), (2.0, True, True)],
            [(1.0, False, True), (3.0, True, True)],
            ((1.0, True), (0.0, False)),
        ),
    ],
    ids=["before", "until", "after"],
)
def test_the_order_of_events_changes_a_temporal_verdict(
    relax: str,
    first: list[tuple[float, bool, bool]],
    second: list[tuple[float, bool, bool]],
    expected: tuple[tuple[float, bool], tuple[float, bool]],
) -> None:
    start = (0.0, relax == UNTIL, False)
    assert replay(relax, [start, *first], at=10.0) == expected[0]
    assert replay(relax, [start, *second], at=10.0) == expected[1]


def test_after_is_relaxed_between_deadline_and_tolerance() -> None:
    # E at 1, P at 2: one second late with within 0 and tolerance 2 -> 0.5, still satisfied
    utility, status = replay(
        AFTER, [(0.0, False, False), (1.0, False, True), (2.0, True, True)], 10.0
    )
    assert utility == pytest.approx(0.5)
    assert status is True
    # while P has not come, the lateness grows with time alone (tick)
    ev = Evaluator(temporal_model(AFTER))
    ev.observe("/a", {"p": False, "e": False}, 0.0)
    ev.observe("/a", {"p": False, "e": True}, 1.0)
    ev.tick(2.0)
    assert ev.state("G1").utility == pytest.approx(0.5)
    ev.tick(2.5)
    assert ev.state("G1").utility == pytest.approx(0.25)
    assert ev.state("G1").status is False
