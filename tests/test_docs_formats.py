"""docs/goal-models.md and docs/traces.md say what the code does.

Every fenced ``yaml`` block is valid YAML; every complete goal model or binding in them
(a block starting with ``anunnaki: goal-model/1`` or ``anunnaki: binding/1``) loads cleanly;
the table of expression values, the worked example's output, the check output and the trace
excerpts are what the code produces today. Every goal-model example in README.md and
docs/*.md, complete or a fragment, loads (see the rule at the end of the file).
"""

from __future__ import annotations

import io
import json
import re
import shutil
from pathlib import Path
from typing import Any

import pytest

from anunnaki._safeyaml import load_yaml
from anunnaki.cli.main import main
from anunnaki.goals import (
    ABSENT,
    Evaluator,
    compile_expression,
    load_binding,
    load_goal_model,
    parse_binding,
    parse_goal_model,
)
from anunnaki.trace import Phase, Record, read_trace

ROOT = Path(__file__).parents[1]
DOCS = ROOT / "docs"
ROVER = ROOT / "examples" / "rover"
GOAL_MODELS = (DOCS / "goal-models.md").read_text(encoding="utf-8")
TRACES = (DOCS / "traces.md").read_text(encoding="utf-8")
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.MULTILINE | re.DOTALL)


def blocks(text: str, lang: str) -> list[str]:
    return [body for tag, body in FENCE.findall(text) if tag == lang]


def tagged(text: str, tag: str) -> list[str]:
    return [
        b
        for b in blocks(text, "yaml")
        if next(line for line in b.splitlines() if line and not line.startswith("#"))
        == f"anunnaki: {tag}"
    ]


def section(text: str, heading: str) -> str:
    start = text.index(heading)
    end = text.find("\n## ", start + len(heading))
    return text[start : end if end >= 0 else len(text)]


def test_every_yaml_block_is_valid_yaml() -> None:
    found = blocks(GOAL_MODELS, "yaml")
    assert len(found) >= 6
    for i, body in enumerate(found):
        load_yaml(f"goal-models.md block {i}", text=body)


def test_complete_goal_models_load_cleanly_and_evaluate() -> None:
    models = tagged(GOAL_MODELS, "goal-model/1")
    assert models, "the page shows at least one complete goal model"
    for body in models:
        model = parse_goal_model(body, source="goal-models.md", strict=False)
        assert [f.render() for f in model.findings] == []
        Evaluator(model)


def test_the_first_model_behaves_as_described() -> None:
    ev = Evaluator(parse_goal_model(tagged(GOAL_MODELS, "goal-model/1")[0]))
    assert ev.model.root == "G3"
    for k in range(11):  # 5 Hz
        ev.observe("/rover/ultrasonic", {"range": 3.0}, k * 0.2)
    ev.observe("/rover/status", {"mode": "autonomous"}, 2.0)
    ev.observe("/utu/oracle/output", {"category": 0, "assessment": {"confidence": 0.9}}, 2.0)
    assert ev.root.status is True
    ev.observe("/utu/oracle/output", {"category": 1}, 2.1)
    assert ev.state("O1").status is True
    assert ev.state("G4").status is False
    assert ev.root.status is False
    ev.observe("/rover/status", {"mode": "manual"}, 2.2)
    assert ev.root.status is True


def test_bindings_load_with_the_rover_model_and_match_the_example_files() -> None:
    bindings = tagged(GOAL_MODELS, "binding/1")
    assert len(bindings) == 2
    for body in bindings:
        binding = parse_binding(body, source="goal-models.md")
        model = load_goal_model(ROVER / "goals.yaml", binding)
        assert model.findings == []
        example = {"rover-sim": "binding.yaml", "rover-ros1": "binding-ros.yaml"}[binding.platform]
        assert binding.spec == load_binding(ROVER / example).spec


# -- the table of expression values -------------------------------------------------------


def literal(text: str) -> Any:
    text = text.strip()
    if text == "?":
        return None
    if text == "absent":
        return ABSENT
    if text in ("true", "false"):
        return text == "true"
    if text.startswith("'"):
        return text[1:-1]
    return float(text) if "." in text else int(text)


