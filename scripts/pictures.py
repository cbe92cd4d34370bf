"""Remake every picture README.md and docs/ show: ``make pictures`` (4 CPU-minutes).

What makes each picture is written in ``docs/images/pictures.yaml`` (read it for the list):

- a **dashboard** picture runs the demo's launch file as ``make demo`` / ``make demo-uav``
  do, with ``anunnaki run LAUNCH --speed 0 --until T --dashboard``: the simulated run stops
  at simulated time T (deterministic: the in-process bus and the simulated clock), the
  dashboard keeps showing that instant, headless Chromium (Playwright, Debian's
  ``/usr/bin/chromium`` or ``$ANUNNAKI_CHROMIUM``) opens the page, clicks the goal whose
  explanation is shown and saves the page (PNG, 256 colours);
- a **plot** runs the launch file whole with ``--plot`` (what ``make demo`` writes to runs/);
- a **command** is a script that draws the picture (the phenomena figure; the benchmarks'
  ``--report``, which redraws from the committed measurements in benchmarks/results/);
- a picture made **by** another command (``make results``) is named, not made.

Before a picture is written, the names its entry ``shows`` (models, oracles, tactics) are
looked for in what the run shows — the page's text, or the run's output for a plot — so a
demo that has changed fails here, naming what is missing, instead of making a picture its
caption no longer describes. tests/test_pictures.py checks the captions against the entries.

    .venv/bin/python scripts/pictures.py                      # every picture
    .venv/bin/python scripts/pictures.py dashboard.png        # only these
    .venv/bin/python scripts/pictures.py --list               # what makes what
    .venv/bin/python scripts/pictures.py --out /tmp/pictures  # write elsewhere

Needs the extras dev (playwright), vision, dashboard, plot and mail, and Chromium
(scripts/setup-browser.sh).
"""

from __future__ import annotations

import argparse
import os
import re
import secrets
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parents[1]
IMAGES = ROOT / "docs" / "images"
MANIFEST = IMAGES / "pictures.yaml"
CHROMIUM = os.environ.get("ANUNNAKI_CHROMIUM", "/usr/bin/chromium")
KINDS = ("dashboard", "plot", "command", "by")
SHOWN = ("models", "oracles", "tactics", "domains")
RUN_LIMIT = 1800.0  # s of wall time for one run (a guard against a hang; 575 s at load 16)


@dataclass(frozen=True)
class Picture:
    """One entry of the manifest: a picture and what makes it."""

    name: str
    kind: str  # one of KINDS
    source: str  # the launch file, the command line or the other command
    until: float | None = None
    goal: str | None = None
    args: tuple[str, ...] = ()
    shows: dict[str, tuple[str, ...]] = field(default_factory=dict)

    def shown(self) -> list[str]:
        """Every name the picture shows, models first."""
        return [n for key in SHOWN for n in self.shows.get(key, ())]


def load_manifest(path: Path = MANIFEST) -> list[Picture]:
    """Read the manifest; a bad entry raises ``SystemExit`` naming the file, entry and fix."""
    doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    if not isinstance(doc, dict) or doc.get("anunnaki") != "pictures/1":
        raise SystemExit(f"{path}: not a picture manifest (first key: 'anunnaki: pictures/1')")
    pictures = doc.get("pictures")
    if not isinstance(pictures, dict) or not pictures:
        raise SystemExit(f"{path}: 'pictures:' must map each picture's file name to its entry")
    return [_entry(path, str(name), spec) for name, spec in pictures.items()]


