"""The README's examples are real.

Its YAML and XML snippets load and check clean together; each "Bring your own" snippet runs
in a fresh interpreter and prints what the README says; the paper is cited as published.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

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


def bring_your_own() -> str:
    text = README.read_text(encoding="utf-8")
    start = text.index("\n## Bring your own\n")
    return text[start : text.index("\n## ", start + 1)]


#: Each "Bring your own" snippet (by its heading) and what it must print, line by line.
SNIPPETS = {
    "Your detector": [r"DetectionResult\(boxes=array\(\[\[ *0\., +54\., +128\., +120\.\]\].*"],
    "Your phenomenon plugin": [r"56\.6 -> 23\.9 \('dust\.amount', 'rain\.intensity', .*\)"],
    "Your goal model and binding": [
        "unsatisfied",
        r"G1 unsatisfied \(utility 0\): OR: one child must be satisfied",
        r"  G2 unsatisfied .*; obstructed by O1",
        r"    O1 holds \(utility 1\): A2\.category >= 1 with A2\.category = 2",
        r"  G3 unsatisfied \(utility 0\): A1\.speed == 0 with A1\.speed = 1\.2; threshold 1",
        "satisfied",
    ],
    "Your oracle": ["0", "1"],
}


def snippet(heading: str) -> str:
    """The one python block under the README's ``### {heading}…`` in "Bring your own"."""
    section = bring_your_own()
    start = section.index(f"\n### {heading}")
    end = section.find("\n### ", start + 1)
    found = re.findall(r"```python\n(.*?)```", section[start : end if end > 0 else None], re.S)
    assert len(found) == 1, heading
    return found[0]


@pytest.mark.parametrize("heading", sorted(SNIPPETS))
def test_bring_your_own_snippet_runs_as_written(heading: str, tmp_path: Path) -> None:
    """Each snippet runs alone in a fresh interpreter and prints what the README implies."""
    script = tmp_path / "snippet.py"
    script.write_text(snippet(heading), encoding="utf-8")
    done = subprocess.run(
        [sys.executable, str(script)],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) == len(SNIPPETS[heading]), done.stdout
    for line, pattern in zip(lines, SNIPPETS[heading], strict=True):
        assert re.fullmatch(pattern, line), (line, pattern)


def test_bring_your_own_names_each_plugin_as_its_entry_point_does() -> None:
    section = bring_your_own()
    for group, name in (
        ("anunnaki.detectors", "bright_spots"),
        ("anunnaki.phenomena", "dust"),
        ("anunnaki.oracles", "darkness"),
    ):
        assert f'[project.entry-points."{group}"]\n{name} = "my_package:' in section
        assert f'name = "{name}"' in section
    assert len(re.findall(r"```python\n", section)) == len(SNIPPETS)


def test_readme_cites_the_paper_as_published() -> None:
    text = README.read_text(encoding="utf-8")
    assert "Langford, Zilberman and Cheng" in text
    assert "19(3), article 17, 2024" in text
    assert "Chan" not in text