def value_rows() -> list[tuple[str, str, str]]:
    part = section(GOAL_MODELS, "### Examples of values")
    rows = re.findall(r"^\| `([^`]+)` \| (?:`([^`]*)`)? *\| `([^`]+)` \|$", part, re.MULTILINE)
    assert len(rows) >= 25
    return rows


@pytest.mark.parametrize(("expression", "inputs", "expected"), value_rows())
def test_expression_values_table(expression: str, inputs: str, expected: str) -> None:
    attributes: dict[str, Any] = {}
    rates: dict[str, float] = {}
    for item in filter(None, inputs.split(", ")):
        name, _, value = item.partition(" = ")
        parsed = literal(value)
        if name.startswith("rate("):
            rates[name[5:-1]] = parsed
        elif parsed is not None:
            attributes[name] = parsed
    got = compile_expression(expression).evaluate(attributes, rates)
    want = literal(expected)
    if isinstance(want, bool) or want is None:
        assert got is want
    else:
        assert got == pytest.approx(want)


# -- the worked example -------------------------------------------------------------------


def text_blocks(text: str) -> list[str]:
    return blocks(text, "text")


def rover_at_25() -> Evaluator:
    ev = Evaluator(load_goal_model(ROVER / "goals.yaml", ROVER / "binding.yaml"))
    for item in read_trace(ROVER / "trace.jsonl").items:
        if item.t > 25.0:
            break
        ev.tick(item.t)
        if isinstance(item, Record):
            ev.observe(item.topic, item.msg, item.t)
    return ev


def test_the_worked_explanation_is_the_evaluators() -> None:
    worked = section(GOAL_MODELS, "## Worked example")
    explanation = next(b for b in text_blocks(worked) if b.startswith("G1 unsatisfied (utility"))
    assert rover_at_25().explain("G1").render() + "\n" == explanation


def test_the_worked_tree_and_the_trace_excerpts_are_the_commands_output(
    capsys: pytest.CaptureFixture[str],
) -> None:
    args = ["evaluate", str(ROVER / "goals.yaml"), "-b", str(ROVER / "binding.yaml")]
    assert main([*args, "-t", str(ROVER / "trace.jsonl"), "--explain", "G1"]) == 0
    out = capsys.readouterr().out.replace(str(ROVER / "trace.jsonl"), "examples/rover/trace.jsonl")
    worked = section(GOAL_MODELS, "## Worked example")
    excerpts = [b for b in text_blocks(worked) if b.startswith("t =")]
    excerpts += [b for b in text_blocks(TRACES) if b.startswith("─")]
    assert len(excerpts) == 3
    for excerpt in excerpts:
        assert excerpt in out


def test_the_json_excerpts_are_the_commands_output(capsys: pytest.CaptureFixture[str]) -> None:
    args = ["evaluate", str(ROVER / "goals.yaml"), "-b", str(ROVER / "binding.yaml")]
    assert main([*args, "-t", str(ROVER / "trace.jsonl"), "--json"]) == 0
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    shown = [json.loads(b) for b in blocks(TRACES, "json")]
    assert shown == [next(x for x in lines if x.get("t") == 25.0), lines[-1]]


