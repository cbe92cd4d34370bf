"""`anunnaki check` and :func:`check_files`: every finding names file, line and element."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from anunnaki.check import check_files
from anunnaki.cli.main import main

EXAMPLES = Path(__file__).parent.parent / "examples"

MODEL = """\
anunnaki: goal-model/1
name: checked
root: G1
agents:
  - id: A1
    description: controller
  - id: A4
    description: oracle
goals:
  - id: G1
    refinement: and
    children: [G2, G3]
  - id: G2
    refinement: or
    children: [G4, G5]
  - id: G3
    utility: A1.buzzer == true
    agents: [A1]
  - id: G4
    utility: A1.mode == 'auto'
    agents: [A1]
  - id: G5
    utility: A1.mode == 'manual'
    agents: [A1]
  - id: G9
    description: a robust model is active (resolution only)
    utility: A4.category <= 1
    agents: [A4]
obstacles:
  - id: O1
    obstructs: [G4]
    condition: A4.category >= 1
    resolutions: [G9]
"""

BINDING = """\
anunnaki: binding/1
platform: test
agents:
  A1:
    topics: [{topic: /r/status, attributes: [mode, buzzer]}]
  A4:
    topics: [{topic: /utu/oracle/output, attributes: [category]}]
endpoints:
  - name: /r/set_mode
    kind: service
    payload:
      mode: {type: string, enum: [auto, manual]}
  - name: /r/stop
    kind: service
    payload:
      reason: {type: string, required: false}
  - name: /r/buzzer
    kind: topic
    payload: {on: boolean}
  - name: /r/teleop
    kind: topic
    payload: {linear: number, steps: integer, label: {type: any, required: false}}
