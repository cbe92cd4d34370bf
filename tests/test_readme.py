"""The README's examples are real: its YAML and XML snippets load and check clean together."""

from __future__ import annotations

import re
from pathlib import Path

from anunnaki.check import check_tactics
from anunnaki.goals import Evaluator, parse_binding, parse_goal_model
from anunnaki.tactics import parse_tactics_xml, parse_tactics_yaml
from anunnaki.trace import read_trace

README = Path(__file__).parents[1] / "README.md"


def blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", README.read_text(encoding="utf-8"), re.S)


def by_tag(tag: str) -> str:
    found = [b for b in blocks("yaml") if b.startswith(f"anunnaki: {tag}")]
    assert len(found) == 1, tag
    return found[0]


def test_readme_snippets_load_and_fit_together(tmp_path: Path) -> None:
    binding = parse_binding(by_tag("binding/1"), source="README binding")
    model = parse_goal_model(by_tag("goal-model/1"), source="README model", binding=binding)
    xml_tactics = parse_tactics_xml(blocks("xml")[0], source="README tactics.xml")
    yaml_tactics = parse_tactics_yaml(by_tag("tactics/1"), source="README tactics.yaml")
    assert xml_tactics.tactic("fail-safe") == yaml_tactics.tactic("fail-safe")
    assert check_tactics(model, yaml_tactics, "README") == []
    trace = tmp_path / "t.jsonl"
    trace.write_text(blocks("json")[0])
    items = read_trace(trace)
    ev = Evaluator(model)
    for rec in items.records:
        ev.observe(rec.topic, rec.msg, rec.t)
    assert ev.state("O1").status is True  # the last record is the oracle's category 1
    assert ev.state("G4").status is False


def test_readme_commands_exist() -> None:
    from anunnaki.cli.main import build_parser

    text = README.read_text(encoding="utf-8")
    commands = set(re.findall(r"^anunnaki ([\w-]+)", text, re.M))
    sub = build_parser()._subparsers._group_actions[0].choices  # type: ignore[union-attr]
    assert commands <= set(sub), commands - set(sub)