def test_the_check_examples_are_the_commands_output(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    for name in ("goals.yaml", "binding.yaml", "tactics.yaml"):
        shutil.copy(ROVER / name, tmp_path / name)
    goals, tactics = tmp_path / "goals.yaml", tmp_path / "tactics.yaml"
    original_tactics = tactics.read_text()
    goals.write_text(goals.read_text().replace("A1.buzzer == true", "A1.buzer == true"))
    tactics.write_text(
        original_tactics.replace("'on': true", "'on': 'yes'").replace(
            "      - goal: G5\n        state: unsatisfied\n",
            "      - goal: G5\n        state: unknown\n"
            "      - expression: A1.bumper == true and A3.rang < 0.1\n",
        )
    )
    monkeypatch.chdir(tmp_path)
    shown = [b for b in text_blocks(section(GOAL_MODELS, "## Checks")) if b.startswith("$ ")]
    assert len(shown) == 2
    assert main(["check", "goals.yaml", "binding.yaml", "tactics.yaml"]) == 1
    assert "\n".join(shown[0].splitlines()[1:]) + "\n" == capsys.readouterr().out

    shutil.copy(ROVER / "goals.yaml", goals)
    start = original_tactics.index("  - name: collision-stop")
    end = original_tactics.index("  - name: warn-pedestrians")
    tactics.write_text(original_tactics[:start] + original_tactics[end:])
    assert main(["check", "goals.yaml", "binding.yaml", "tactics.yaml"]) == 1
    assert "\n".join(shown[1].splitlines()[1:]) + "\n" == capsys.readouterr().out


# -- traces.md ---------------------------------------------------------------------------------


def test_the_trace_example_is_the_start_of_the_rover_trace() -> None:
    (example,) = blocks(TRACES, "jsonl")
    trace = read_trace(io.StringIO(example))
    assert trace.header["anunnaki"] == "trace/1"
    assert isinstance(trace.items[0], Phase)
    rover = (ROVER / "trace.jsonl").read_text().splitlines()
    assert example.splitlines() == rover[: len(example.splitlines())]


def test_the_bad_trace_example_message(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.jsonl"
    bad.write_text(
        '{"anunnaki": "trace/1"}\n{"t": 0, "topic": "/rover/status", "msg": {}}\n'
        '{"t": 1, "topic": "/rover/status", "msg": {}, "extra": 1}\n'
    )
    args = ["evaluate", str(ROVER / "goals.yaml"), "-b", str(ROVER / "binding.yaml")]
    assert main([*args, "-t", str(bad)]) == 2
    err = capsys.readouterr().err.replace(str(bad), "bad.jsonl")
    shown = next(b for b in text_blocks(TRACES) if "bad.jsonl" in b)
    assert shown.splitlines()[1] == err.strip()


# -- every goal-model example in README.md and docs/*.md loads ----------------------------------
#
# A fenced ``yaml`` block is a goal-model example when it is
#   * a complete model: a mapping with ``anunnaki: goal-model/1``;
#   * a model fragment: a mapping without ``anunnaki`` whose keys are all goal-model keys and
#     include ``goals`` or ``obstacles``;
#   * a list of goals: a list of mappings, each with an ``id`` and a goal's ``utility``,
#     ``refinement`` or ``relax``;
#   * an agent's topics: a mapping whose only key is ``topics``.
# A complete model whose agents lack topics is loaded with the page's next
# ``anunnaki: binding/1`` block (the README and model-manager.md show the model, then the
# binding that gives its agents topics).
# A fragment is wrapped into the smallest model around it: an agent for every agent it names
# (one topic carrying every attribute it reads), a stub leaf for every goal it refers to but
# does not define, and a root AND over its top-level goals.

GOAL_MODEL_KEYS = {"name", "description", "root", "unknown_policy", "staleness", "agents"}
GOAL_MODEL_KEYS |= {"goals", "obstacles"}
GOAL_KEYS = {"utility", "refinement", "relax"}


def doc_pages() -> list[Path]:
    return [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]


def goal_model_examples() -> list[tuple[str, str, Any, str | None]]:
    """(``page:line``, kind, parsed data, binding text) of every goal-model example."""
    found: list[tuple[str, str, Any, str | None]] = []
    for page in doc_pages():
        text = page.read_text(encoding="utf-8")
        yaml_blocks = [
            m
            for m in re.finditer(r"^```(\w*)\n(.*?)^```", text, re.MULTILINE | re.DOTALL)
            if m.group(1) in ("yaml", "yml")
        ]
        for k, match in enumerate(yaml_blocks):
            where = f"{page.name}:{text.count(chr(10), 0, match.start()) + 1}"
            data, _ = load_yaml(where, text=match.group(2))
            if isinstance(data, dict) and data.get("anunnaki") == "goal-model/1":
                binding = next(
                    (
                        m.group(2)
                        for m in yaml_blocks[k + 1 :]
                        if m.group(2).startswith("anunnaki: binding/1")
                    ),
                    None,
                )
                unbound = any("topics" not in a for a in data.get("agents", []))
                found.append((where, "model", data, binding if unbound else None))
            elif (
                isinstance(data, dict)
                and "anunnaki" not in data
                and set(data) <= GOAL_MODEL_KEYS
                and {"goals", "obstacles"} & set(data)
            ):
                found.append((where, "fragment", data, None))
            elif (
                isinstance(data, list)
                and data
                and all(isinstance(g, dict) and "id" in g and GOAL_KEYS & set(g) for g in data)
            ):
                found.append((where, "fragment", {"goals": data}, None))
            elif isinstance(data, dict) and set(data) == {"topics"}:
                found.append((where, "agent", data, None))
    return found


def _expressions(item: dict[str, Any]) -> list[str]:
    texts = [item[k] for k in ("utility", "condition") if isinstance(item.get(k), str)]
    relax = item.get("relax")
    if isinstance(relax, dict):
        if isinstance(relax.get("event"), str):
            texts.append(relax["event"])
        texts += [a for a in relax.get("alternatives", []) if isinstance(a, str)]
    return texts


def wrap_fragment(data: dict[str, Any]) -> dict[str, Any]:
    """The smallest goal model around a fragment (see the rule above)."""
    goals: list[dict[str, Any]] = list(data.get("goals", []))
    obstacles: list[dict[str, Any]] = list(data.get("obstacles", []))
    attributes: dict[str, set[str]] = {}
    for item in goals + obstacles:
        for agent in item.get("agents", []):
            attributes.setdefault(agent, set())
        for text in _expressions(item):
            expr = compile_expression(text)
            for agent in expr.agents:
                attributes.setdefault(agent, set())
            for ref in expr.refs:
                attributes[ref.agent].add(ref.attribute)
    defined = {g["id"] for g in goals}
    children = {c for g in goals for c in g.get("children", [])}
    referred = children | {r for o in obstacles for r in o.get("obstructs", [])}
    referred |= {r for o in obstacles for r in o.get("resolutions", [])}
    stubs = sorted(referred - defined)
    attributes.setdefault("Z0", set()).update(f"stub_{s}" for s in stubs)
    goals += [{"id": s, "utility": f"Z0.stub_{s}"} for s in stubs]
    tops = [g["id"] for g in goals if g["id"] not in children]
    model = {
        "anunnaki": "goal-model/1",
        "name": "doc-fragment",
        "root": "ROOT",
        "agents": [
            {"id": agent, "topics": [{"topic": f"/doc/{agent}", "attributes": sorted(attrs)}]}
            for agent, attrs in sorted(attributes.items())
        ],
        "goals": [{"id": "ROOT", "refinement": "and", "children": tops}, *goals],
    }
    if obstacles:
        model["obstacles"] = obstacles
    return model


def as_model(kind: str, data: Any) -> dict[str, Any]:
    if kind == "model":
        return dict(data)
    if kind == "fragment":
        return wrap_fragment(data)
    attributes = data["topics"][0]["attributes"]
    first = next(iter(attributes))
    model = wrap_fragment({"goals": [{"id": "G1", "utility": f"A1 has {first}"}]})
    model["agents"] = [{"id": "A1", **data}]
    return model


def test_the_rule_finds_the_goal_model_examples() -> None:
    found = goal_model_examples()
    pages = {where.split(":")[0] for where, *_ in found}
    assert {"README.md", "goal-models.md", "relax.md", "model-manager.md"} <= pages
    assert sum(where.startswith("relax.md") for where, *_ in found) == 13  # G6, G2, G8–G18
    assert sum(kind == "model" for _, kind, *_ in found) >= 3


@pytest.mark.parametrize(
    ("where", "kind", "data", "binding"),
    [pytest.param(*example, id=example[0]) for example in goal_model_examples()],
)
def test_every_goal_model_example_in_the_docs_loads(
    where: str, kind: str, data: Any, binding: str | None
) -> None:
    text = json.dumps(as_model(kind, data))
    bound = parse_binding(binding, source=where) if binding is not None else None
    model = parse_goal_model(text, source=where, binding=bound, strict=True)
    assert [f.render() for f in model.findings if f.severity == "error"] == []
    Evaluator(model)