"""


def tactic(name: str, precondition: str, action: str, *, extra: str = "") -> str:
    """One YAML tactic; ``precondition`` and ``action`` are flow mappings."""
    return (
        f"  - name: {name}\n"
        f"    preconditions:\n      - {precondition}\n"
        f"    actions:\n      - {action}\n" + extra
    )


COVERING = tactic(
    "cover-all", "{goal: G1, state: unsatisfied}", "{type: request, service: /r/stop}"
)


def tactics_file(*tactics: str) -> str:
    return "anunnaki: tactics/1\ntactics:\n" + "".join(tactics)


@pytest.fixture
def files(tmp_path: Path) -> dict[str, Path]:
    (tmp_path / "goals.yaml").write_text(MODEL)
    (tmp_path / "binding.yaml").write_text(BINDING)
    return {"model": tmp_path / "goals.yaml", "binding": tmp_path / "binding.yaml"}


def write_tactics(tmp_path: Path, *tactics: str) -> Path:
    path = tmp_path / "tactics.yaml"
    path.write_text(tactics_file(*tactics))
    return path


def line_of(path: Path, marker: str) -> int:
    """1-based line of the first line of ``path`` that contains ``marker``."""
    for i, line in enumerate(path.read_text().splitlines(), start=1):
        if marker in line:
            return i
    raise AssertionError(f"{marker!r} not in {path}")


def rendered(result_findings: list[object]) -> list[str]:
    return [f.render() for f in result_findings]  # type: ignore[attr-defined]


# -- clean models and exit codes ----------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "tactics"),
    [("rover", "tactics.xml"), ("rover", "tactics.yaml"), ("uav", "tactics.yaml")],
)
def test_the_examples_are_clean(
    name: str, tactics: str, capsys: pytest.CaptureFixture[str]
) -> None:
    d = EXAMPLES / name
    code = main(["check", str(d / "goals.yaml"), str(d / "binding.yaml"), str(d / tactics)])
    out = capsys.readouterr().out
    assert code == 0
    assert out.startswith("ok: ")
    assert "tactics" in out


def test_a_clean_model_with_binding_and_covering_tactics(
    files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    tactics = write_tactics(tmp_path, COVERING)
    result = check_files(files["model"], files["binding"], tactics)
    assert rendered(result.findings) == []
    assert (result.exit_code, result.errors, result.warnings) == (0, [], [])
    assert result.model is not None
    assert result.tactics is not None
    assert main(["check", str(files["model"]), str(files["binding"]), str(tactics)]) == 0
    assert capsys.readouterr().out == "ok: 6 goals, 1 obstacles, 2 agents; 1 tactics\n"


def test_errors_exit_1_with_a_count(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    files["model"].write_text(MODEL.replace("children: [G2, G3]", "children: [G2, G3, G7]"))
    result = check_files(files["model"], files["binding"])
    assert result.exit_code == 1
    assert main(["check", str(files["model"]), str(files["binding"])]) == 1
    out = capsys.readouterr().out
    assert out.startswith(
        f"{files['model']}:12: error: goals[G1].children: unknown child goal 'G7'"
    )
    assert out.endswith("1 error(s), 0 warning(s)\n")


def test_warnings_alone_exit_1(files: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    files["model"].write_text(
        MODEL.replace("    agents: [A1]\n  - id: G4", "  - id: G4").replace(
            "utility: A1.buzzer == true", "utility: 0.5 + 0.5"
        )
    )
    result = check_files(files["model"], files["binding"])
    assert result.errors == []
    assert [f.message for f in result.warnings] == ["leaf goal without a responsible agent"]
    assert result.exit_code == 1
    assert main(["check", str(files["model"]), str(files["binding"])]) == 1
    assert capsys.readouterr().out.endswith("0 error(s), 1 warning(s)\n")


@pytest.mark.parametrize(
    ("setup", "message"),
    [
        ("missing-model", "cannot read file"),
        ("folder-model", "not a regular file"),
        ("missing-extra", "cannot read file"),
        ("unrecognised-extra", "cannot tell whether this is a binding or a tactics file"),
        ("two-bindings", "a second binding file"),
    ],
)
def test_a_file_named_that_cannot_be_read_exits_2(
    setup: str,
    message: str,
    files: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    model, args = files["model"], [str(files["binding"])]
    if setup == "missing-model":
        model = tmp_path / "nope.yaml"
    elif setup == "folder-model":
        model = tmp_path
    elif setup == "missing-extra":
        args = [str(tmp_path / "missing.yaml")]
    elif setup == "unrecognised-extra":
        (tmp_path / "notes.yaml").write_text("hello: world\n")
        args = [str(tmp_path / "notes.yaml")]
    elif setup == "two-bindings":
        args.append(str(files["binding"]))
    result = check_files(model, *args)
    assert result.exit_code == 2
    assert result.unreadable
    assert any(message in f.message for f in result.findings), rendered(result.findings)
    assert main(["check", str(model), *args]) == 2
    captured = capsys.readouterr()
    assert "nothing checked: a file could not be read" in captured.out
    assert "Traceback" not in captured.out + captured.err


@pytest.mark.parametrize(
    ("setup", "message"),
    [
        ("bad-yaml-model", "invalid YAML"),
        ("bad-binding", "unknown field 'bogus'"),
        ("bad-tactics", "missing field 'preconditions'"),
    ],
)
def test_a_file_read_but_invalid_is_a_finding_exit_1(
    setup: str,
    message: str,
    files: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    # exit 2 says "nothing could be checked"; a file that is read but does not fit its
    # format is what check is for: a finding, located, exit 1 (docs/goal-models.md#checks)
    model, args = files["model"], [str(files["binding"])]
    if setup == "bad-yaml-model":
        model.write_text("anunnaki: goal-model/1\ngoals: [\n")
    elif setup == "bad-binding":
        files["binding"].write_text(BINDING + "bogus: 1\n")
    elif setup == "bad-tactics":
        (tmp_path / "t.yaml").write_text("anunnaki: tactics/1\ntactics: [{name: x}]\n")
        args.append(str(tmp_path / "t.yaml"))
    result = check_files(model, *args)
    assert (result.exit_code, result.unreadable) == (1, False)
    assert any(message in f.message for f in result.errors), rendered(result.findings)
    assert main(["check", str(model), *args]) == 1
    captured = capsys.readouterr()
    assert "1 error(s), 0 warning(s)" in captured.out
    assert "could not be read" not in captured.out
    assert "Traceback" not in captured.out + captured.err


def test_an_invalid_binding_does_not_bury_its_error_under_consequences(
    files: dict[str, Path],
) -> None:
    files["binding"].write_text(BINDING.replace("platform: test\n", ""))
    result = check_files(files["model"], files["binding"])
    # without the binding every agent would look unobserved; only the real problem is shown
    assert rendered(result.findings) == [
        f"{files['binding']}:1: error: platform: missing required field 'platform'"
    ]
    assert result.exit_code == 1


def test_more_than_two_positional_files_is_a_usage_error(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    b = str(files["binding"])
    assert main(["check", str(files["model"]), b, b, b]) == 2
    assert "at most a binding and a tactics file" in capsys.readouterr().err


# -- positional files are recognised --------------------------------------------------------


def test_positional_files_are_recognised_by_tag_in_any_order(
    files: dict[str, Path], tmp_path: Path
) -> None:
    tactics = write_tactics(tmp_path, COVERING)
    for extra in ([files["binding"], tactics], [tactics, files["binding"]]):
        result = check_files(files["model"], *extra)
        assert result.exit_code == 0, rendered(result.findings)
        assert result.tactics is not None
        assert result.model is not None
        assert result.model.binding is not None
    # a quoted tag and a comment above it are fine; the name of the file does not matter
    odd = tmp_path / "platform.txt"
    odd.write_text("# the lab rover\nanunnaki: 'binding/1'\n" + BINDING.split("\n", 1)[1])
    assert check_files(files["model"], odd).exit_code == 0


def test_xml_tactics_are_recognised_by_extension(files: dict[str, Path], tmp_path: Path) -> None:
    xml = tmp_path / "tactics.xml"
    xml.write_text(
        '<tactics name="t">\n'
        '  <tactic name="stop">\n'
        '    <preconditions><goal id="G1" state="unsatisfied"/></preconditions>\n'
        '    <actions><request service="/r/stop"/></actions>\n'
        "  </tactic>\n"
        "</tactics>\n"
    )
    result = check_files(files["model"], xml, files["binding"])
    assert result.exit_code == 0, rendered(result.findings)
    assert result.tactics is not None
    assert result.tactics.tactics[0].name == "stop"


def test_binding_and_tactics_options(
    files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    tactics = write_tactics(tmp_path, COVERING)
    code = main(
        [
            "check",
            str(files["model"]),
            "--binding",
            str(files["binding"]),
            "--tactics",
            str(tactics),
        ]
    )
    assert code == 0
    assert capsys.readouterr().out.startswith("ok: ")
    assert check_files(files["model"], binding=files["binding"], tactics=tactics).exit_code == 0


# -- tactics against the model and binding ------------------------------------------------


@pytest.mark.parametrize(
    ("precondition", "action", "marker", "element", "message"),
    [
        (
            "{goal: G33, state: unsatisfied}",
            "{type: request, service: /r/stop}",
            "goal: G33",
            "preconditions[0]",
            "unknown goal 'G33' (hint: did you mean 'G3'?)",
        ),
        (
            "{goal: G1, state: unsatisfied}",
            "{type: request, service: /r/halt}",
            "/r/halt",
            "actions[0]",
            "unknown service /r/halt (hint: the binding's services: /r/set_mode, /r/stop)",
        ),
        (
            "{goal: G1, state: unsatisfied}",
            "{type: publish, topic: /r/horn, payload: {}}",
            "/r/horn",
            "actions[0]",
            "unknown topic /r/horn (hint: the binding's topics: /r/buzzer, /r/teleop)",
        ),
        (
            "{goal: G1, state: unsatisfied}",
            "{type: request, service: /r/buzzer, payload: {on: true}}",
            "service: /r/buzzer",
            "actions[0]",
            "/r/buzzer is a topic, not a service (hint: publish to topics, request services)",
        ),
        (
            "{goal: G1, state: unsatisfied}",
            "{type: publish, topic: /r/stop, payload: {}}",
            "topic: /r/stop",
            "actions[0]",
            "/r/stop is a service, not a topic (hint: publish to topics, request services)",
        ),
        (
            "{goal: G1, state: unsatisfied}",
            "{type: publish, topic: /r/buzzer, payload: {on: true, volume: 3}}",
            "volume: 3",
            "actions[0]",
            "/r/buzzer takes no field 'volume' (fields: on)",
        ),
        (
            "{goal: G1, state: unsatisfied}",
            "{type: publish, topic: /r/buzzer, payload: {on: 'yes'}}",
            "on: 'yes'",
            "actions[0]",
            "field 'on' of /r/buzzer must be a boolean, got 'yes'",
        ),
        (
            "{goal: G1, state: unsatisfied}",
            "{type: publish, topic: /r/buzzer, payload: {on: 1}}",
            "on: 1",
            "actions[0]",
            "field 'on' of /r/buzzer must be a boolean, got 1",
        ),
        (
            "{goal: G1, state: unsatisfied}",
            "{type: publish, topic: /r/teleop, payload: {linear: true, steps: 2}}",
            "linear: true",
            "actions[0]",
            "field 'linear' of /r/teleop must be a number, got True",
        ),
        (
            "{goal: G1, state: unsatisfied}",
            "{type: publish, topic: /r/teleop, payload: {linear: 0.5, steps: 2.5}}",
            "steps: 2.5",
            "actions[0]",
            "field 'steps' of /r/teleop must be an integer, got 2.5",
        ),
        (
            "{goal: G1, state: unsatisfied}",
            "{type: change_mode, service: /r/set_mode, mode: hover}",
            "mode: hover",
            "actions[0]",
            "field 'mode' of /r/set_mode must be one of auto, manual; got 'hover'",
        ),
        (
            "{goal: G1, state: unsatisfied}",
            "{type: publish, topic: /r/teleop, payload: {linear: 0.5}}",
            "linear: 0.5",
            "actions[0]",
            "/r/teleop needs field 'steps'",
        ),
        (
            "{expression: 'A4.category >= '}",
            "{type: request, service: /r/stop}",
            "expression:",
            "preconditions[0]",
            "syntax error at column 15: unexpected end of expression",  # just past the end
        ),
        (
            "{expression: 'A4.categroy >= 1'}",
            "{type: request, service: /r/stop}",
            "expression:",
            "preconditions[0]",
            "unknown attribute 'A4.categroy' in 'A4.categroy >= 1' (hint: A4 publishes: category)",
        ),
        (
            "{expression: 'A7.category >= 1'}",
            "{type: request, service: /r/stop}",
            "expression:",
            "preconditions[0]",
            "unknown agent 'A7' in 'A7.category >= 1'",
        ),
        (
            "{expression: \"A1.mode < 'x' + 1\"}",
            "{type: request, service: /r/stop}",
            "expression:",
            "preconditions[0]",
            "arithmetic on a string or boolean",
        ),
    ],
    ids=[
        "unknown-goal",
        "unknown-service",
        "unknown-topic",
        "topic-as-service",
        "service-as-topic",
        "unknown-field",
        "wrong-type",
        "int-for-boolean",
        "bool-for-number",
        "float-for-integer",
        "outside-enum",
        "missing-required",
        "bad-expression",
        "unknown-attribute",
        "unknown-agent",
        "type-clash",
    ],
)
def test_tactic_findings_name_file_line_and_element(
    precondition: str,
    action: str,
    marker: str,
    element: str,
    message: str,
    files: dict[str, Path],
    tmp_path: Path,
) -> None:
    tactics = write_tactics(tmp_path, COVERING, tactic("t", precondition, action))
    result = check_files(files["model"], files["binding"], tactics)
    line = line_of(tactics, marker)
    assert line > 8  # in the second tactic, not the first
    expected_prefix = f"{tactics}:{line}: error: tactics[t].{element}: "
    errors = rendered(result.errors)
    assert len(errors) == 1, errors
    assert errors[0].startswith(expected_prefix), errors[0]
    assert message in errors[0]
    assert result.exit_code == 1


def test_several_payload_problems_are_each_reported(files: dict[str, Path], tmp_path: Path) -> None:
    action = "{type: publish, topic: /r/teleop, payload: {linear: x, bogus: 1}}"
    tactics = write_tactics(tmp_path, COVERING, tactic("t", "{goal: G1, state: unknown}", action))
    messages = [f.message for f in check_files(files["model"], files["binding"], tactics).errors]
    assert messages == [
        "field 'linear' of /r/teleop must be a number, got 'x'",
        "/r/teleop takes no field 'bogus' (fields: linear, steps, label)",
        "/r/teleop needs field 'steps'",
    ]


def test_optional_and_any_fields_and_schemaless_endpoints_pass(
    files: dict[str, Path], tmp_path: Path
) -> None:
    binding = BINDING + "  - name: /r/raw\n    kind: topic\n"
    files["binding"].write_text(binding)
    tactics = write_tactics(
        tmp_path,
        COVERING,
        tactic(
            "ok",
            "{goal: G1, state: unknown}",
            "{type: publish, topic: /r/teleop, payload: {linear: 1, steps: 3, label: [1, x]}}",
            extra="      - {type: request, service: /r/stop, payload: {reason: because}}\n"
            "      - {type: publish, topic: /r/raw, payload: {anything: {goes: here}}}\n"
            "      - {type: change_mode, service: /r/set_mode, mode: manual}\n",
        ),
    )
    result = check_files(files["model"], files["binding"], tactics)
    assert rendered(result.findings) == []


def test_a_swap_model_action_is_checked_against_the_manager_service(
    files: dict[str, Path], tmp_path: Path
) -> None:
    action = "{type: swap_model, domain: fog}"
    tactics = write_tactics(
        tmp_path, COVERING, tactic("swap", "{goal: G4, state: unsatisfied}", action)
    )
    result = check_files(files["model"], files["binding"], tactics)
    line = line_of(tactics, "swap_model")
    assert rendered(result.errors) == [
        f"{tactics}:{line}: error: tactics[swap].actions[0]: unknown service /lm_manager/swap "
        "(hint: the binding's services: /r/set_mode, /r/stop)"
    ]


# -- goals no tactic addresses --------------------------------------------------------------


def unaddressed(files: dict[str, Path], tmp_path: Path, *tactics: str) -> list[str]:
    path = write_tactics(tmp_path, *tactics)
    result = check_files(files["model"], files["binding"], path)
    assert result.errors == [], rendered(result.errors)
    return [f.element or "" for f in result.warnings]


def stop_when(goal: str, state: str = "unsatisfied") -> str:
    return tactic(
        f"on-{goal}-{state}",
        f"{{goal: {goal}, state: {state}}}",
        "{type: request, service: /r/stop}",
    )


def test_a_tactic_on_an_ancestor_covers_every_descendant(
    files: dict[str, Path], tmp_path: Path
) -> None:
    assert unaddressed(files, tmp_path, stop_when("G1")) == []
    assert unaddressed(files, tmp_path, stop_when("G1", "unknown")) == []


def test_an_and_goal_is_covered_when_all_its_children_are(
    files: dict[str, Path], tmp_path: Path
) -> None:
    # G1 = AND(G2, G3): covering G2 alone leaves G1 and G3 unaddressed
    assert unaddressed(files, tmp_path, stop_when("G2")) == ["goals[G1]", "goals[G3]"]
    assert unaddressed(files, tmp_path, stop_when("G2"), stop_when("G3")) == []


def test_an_or_goal_is_covered_when_one_child_is(files: dict[str, Path], tmp_path: Path) -> None:
    # G2 = OR(G4, G5): a violated OR means every child is violated, so one tactic suffices
    assert unaddressed(files, tmp_path, stop_when("G5"), stop_when("G3")) == ["goals[G4]"]
    # G4 itself is not covered by its sibling; but naming it covers the OR parent too
    assert unaddressed(files, tmp_path, stop_when("G4"), stop_when("G3")) == ["goals[G5]"]


def test_a_tactic_for_the_satisfied_state_addresses_nothing(
    files: dict[str, Path], tmp_path: Path
) -> None:
    warned = unaddressed(files, tmp_path, stop_when("G1", "satisfied"))
    assert warned == [f"goals[G{i}]" for i in (1, 2, 3, 4, 5)]


def test_resolution_only_goals_are_exempt_and_the_warning_is_located(
    files: dict[str, Path], tmp_path: Path
) -> None:
    path = write_tactics(tmp_path, stop_when("G2"))
    result = check_files(files["model"], files["binding"], path)
    assert "goals[G9]" not in [f.element for f in result.warnings]  # G9 only resolves O1
    g3 = next(f for f in result.warnings if f.element == "goals[G3]")
    assert g3.render() == (
        f"{files['model']}:16: warning: goals[G3]: no tactic addresses a violation of this goal "
        "(hint: add a tactic with precondition 'goal: G3, state: unsatisfied' (or on an ancestor))"
    )


def test_no_tactics_file_means_no_coverage_warnings(files: dict[str, Path]) -> None:
    assert check_files(files["model"], files["binding"]).exit_code == 0


# -- model-level checks through check ------------------------------------------------------


def test_a_dependency_cycle_through_a_resolution_goal_is_reported(files: dict[str, Path]) -> None:
    files["model"].write_text(MODEL.replace("resolutions: [G9]", "resolutions: [G1]"))
    result = check_files(files["model"], files["binding"])
    assert [f.message for f in result.errors] == [
        "the goal model's dependencies form a cycle through G1, G2, G4"
    ]
    assert result.exit_code == 1


def test_without_a_binding_unobserved_agents_are_errors(files: dict[str, Path]) -> None:
    result = check_files(files["model"])
    assert [f.element for f in result.errors] == ["agents[A1]", "agents[A4]"]
    assert result.errors[0].line == 5


# -- JSON output ------------------------------------------------------------------------------


def test_json_output(
    files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    tactics = write_tactics(
        tmp_path,
        tactic("t", "{goal: G99, state: unsatisfied}", "{type: request, service: /r/stop}"),
    )
    code = main(["check", str(files["model"]), str(files["binding"]), str(tactics), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == out["exit_code"] == 1
    first = out["findings"][0]
    assert first == {
        "severity": "error",
        "message": "unknown goal 'G99'",
        "path": str(tactics),
        "line": line_of(tactics, "G99"),
        "element": "tactics[t].preconditions[0]",
        "hint": "did you mean 'G9'?",
    }
    assert {f["severity"] for f in out["findings"][1:]} == {"warning"}
    assert (
        main(
            [
                "check",
                str(EXAMPLES / "uav" / "goals.yaml"),
                str(EXAMPLES / "uav" / "binding.yaml"),
                "--json",
            ]
        )
        == 0
    )
    assert json.loads(capsys.readouterr().out) == {"exit_code": 0, "findings": []}


def test_json_output_of_an_unreadable_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["check", str(tmp_path / "none.yaml"), "--json"]) == 2
    out = json.loads(capsys.readouterr().out)
    assert out["exit_code"] == 2
    assert out["findings"][0]["message"] == "cannot read file: No such file or directory"


# -- logical endpoints ------------------------------------------------------------------------

LOGICAL = BINDING.replace(
    "  - name: /r/set_mode\n", "  - name: /r/set_mode\n    logical: set_mode\n"
)


def test_a_logical_endpoint_is_checked_against_the_one_the_binding_maps(
    files: dict[str, Path], tmp_path: Path
) -> None:
    files["binding"].write_text(LOGICAL)
    good = tactic(
        "mode",
        "{goal: G4, state: unsatisfied}",
        "{type: change_mode, service: set_mode, mode: manual}",
    )
    bad = tactic(
        "bad",
        "{goal: G5, state: unsatisfied}",
        "{type: change_mode, service: set_mode, mode: sleep}",
    )
    horn = tactic(
        "horn", "{goal: G3, state: unsatisfied}", "{type: publish, topic: horn, payload: {}}"
    )
    tactics = write_tactics(tmp_path, COVERING, good, bad, horn)
    result = check_files(files["model"], files["binding"], tactics)
    assert rendered(result.errors) == [
        f"{tactics}:{line_of(tactics, 'sleep')}: error: tactics[bad].actions[0]: field 'mode' "
        "of /r/set_mode must be one of auto, manual; got 'sleep'",
        f"{tactics}:{line_of(tactics, 'horn, payload')}: error: tactics[horn].actions[0]: "
        "unknown topic horn (hint: the binding maps no logical topic 'horn'; its logical "
        "topics: none (add 'logical: horn' to the binding's topic that does this))",
    ]


def test_a_direct_name_with_a_logical_name_warns_and_another_platform_says_how_to_migrate(
    files: dict[str, Path], tmp_path: Path
) -> None:
    files["binding"].write_text(LOGICAL)
    direct = tactic(
        "mode",
        "{goal: G4, state: unsatisfied}",
        "{type: change_mode, service: /r/set_mode, mode: manual}",
    )
    tactics = write_tactics(tmp_path, COVERING, direct)
    result = check_files(files["model"], files["binding"], tactics)
    line = line_of(tactics, "/r/set_mode")
    assert result.errors == []  # it still runs on this binding: a warning, not an error
    assert (
        f"{tactics}:{line}: warning: tactics[mode].actions[0]: /r/set_mode is named "
        "directly; its logical name is 'set_mode'" in rendered(result.warnings)[0]
    )
    # another platform puts set_mode elsewhere: the direct name is unknown there
    files["binding"].write_text(LOGICAL.replace("/r/set_mode", "/other/mode"))
    result = check_files(files["model"], files["binding"], tactics)
    assert rendered(result.errors) == [
        f"{tactics}:{line}: error: tactics[mode].actions[0]: unknown service /r/set_mode "
        "(hint: the binding's services: /other/mode, /r/stop; to migrate, name a logical "
        "endpoint (set_mode) in the tactic, which every binding maps to its own name)"
    ]


def test_the_rover_check_with_the_ros_binding_passes_from_the_command_line(
    capsys: pytest.CaptureFixture[str],
) -> None:
    rover = EXAMPLES / "rover"
    args = ["check", str(rover / "goals.yaml"), str(rover / "binding-ros.yaml")]
    assert main([*args, str(rover / "tactics.xml")]) == 0
    assert "unknown service" not in capsys.readouterr().out


# -- platform modes (issue #24: every mode a tactic requests exists on the platform) ----------


def _uav_files(tmp_path: Path, tactics_text: str | None = None) -> Path:
    """A copy of examples/uav (tactics replaced by *tactics_text* if given)."""
    import shutil

    uav = tmp_path / "uav"
    shutil.copytree(EXAMPLES / "uav", uav)
    shutil.copytree(EXAMPLES / "models", tmp_path / "models")
    if tactics_text is not None:
        (uav / "tactics.yaml").write_text(tactics_text)
    return uav


LOITER = (
    (EXAMPLES / "uav" / "tactics.yaml")
    .read_text()
    .replace(
        "        mode: hover\n      - type: notify\n        channel: log",
        "        mode: loiter\n      - type: notify\n        channel: log",
    )
)


def test_the_uav_tactics_request_only_the_simulated_uavs_modes() -> None:
    from anunnaki.check import PlatformModes
    from anunnaki.sim import PLATFORM_MODES, UavSim

    assert PLATFORM_MODES["uav"] == UavSim.modes == ("auto", "hover", "return_home", "land")
    d = EXAMPLES / "uav"
    result = check_files(
        d / "goals.yaml",
        d / "binding.yaml",
        d / "tactics.yaml",
        modes=PlatformModes("uav", PLATFORM_MODES["uav"]),
    )
    assert result.findings == []


def test_an_undeclared_mode_is_an_error_with_file_line_element_and_fix(tmp_path: Path) -> None:
    from anunnaki.check import PlatformModes

    assert (EXAMPLES / "uav" / "tactics.yaml").read_text() != LOITER
    uav = _uav_files(tmp_path, LOITER)
    modes = PlatformModes("uav", ("auto", "hover", "return_home", "land"), "UavSim.modes")
    result = check_files(
        uav / "goals.yaml", uav / "binding.yaml", uav / "tactics.yaml", modes=modes
    )
    assert result.exit_code == 1
    # the binding's payload schema (enum) says so too; the platform's modes say it for sure
    (finding,) = [f for f in result.findings if "platform" in f.message]
    assert finding.severity == "error"
    assert finding.message == (
        "tactic 'hold-route' requests mode 'loiter', which the uav platform does not declare"
    )
    assert finding.path == str(uav / "tactics.yaml")
    # the line where the action starts ('- type: change_mode', two lines above its mode)
    assert finding.line == line_of(uav / "tactics.yaml", "mode: loiter") - 2
    assert finding.element == "tactics[hold-route].actions[0].mode"
    assert finding.hint == (
        "the uav platform's modes (UavSim.modes): auto, hover, return_home, land; "
        "request one of them, or declare the mode on the platform"
    )
    # a binding without a schema for the mode says nothing; the platform's modes still do
    binding = uav / "binding.yaml"
    binding.write_text(
        binding.read_text().replace(
            "mode: {type: string, enum: [auto, hover, return_home, land]}", "mode: string"
        )
    )
    files = (uav / "goals.yaml", binding, uav / "tactics.yaml")
    assert check_files(*files).findings == []
    assert [f.message for f in check_files(*files, modes=modes).findings] == [finding.message]


def test_check_a_launch_file_takes_the_modes_of_its_simulated_platform(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["check", str(EXAMPLES / "uav" / "sim.yaml")]) == 0
    assert "ok: 14 goals, 2 obstacles, 7 agents" in capsys.readouterr().out
    assert main(["check", str(EXAMPLES / "rover" / "sim.yaml")]) == 0
    capsys.readouterr()
    uav = _uav_files(tmp_path, LOITER)
    # the binding's enum and the platform's modes both say it: findings, as for the files
    assert main(["check", str(uav / "sim.yaml")]) == 1
    out = capsys.readouterr().out
    assert "field 'mode' of /uav/set_mode must be one of" in out
    assert "requests mode 'loiter', which the uav platform does not declare" in out
    files = [str(uav / name) for name in ("goals.yaml", "binding.yaml", "tactics.yaml")]
    assert main(["check", *files, "--platform", "uav"]) == 1
    assert capsys.readouterr().out == out
    binding = uav / "binding.yaml"  # a binding that does not say which modes there are
    binding.write_text(
        binding.read_text().replace(
            "mode: {type: string, enum: [auto, hover, return_home, land]}", "mode: string"
        )
    )
    assert main(["check", str(uav / "sim.yaml")]) == 1
    out = capsys.readouterr().out
    line = line_of(uav / "tactics.yaml", "mode: loiter") - 2
    assert f"{uav / 'tactics.yaml'}:{line}: error: tactics[hold-route].actions[0].mode" in out
    assert "anunnaki.sim.UavSim.modes" in out and "1 error(s)" in out


def test_check_platform_option_and_a_launchs_declared_modes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    d = EXAMPLES / "uav"
    files = [str(d / "goals.yaml"), str(d / "binding.yaml"), str(d / "tactics.yaml")]
    assert main(["check", *files, "--platform", "uav"]) == 0
    capsys.readouterr()
    assert main(["check", *files, "--platform", "rover", "--json"]) == 1
    found = json.loads(capsys.readouterr().out)["findings"]
    assert found
    assert all(f["message"].endswith("the rover platform does not declare") for f in found)
    assert {f["element"].split(".")[0] for f in found} >= {"tactics[return-home]"}
    # a scripted system declares its modes in the launch file (managed.scripted.modes)
    launch = tmp_path / "scripted.yaml"
    launch.write_text(
        "anunnaki: launch/1\nname: t\n"
        f"utu: {{goal_model: {d / 'goals.yaml'}, binding: {d / 'binding.yaml'}, "
        f"tactics: {d / 'tactics.yaml'}}}\n"
        f"managed:\n  scripted: {{trace: {d / 'trace.jsonl'}, prefix: /uav, "
        "modes: [auto, hover, land]}\n"
    )
    assert main(["check", str(launch)]) == 1
    out = capsys.readouterr().out
    assert "requests mode 'return_home', which the scripted platform does not declare" in out
    assert f"{launch}: managed.scripted.modes" in out


# -- model swaps and the fail-safe (what a launch file's check adds) ------------------------
SWAPS = """\
anunnaki: tactics/1
tactics:
  - name: to-fog
    preconditions: [{goal: G4, state: unsatisfied}]
    actions:
      - {type: swap_model, domain: fog}
      - {type: swap_model, model: rover-fog-v9}
      - {type: swap_model, lec: camera2, domain: fog}
      - {type: swap_model, domain: dusk}
      - {type: swap_model, domain: dusk, service: /other/swap}
