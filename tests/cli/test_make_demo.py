"""``make demo``'s run: it imports only what its setup installs, ends without a warning, and
its dashboard says what it waits for after the run (issue #34, item 9)."""

from __future__ import annotations

import importlib.metadata as md
import json
import os
import re
import subprocess
import sys
import threading
import tomllib
from pathlib import Path

import pytest

from anunnaki.cli._dashboard import linger

ROOT = Path(__file__).resolve().parents[2]
URL = "http://127.0.0.1:8765/"

#: Runs the CLI and writes the distributions of every module it imported to argv[1] at exit.
IMPORTS = """
import atexit, importlib.metadata as md, json, runpy, sys
out = sys.argv.pop(1)
def dump():
    names = md.packages_distributions()
    tops = {m.partition(".")[0] for m in list(sys.modules)}
    with open(out, "w") as fh:
        json.dump(sorted({d for t in tops for d in names.get(t, [])}), fh)
atexit.register(dump)
sys.argv[0] = "anunnaki"
runpy.run_module("anunnaki.cli.main", run_name="__main__")
"""


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def needs(extras: list[str]) -> set[str]:
    """The distributions ``anunnaki[extras]`` requires, transitively.

    Anunnaki's own requirements come from pyproject.toml (an editable install's metadata is
    as old as its install), those of the others from what is installed.
    """
    from packaging.requirements import Requirement

    project = tomllib.loads((ROOT / "pyproject.toml").read_text("utf-8"))["project"]
    todo = [Requirement(r) for r in project["dependencies"]]
    groups, seen_groups = list(extras), set()
    while groups:
        group = groups.pop()
        if group not in seen_groups:
            seen_groups.add(group)
            for line in project["optional-dependencies"][group]:
                req = Requirement(line)
                if req.name == "anunnaki":
                    groups.extend(req.extras)
                else:
                    todo.append(req)
    seen: set[tuple[str, frozenset[str]]] = set()
    while todo:
        req = todo.pop()
        key = (_norm(req.name), frozenset(req.extras))
        if key in seen:
            continue
        seen.add(key)
        try:
            lines = md.requires(req.name) or []
        except md.PackageNotFoundError:
            continue
        envs = [{"extra": e} for e in req.extras] or [{"extra": ""}]
        for line in lines:
            sub = Requirement(line)
            if sub.marker is None or any(sub.marker.evaluate(env) for env in envs):
                todo.append(sub)
    return {name for name, _ in seen}


def demo_extras() -> list[str]:
    text = (ROOT / "scripts" / "setup.sh").read_text("utf-8")
    m = re.search(r"^DEMO_EXTRAS=(\S+)$", text, re.MULTILINE)
    assert m is not None
    return m.group(1).split(",")


@pytest.mark.slow
@pytest.mark.timeout(300)  # the simulator and six models load: 15 s quiet, minutes shared
def test_the_demo_imports_what_its_setup_installs_and_ends_quietly(tmp_path: Path) -> None:
    pytest.importorskip("pybullet")
    pytest.importorskip("fastapi")
    out = tmp_path / "imported.json"
    args = ["run", str(ROOT / "examples" / "rover" / "demo.yaml"), "--speed", "0"]
    args += ["--until", "2", "--dashboard", "--dashboard-port", "0"]
    # The linger outlasts the dashboard's 2 s poll of Utu's decisions: a poll after the bus
    # closed warned 'knowledge … does not answer (bus 'rover-demo-launch' is closed)'.
    args += ["--dashboard-linger", "3", "--report", str(tmp_path / "demo.json")]
    args += ["--plot", str(tmp_path / "demo.png")]
    proc = subprocess.run(
        [sys.executable, "-c", IMPORTS, str(out), *args],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
        timeout=280,
        check=False,
    )
    text = proc.stdout + proc.stderr
    assert proc.returncode == 0, text
    assert "stopped (reached t=2)" in text
    assert "keeps showing its last state for 3 s (Ctrl-C to leave now)" in text
    assert "does not answer" not in text, proc.stderr
    # Nothing outside the demo profile's extras (besides itself and the venv's pip, setuptools).
    imported = {_norm(d) for d in json.loads(out.read_text("utf-8"))}
    extra = imported - needs(demo_extras()) - {"anunnaki", "pip", "setuptools"}
    assert not extra, f"make demo imports {sorted(extra)}, which scripts/setup.sh demo lacks"


class FakeWait:
    """Stands in for the wait on a signal: records each timeout; a 'Ctrl-C' on call N."""

    def __init__(self, interrupt_at: int | None = None) -> None:
        self.timeouts: list[float | None] = []
        self.interrupt_at = interrupt_at

    def __call__(self, stop: threading.Event, timeout: float | None) -> None:
        self.timeouts.append(timeout)
        if len(self.timeouts) == self.interrupt_at:
            stop.set()


def test_the_linger_says_every_10_s_how_long_the_page_stays_up() -> None:
    said: list[str] = []
    wait = FakeWait()
    linger(URL, 30, say=said.append, wait=wait)
    assert wait.timeouts == [10, 10, 10]
    assert said == [
        f"dashboard: the run has ended; {URL} keeps showing its last state for 30 s "
        "(Ctrl-C to leave now)",
        f"dashboard: still up at {URL} for 20 s more; Ctrl-C to leave",
        f"dashboard: still up at {URL} for 10 s more; Ctrl-C to leave",
    ]


def test_the_linger_ends_at_ctrl_c_and_keeps_odd_lengths() -> None:
    said: list[str] = []
    wait = FakeWait(interrupt_at=2)
    linger(URL, 25, say=said.append, wait=wait)
    assert wait.timeouts == [10, 10] and len(said) == 2  # nothing said after the Ctrl-C
    wait = FakeWait()
    linger(URL, 25, say=(said := []).append, wait=wait)
    assert wait.timeouts == [10, 10, 5] and said[-1].endswith("for 5 s more; Ctrl-C to leave")


def test_without_a_linger_the_page_stays_until_ctrl_c() -> None:
    said: list[str] = []
    wait = FakeWait()
    linger(URL, None, say=said.append, wait=wait)
    assert wait.timeouts == [None]
    assert said == [
        f"dashboard: the run has ended; {URL} keeps showing its last state until Ctrl-C"
    ]
