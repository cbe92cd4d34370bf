"""The pictures README.md and docs/ show: each is made by `make pictures` from the current files.

docs/images/pictures.yaml (read by scripts/pictures.py, which makes the pictures) names what
makes each picture and what it shows. Here: every picture a page shows has an entry; a
dashboard picture comes from a launch file that `make demo` or `make demo-uav` runs; the
models, oracles, tactics and benchmark domains an entry shows exist (the launch's registry,
its oracle and scorer, its tactics file; benchmarks/results/robustify.json); and every
caption — the alt text, the table cell under the picture, the paragraph after it (and the
one before it when that ends in a colon) — names only what its entry shows: model ids
(``rover-…``, ``uav-…``), oracle names, tactics in backticks, launch files and the instant
``t = N s`` of a dashboard picture.
"""

from __future__ import annotations

import importlib.util
import json
import re
import sys
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("**/*.md"))]
IMAGE = re.compile(r"!\[([^\]]*)\]\(([^)\s]+)\)")
MODEL_ID = re.compile(r"(?<![\w/.+-])(?:rover|uav)-[A-Za-z0-9_+]+(?:-[A-Za-z0-9_+]+)*")
BACKTICKED = re.compile(r"`([^`\n]+)`")
TACTIC_LIKE = re.compile(r"[a-z][a-z0-9_]*(?:-[a-z0-9_]+)+")
YAML_PATH = re.compile(r"[\w./-]+\.yaml\b")
INSTANT = re.compile(r"\bt = (\d+(?:\.\d+)?) s\b")


