"""docs/simulation.md: its first Python block runs, its scenario example is valid."""

from __future__ import annotations

import re
from pathlib import Path

from anunnaki._safeyaml import load_yaml
from anunnaki.sim import parse_scenario

DOC = (Path(__file__).parents[2] / "docs" / "simulation.md").read_text(encoding="utf-8")
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.MULTILINE | re.DOTALL)


def test_the_dataset_example_runs() -> None:
    blocks = [body for lang, body in FENCE.findall(DOC) if lang == "python"]
    exec(compile(blocks[0], "docs/simulation.md", "exec"), {})  # our own docs


def test_the_scenario_example_is_valid() -> None:
    blocks = [body for lang, body in FENCE.findall(DOC) if lang == "yaml"]
    data, lines = load_yaml("docs/simulation.md", text=blocks[0])
    sc = parse_scenario(data, lines=lines)
    assert sc.platform == "rover" and len(sc.faults) == 3