def _entry(path: Path, name: str, spec: Any) -> Picture:
    where = f"{path}: pictures[{name}]"
    if not isinstance(spec, dict):
        raise SystemExit(f"{where}: must be a mapping")
    kinds = [k for k in KINDS if k in spec]
    if len(kinds) != 1:
        raise SystemExit(f"{where}: give exactly one of {', '.join(KINDS)} (what makes it)")
    unknown = set(spec) - {*KINDS, "until", "goal", "args", "shows"}
    if unknown:
        raise SystemExit(f"{where}: unknown key(s) {sorted(unknown)}")
    kind = kinds[0]
    shows = spec.get("shows") or {}
    if not isinstance(shows, dict) or set(shows) - set(SHOWN):
        raise SystemExit(f"{where}.shows: a mapping of {', '.join(SHOWN)} to lists of names")
    until = spec.get("until")
    if (kind == "dashboard") != isinstance(until, int | float):
        raise SystemExit(f"{where}: a dashboard picture (and only one) gives 'until: SECONDS'")
    return Picture(
        name=name,
        kind=kind,
        source=str(spec[kind]),
        until=None if until is None else float(until),
        goal=None if spec.get("goal") is None else str(spec["goal"]),
        args=tuple(str(a) for a in spec.get("args") or ()),
        shows={k: tuple(str(n) for n in v) for k, v in shows.items()},
    )


def describe(picture: Picture) -> str:
    """The command that makes *picture*, as a user would type it."""
    if picture.kind == "dashboard":
        return (
            f"anunnaki run {picture.source} --speed 0 --until {picture.until:g} --dashboard"
            f" (Chromium; goal {picture.goal})"
        )
    if picture.kind == "plot":
        return shlex.join(
            ["anunnaki", "run", picture.source, "--speed", "0", *picture.args, "--plot", "…"]
        )
    if picture.kind == "command":
        return f".venv/bin/python {picture.source}"
    return f"{picture.source} (not run by make pictures)"


# -- one run of the CLI -----------------------------------------------------------------------
class Run:
    """``anunnaki run …`` in a child process, its output collected by a thread."""

    def __init__(self, argv: Sequence[str], env: dict[str, str] | None = None) -> None:
        self.argv = [sys.executable, "-m", "anunnaki.cli.main", "run", *argv]
        self.lines: list[str] = []
        self._proc = subprocess.Popen(
            self.argv,
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env={**os.environ, **(env or {})},
        )
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self._proc.stdout is not None
        for line in self._proc.stdout:
            self.lines.append(line.rstrip("\n"))

    def text(self) -> str:
        """Everything the run printed so far."""
        return "\n".join(self.lines)

    def poll(self) -> int | None:
        """The exit status, ``None`` while it runs."""
        return self._proc.poll()

    def wait(self, timeout: float) -> int:
        """Wait for the run to exit; its status."""
        rc = self._proc.wait(timeout)
        self._reader.join(5)
        return rc

    def interrupt(self) -> int:
        """Ctrl-C (a clean stop), then its status; killed if it does not stop in 30 s."""
        if self._proc.poll() is None:
            self._proc.send_signal(signal.SIGINT)
            try:
                return self.wait(30)
            except subprocess.TimeoutExpired:
                self._proc.kill()
        return self.wait(30)

    def fail(self, why: str) -> SystemExit:
        """An error naming the run, with the end of its output."""
        tail = "\n".join(self.lines[-25:])
        return SystemExit(f"{shlex.join(self.argv[3:])}: {why}\n--- its output (end) ---\n{tail}")


def missing_names(picture: Picture, text: str) -> list[str]:
    """The names *picture* shows that *text* (a page's, a run's output) does not contain."""
    return [
        n for n in picture.shown() if not re.search(rf"(?<![\w-]){re.escape(n)}(?![\w-])", text)
    ]


def make_plot(picture: Picture, out: Path) -> None:
    """Run the launch whole and draw it."""
    with tempfile.TemporaryDirectory() as tmp:
        png = Path(tmp) / picture.name
        run = Run([picture.source, "--speed", "0", *picture.args, "--plot", str(png)])
        try:
            rc = run.wait(RUN_LIMIT)
        except subprocess.TimeoutExpired:
            run.interrupt()
            raise run.fail(f"did not end within {RUN_LIMIT:g} s") from None
        if rc != 0 or not png.is_file():
            raise run.fail(f"exit {rc}, no plot written")
        missing = missing_names(picture, run.text())
        if missing:
            raise run.fail(
                f"the run does not show {missing}, which {MANIFEST.name} says {picture.name} "
                "shows: the demo changed; update the entry and the picture's captions"
            )
        shutil.copyfile(png, out / picture.name)