def _load_pictures() -> ModuleType:
    spec = importlib.util.spec_from_file_location("pictures", ROOT / "scripts" / "pictures.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["pictures"] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


pictures = _load_pictures()
Picture = pictures.Picture


@dataclass(frozen=True)
class Caption:
    page: Path
    picture: str  # the file name under docs/images
    text: str  # alt text and the caption around it

    def where(self) -> str:
        return f"{self.page.relative_to(ROOT)} ({self.picture})"


# -- reading the pages ------------------------------------------------------------------------
def _blocks(text: str) -> list[str]:
    """The page's paragraphs (blank-line separated; a fenced block is one)."""
    blocks, current, fenced = [], [], False
    for line in text.splitlines():
        if line.startswith("```"):
            fenced = not fenced
        if not line.strip() and not fenced:
            if current:
                blocks.append("\n".join(current))
            current = []
        else:
            current.append(line)
    if current:
        blocks.append("\n".join(current))
    return blocks


def _prose(block: str | None) -> str:
    """A block that can be a caption: not a heading, code, table or another picture."""
    if block is None or block.startswith(("#", "```", "|", "<!--")) or IMAGE.search(block):
        return ""
    return block


def _cells(row: str) -> list[str]:
    return [c.strip() for c in row.strip().strip("|").split("|")]


def captions_of(page: Path, text: str) -> list[Caption]:
    """Every picture under images/ that *text* shows, with its caption."""
    found = []
    blocks = _blocks(text)
    for i, block in enumerate(blocks):
        if not IMAGE.search(block):
            continue
        if block.startswith("|"):  # a table: the caption is the cell under the picture
            rows = [r for r in block.splitlines() if not re.fullmatch(r"[|\s:-]+", r)]
            for r, row in enumerate(rows):
                for c, cell in enumerate(_cells(row)):
                    below = _cells(rows[r + 1]) if r + 1 < len(rows) else []
                    under = below[c] if c < len(below) and not IMAGE.search(below[c]) else ""
                    for alt, path in IMAGE.findall(cell):
                        found.append((path, f"{alt}\n{under}"))
            continue
        before = _prose(blocks[i - 1] if i else None)
        after = _prose(blocks[i + 1] if i + 1 < len(blocks) else None)
        around = (before if before.rstrip().endswith(":") else "") + "\n" + after
        for alt, path in IMAGE.findall(block):
            found.append((path, f"{alt}\n{around}"))
    return [
        Caption(page, Path(path).name, caption)
        for path, caption in found
        if "images/" in path and path.endswith(".png")
    ]


@cache
def all_captions() -> tuple[Caption, ...]:
    return tuple(c for p in PAGES for c in captions_of(p, p.read_text(encoding="utf-8")))


# -- what the files say -----------------------------------------------------------------------
def demo_launches() -> set[str]:
    """The launch files the Makefile's recipes run (``anunnaki run FILE``)."""
    text = (ROOT / "Makefile").read_text(encoding="utf-8")
    variables = dict(re.findall(r"^(\w+)\s*:=\s*(\S+)\s*$", text, re.M))
    runs = re.findall(r"^\t.*\banunnaki(?:\.cli\.main)? run (\S+)", text, re.M)  # recipes
    return {re.sub(r"\$\((\w+)\)", lambda m: variables[m.group(1)], r) for r in runs}


def make_targets() -> set[str]:
    text = (ROOT / "Makefile").read_text(encoding="utf-8")
    return set(re.findall(r"^([\w-]+):", text, re.M))


@cache
def launch_facts(launch: str) -> dict[str, Any]:
    """What a launch file shows: its models, oracle and scorer, tactics, goals, files."""
    from anunnaki.goals import load_binding, load_goal_model
    from anunnaki.lec import load_registry
    from anunnaki.tactics import load_tactics

    path = ROOT / launch
    doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    utu, sim = doc["utu"], doc["managed"]["sim"]
    files = {
        k: path.parent / v for k, v in utu.items() if k in ("goal_model", "binding", "tactics")
    }
    files |= {k: path.parent / sim[k] for k in ("scenario", "models")}
    binding = load_binding(files["binding"])
    scenario = yaml.safe_load(files["scenario"].read_text(encoding="utf-8"))
    return {
        "models": set(load_registry(files["models"]).ids()),
        "oracles": {sim[k]["name"] for k in ("oracle", "scorer") if k in sim},
        "tactics": {t.name for t in load_tactics(files["tactics"]).tactics},
        "goals": set(load_goal_model(files["goal_model"], binding=binding).nodes()),
        "files": {path.name, *(f.name for f in files.values())},
        "duration": float(scenario["duration"]),
    }


@cache
def benchmark_domains() -> set[str]:
    doc = json.loads((ROOT / "benchmarks/results/robustify.json").read_text(encoding="utf-8"))
    return set(doc["domains"])


@cache
def oracle_names() -> set[str]:
    """The oracles' names: built in, and the installed plugins' (not loaded: torch is slow)."""
    from importlib.metadata import entry_points

    from anunnaki.oracles import ORACLES

    plugins = {ep.name for ep in entry_points(group=ORACLES.group or "")}
    return set(ORACLES.copy(entry_points=False).names()) | plugins


# -- the checks -------------------------------------------------------------------------------
def entry_problems(p: Any) -> list[str]:
    """What is wrong with one manifest entry (empty: nothing)."""
    problems = []
    if p.kind == "dashboard" and p.source not in demo_launches():
        problems.append(
            f"{p.name}: dashboard of {p.source}, which neither `make demo` nor `make demo-uav` "
            f"runs ({sorted(demo_launches())}): a dashboard picture shows a current demo"
        )
    if p.kind in ("dashboard", "plot"):
        problems += _launch_problems(p)
    elif p.shows.get("models") or p.shows.get("oracles") or p.shows.get("tactics"):
        problems.append(f"{p.name}: only a launch's picture shows models, oracles or tactics")
    for name in p.shows.get("domains", ()):
        if name not in benchmark_domains():
            problems.append(f"{p.name}: shows domain {name!r}, not a benchmarks/robustify.py one")
    if p.kind == "command" and not (ROOT / p.source.split()[0]).is_file():
        problems.append(f"{p.name}: no script {p.source.split()[0]}")
    if p.kind == "by" and not re.fullmatch(r"make [\w-]+", p.source):
        problems.append(f"{p.name}: by: must be a make target ('make results')")
    elif p.kind == "by" and p.source.split()[1] not in make_targets():
        problems.append(f"{p.name}: the Makefile has no target {p.source.split()[1]!r}")
    return problems


def _launch_problems(p: Any) -> list[str]:
    """A dashboard's or plot's names are its launch file's."""
    if not (ROOT / p.source).is_file():
        return [f"{p.name}: no launch file {p.source}"]
    facts = launch_facts(p.source)
    problems = [
        f"{p.name}: shows {key[:-1]} {name!r}, which {p.source} does not have "
        f"(its {key}: {sorted(facts[key])})"
        for key in ("models", "oracles", "tactics")
        for name in p.shows.get(key, ())
        if name not in facts[key]
    ]
    if p.goal is not None and p.goal not in facts["goals"]:
        problems.append(f"{p.name}: goal {p.goal} is not in {p.source}'s goal model")
    if p.until is not None and not 0 < p.until <= facts["duration"]:
        problems.append(f"{p.name}: until {p.until:g} s is outside the scenario")
    return problems


def caption_problems(caption: Caption, p: Any) -> list[str]:
    """The names *caption* gives that its entry *p* does not show."""
    text, where = caption.text, caption.where()
    problems = []
    models = set(p.shows.get("models", ())) | set(p.shows.get("domains", ()))
    for name in sorted(set(MODEL_ID.findall(text)) - models):
        problems.append(
            f"{where}: the caption names model {name!r}; the picture shows {sorted(models)}"
        )
    said = {n.replace("-", "_") for n in re.findall(r"`?([\w-]+)`?\)? oracles?\b", text)}
    said |= set(BACKTICKED.findall(text))
    for name in sorted((said & oracle_names()) - set(p.shows.get("oracles", ()))):
        problems.append(f"{where}: the caption names oracle {name!r}; the picture shows "
                        f"{sorted(p.shows.get('oracles', ()))}")  # fmt: skip
    tactics = set(p.shows.get("tactics", ()))
    for name in sorted(set(BACKTICKED.findall(text)) - models):
        if TACTIC_LIKE.fullmatch(name) and not MODEL_ID.fullmatch(name) and name not in tactics:
            problems.append(f"{where}: the caption names tactic {name!r}; the picture shows "
                            f"{sorted(tactics)}")  # fmt: skip
    if p.kind in ("dashboard", "plot") and (ROOT / p.source).is_file():
        files = launch_facts(p.source)["files"]
        for path in sorted(set(YAML_PATH.findall(text))):
            if Path(path).name not in files:
                problems.append(f"{where}: the caption names {path}; the picture is of "
                                f"{p.source} ({sorted(files)})")  # fmt: skip
    if p.kind == "dashboard":
        instants = {float(t) for t in INSTANT.findall(text)}
        if p.until not in instants:
            problems.append(f"{where}: the caption does not give the instant t = {p.until:g} s")
        for t in sorted(instants):
            if t > p.until:
                problems.append(f"{where}: the caption gives t = {t:g} s, after the picture's "
                                f"instant {p.until:g} s")  # fmt: skip
    return problems


def manifest() -> dict[str, Any]:
    return {p.name: p for p in pictures.load_manifest()}


# -- the tests --------------------------------------------------------------------------------
def test_every_picture_shown_has_an_entry_and_a_file() -> None:
    entries = manifest()
    shown = {c.picture for c in all_captions()}
    assert shown - set(entries) == set(), "pictures shown but not in docs/images/pictures.yaml"
    assert set(entries) - shown == set(), "entries for pictures no page shows"
    missing = [n for n in entries if not (pictures.IMAGES / n).is_file()]
    assert missing == []


def test_every_entry_names_what_exists() -> None:
    problems = [m for p in manifest().values() for m in entry_problems(p)]
    assert problems == []


def test_every_caption_names_only_what_its_picture_shows() -> None:
    entries = manifest()
    problems = [m for c in all_captions() for m in caption_problems(c, entries[c.picture])]
    assert problems == []


def test_the_dashboard_pictures_are_of_the_demos() -> None:
    kinds = {p.name: (p.kind, p.source) for p in pictures.load_manifest()}
    assert kinds["dashboard.png"] == ("dashboard", "examples/rover/demo.yaml")
    assert kinds["uav-dashboard.png"] == ("dashboard", "examples/uav/sim.yaml")
    assert demo_launches() == {"examples/rover/demo.yaml", "examples/uav/sim.yaml"}


# The old rover picture (docs/images/dashboard.png until issue 34): examples/rover/sim.yaml
# at 15.9 s with the ground-truth oracle and rover-fog, since gone from the registry.
OLD_ROVER = Picture(
    name="dashboard.png",
    kind="dashboard",
    source="examples/rover/sim.yaml",
    until=16.0,
    goal="G4",
    shows={"models": ("rover-fog",), "oracles": ("ground_truth",)},
)


def test_the_old_rover_picture_is_refused() -> None:
    problems = entry_problems(OLD_ROVER)
    assert len(problems) == 2, problems
    assert "which neither `make demo` nor `make demo-uav` runs" in problems[0]
    assert "shows model 'rover-fog', which examples/rover/sim.yaml does not have" in problems[1]


def test_a_caption_naming_what_the_picture_does_not_show_is_refused() -> None:
    entry = manifest()["dashboard.png"]
    text = (
        "![The dashboard on the rover](docs/images/dashboard.png)\n\n"
        "*The rover (`examples/rover/sim.yaml`) at t = 15.9 s: `rover-fog` is active, the "
        "`ground_truth` oracle says 0, `swap-to-low-light-model` is done; at t = 41 s the "
        "operator gets mail.*\n"
    )
    [caption] = captions_of(ROOT / "README.md", text)
    problems = caption_problems(caption, entry)
    assert [m.split(": ", 1)[1].split(";")[0] for m in problems] == [
        "the caption names model 'rover-fog'",
        "the caption names oracle 'ground_truth'",
        "the caption names tactic 'swap-to-low-light-model'",
        "the caption names examples/rover/sim.yaml",
        "the caption does not give the instant t = 30 s",
        "the caption gives t = 41 s, after the picture's instant 30 s",
    ]


def test_a_table_caption_is_the_cell_under_the_picture() -> None:
    text = (
        "| a | b |\n|---|---|\n| ![A](docs/images/a.png) | ![B](docs/images/b.png) |\n"
        "| under a: `rover-x` | under b: `uav-y` |\n"
    )
    got = {c.picture: c.text for c in captions_of(ROOT / "README.md", text)}
    assert got == {"a.png": "A\nunder a: `rover-x`", "b.png": "B\nunder b: `uav-y`"}


@pytest.mark.parametrize(
    ("spec", "error"),
    [
        ({"plot": "x.yaml", "by": "make results"}, "give exactly one of"),
        ({"dashboard": "x.yaml"}, "gives 'until: SECONDS'"),
        ({"plot": "x.yaml", "shows": {"model": ["a"]}}, "shows: a mapping of"),
    ],
)
def test_a_bad_manifest_entry_is_named(tmp_path: Path, spec: dict[str, Any], error: str) -> None:
    path = tmp_path / "pictures.yaml"
    path.write_text(yaml.safe_dump({"anunnaki": "pictures/1", "pictures": {"p.png": spec}}))
    with pytest.raises(SystemExit, match=rf"pictures\.yaml: pictures\[p\.png\].*{error}"):
        pictures.load_manifest(path)