"""


def test_swaps_the_model_manager_would_refuse_are_warnings(tmp_path: Path) -> None:
    from anunnaki.check import ModelCatalogue, check_failsafe, check_swaps
    from anunnaki.goals import load_binding, load_goal_model
    from anunnaki.tactics import load_tactics

    (tmp_path / "t.yaml").write_text(SWAPS)
    rover = EXAMPLES / "rover"
    model = load_goal_model(rover / "goals-lm.yaml", load_binding(rover / "binding-lm.yaml"))
    ts = load_tactics(tmp_path / "t.yaml")
    models = ModelCatalogue(
        "detector", ("rover-default", "rover-fog"), ("default", "fog"), "r.yaml"
    )
    found = check_swaps(model, ts, "t.yaml", models)
    assert {f.severity for f in found} == {"warning"}
    assert [(f.element, f.message.split(":")[0]) for f in found] == [
        (
            "tactics[to-fog].actions[1].model",
            "tactic 'to-fog' swaps to model 'rover-fog-v9', which the model registry does not have",
        ),
        (
            "tactics[to-fog].actions[2].lec",
            "tactic 'to-fog' swaps a model of lec 'camera2', but the model manager serves lec "
            "'detector'",
        ),
        (
            "tactics[to-fog].actions[3].domain",
            "tactic 'to-fog' swaps to domain 'dusk', for which the model registry has no model",
        ),
    ]  # the swap sent to another service is another manager's business
    assert found[2].hint == (
        "the registry's domains (r.yaml): default, fog; name one of them, or add a model "
        "for the domain to the registry"
    )
    assert check_failsafe(ts, "t.yaml", "to-fog") == []
    (missing,) = check_failsafe(ts, "t.yaml", "fail-safe")
    assert (missing.severity, missing.element, missing.hint) == (
        "error",
        "failsafe",
        "name one of the tactics (to-fog)",
    )


def test_check_help_says_what_each_exit_code_means(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as done:
        main(["check", "--help"])
    assert done.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "Exit codes: 0 nothing found; 1 findings (errors or warnings)" in text
    assert "2 nothing could be checked: a usage error, or a file named on the command line" in text
    assert "everything 'anunnaki run' would load" in text