def make_dashboard(picture: Picture, out: Path) -> None:
    """Run the launch until the instant, open the dashboard, save the page."""
    from playwright.sync_api import sync_playwright

    assert picture.until is not None
    token = secrets.token_urlsafe(16)  # operator controls shown, as an operator sees them
    run = Run(
        [picture.source, "--speed", "0", "--until", f"{picture.until:g}", *picture.args,
         "--dashboard", "--dashboard-port", "0", "--dashboard-linger", f"{RUN_LIMIT:g}"],
        env={"ANUNNAKI_DASHBOARD_TOKEN": token},
    )  # fmt: skip
    try:
        url = _wait_for(run, lambda: re.search(r"dashboard: (http://\S+)", run.text()), "no URL")
        with tempfile.TemporaryDirectory() as profile, sync_playwright() as pw:
            ctx = pw.chromium.launch_persistent_context(
                profile,
                executable_path=CHROMIUM,
                headless=True,
                args=["--no-sandbox", "--disable-gpu", "--disable-background-networking"],
                viewport={"width": 1440, "height": 1180},
            )
            try:
                page = ctx.new_page()
                page.goto(url.group(1))
                ended = '#connection[data-state=ended][title="the run has ended"]'
                _wait_for(run, lambda: page.query_selector(ended), "the run did not end")
                _check_page(run, picture, page)
                shot = Path(profile) / "page.png"
                page.screenshot(path=str(shot), full_page=True)
                _save_png(shot, out / picture.name)
            finally:
                ctx.close()
    finally:
        run.interrupt()


def _wait_for(run: Run, found: Any, what: str) -> Any:
    """Poll ``found()`` until it is true; the run's death or the time limit is an error."""
    deadline = time.monotonic() + RUN_LIMIT
    while time.monotonic() < deadline:
        value = found()
        if value:
            return value
        if run.poll() is not None:
            raise run.fail(f"exited ({run.poll()}): {what}")
        time.sleep(0.25)
    raise run.fail(f"{what} within {RUN_LIMIT:g} s")


def _check_page(run: Run, picture: Picture, page: Any) -> None:
    """The page shows the instant and every name the entry says it shows; the goal opened."""
    assert picture.until is not None
    t = float(page.inner_text("#utu-time").split("=")[1])
    if abs(t - picture.until) > 0.5:
        raise run.fail(f"the page shows t = {t:g}, not the instant {picture.until:g}")
    if picture.goal:
        page.click(f"[data-node={picture.goal}]")
        page.wait_for_selector("#explanation-text", timeout=10_000)
    deadline = time.monotonic() + 20
    while missing := missing_names(picture, page.inner_text("body")):
        if time.monotonic() > deadline:
            raise run.fail(
                f"the page at t = {t:g} does not show {missing}, which {MANIFEST.name} says "
                f"{picture.name} shows: the demo changed; choose another instant or update "
                "the entry and the picture's captions"
            )
        page.wait_for_timeout(250)
    page.wait_for_timeout(600)  # the timeline redraws at most 4 times a second


def _save_png(src: Path, dst: Path) -> None:
    """Write *src* as a 256-colour PNG (a third of the size; the page has few colours)."""
    from PIL import Image

    with Image.open(src) as image:
        image.convert("RGB").quantize(256, method=Image.Quantize.MEDIANCUT).save(dst, optimize=True)


def make_command(picture: Picture, out: Path) -> None:
    """Run the picture's script (its output folder moved to *out* where it takes one)."""
    argv = shlex.split(picture.source)
    if out != IMAGES:
        flag = "--output" if argv[0].endswith("make_phenomena_figure.py") else "--images"
        argv += [flag, str(out / picture.name) if flag == "--output" else str(out)]
        if flag == "--images":
            argv += ["--doc", str(out / (Path(argv[0]).stem + ".md"))]
    result = subprocess.run(
        [sys.executable, *argv], cwd=ROOT, capture_output=True, text=True, check=False
    )
    if result.returncode != 0:
        raise SystemExit(f"{picture.source}: exit {result.returncode}\n{result.stderr[-3000:]}")


MAKERS = {"dashboard": make_dashboard, "plot": make_plot, "command": make_command}


def check_tools() -> None:
    """What the pictures need is here, or say how to get it."""
    need = {"playwright": "dev", "PIL": "plot", "matplotlib": "plot", "fastapi": "dashboard"}
    missing = []
    for module, extra in need.items():
        try:
            __import__(module)
        except ImportError:
            missing.append(extra)
    if missing:
        raise SystemExit(
            f"the pictures need the extras {sorted(set(missing))}: "
            f".venv/bin/python -m pip install -e '.[{','.join(sorted(set(missing)))}]'"
        )
    if not Path(CHROMIUM).is_file():
        raise SystemExit(f"no Chromium at {CHROMIUM}: scripts/setup-browser.sh (as root), "
                         "or set ANUNNAKI_CHROMIUM")  # fmt: skip


def cost(picture: Picture) -> float:
    """Simulated seconds a picture's run takes (its scenario's duration for a plot)."""
    if picture.kind == "dashboard":
        return picture.until or 0.0
    if picture.kind != "plot":
        return 0.0
    launch = ROOT / picture.source
    sim = yaml.safe_load(launch.read_text(encoding="utf-8"))["managed"]["sim"]
    scenario = yaml.safe_load((launch.parent / sim["scenario"]).read_text(encoding="utf-8"))
    return float(scenario["duration"])


def make(picture: Picture, out: Path) -> str | None:
    """Make one picture; the error, or ``None``."""
    start = time.monotonic()
    print(f"{picture.name}: {describe(picture)}", flush=True)
    try:
        MAKERS[picture.kind](picture, out)
    except SystemExit as e:
        print(f"{picture.name}: FAILED", flush=True)
        return f"{picture.name}: {e}"
    print(f"{picture.name}: written in {time.monotonic() - start:.0f} s", flush=True)
    return None


def main(argv: Sequence[str] | None = None) -> int:
    """Make the pictures asked for (default: all the manifest's that this command makes)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help="pictures to make (default: every one)")
    ap.add_argument("--out", type=Path, default=IMAGES, help="folder (default docs/images)")
    ap.add_argument("--list", action="store_true", help="print what makes each picture")
    ap.add_argument("--jobs", type=int, default=2, help="runs at a time (default 2)")
    args = ap.parse_args(argv)
    pictures = load_manifest()
    if args.list:
        for p in pictures:
            print(f"{p.name:40} {describe(p)}")
        return 0
    unknown = set(args.names) - {p.name for p in pictures}
    if unknown:
        raise SystemExit(f"not in {MANIFEST}: {sorted(unknown)}")
    chosen = [p for p in pictures if not args.names or p.name in args.names]
    for p in chosen:
        if p.kind == "by":
            print(f"{p.name}: made by {p.source}, not here")
    once = {(p.kind, p.source) if p.kind == "command" else p.name: p for p in chosen}
    todo = sorted((p for p in once.values() if p.kind != "by"), key=cost, reverse=True)
    check_tools()
    args.out.mkdir(parents=True, exist_ok=True)
    start = time.monotonic()
    with ThreadPoolExecutor(max(1, args.jobs)) as pool:  # the runs are child processes
        errors = [e for e in pool.map(lambda p: make(p, args.out), todo) if e]
    print(f"{len(todo) - len(errors)} of {len(todo)} made in {time.monotonic() - start:.0f} s")
    for error in errors:
        print(error, file=sys.stderr)
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
