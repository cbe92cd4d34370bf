"""A simulated run is one deterministic program (issue #30): the same run twice, one of them
beside a busy process, gives the same report byte for byte and the same decision log.

The full check (the rover demo's first 30 s and the whole UAV mission, three times each) is
``benchmarks/determinism.py``; here shorter stretches of both, so the suite stays quick.
"""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from anunnaki.launch import load_launch, run_launch
from anunnaki.managed import SimKind
from anunnaki.utu import replay

ROOT = Path(__file__).parents[2]


@contextlib.contextmanager
def busy() -> Iterator[None]:
    """A process that keeps one core busy for as long as the block runs."""
    proc = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        yield
    finally:
        proc.kill()
        proc.wait()


def run(launch_file: Path, until: float, report: Path) -> tuple[bytes, list[tuple]]:
    """One run at ``--speed 0``: its report file's bytes and its decisions.

    Its knowledge base is kept beside the report (``.db``): ``anunnaki replay`` reads it.
    """
    launch = load_launch(launch_file)
    assert isinstance(launch.managed, SimKind)
    launch.managed.with_reports(report=str(report), plot=None)
    out = io.StringIO()
    result = run_launch(
        launch,
        speed=0,
        until=until,
        out=out,
        handle_signals=False,
        knowledge=str(report.with_suffix(".db")),
    )
    assert result.exit_code == 0, out.getvalue()
    decisions = [(d.t, d.kind, d.tactic, sorted(d.data.items())) for d in result.decisions]
    return report.read_bytes(), decisions


@pytest.mark.slow
@pytest.mark.timeout(600)
@pytest.mark.parametrize(
    ("launch", "until"),
    [("examples/rover/demo.yaml", 9.0), ("examples/uav/sim.yaml", 11.0)],
    ids=["rover", "uav"],
)
def test_a_run_repeats_itself_quiet_and_loaded(tmp_path: Path, launch: str, until: float) -> None:
    quiet = run(ROOT / launch, until, tmp_path / "quiet.json")
    with busy():
        loaded = run(ROOT / launch, until, tmp_path / "loaded.json")
    assert quiet[1], "the stretch should decide something"
    assert loaded[1] == quiet[1]  # the same decisions at the same times
    assert loaded[0] == quiet[0]  # the same report, byte for byte
    again = replay(str(tmp_path / "quiet.db"))  # `anunnaki replay` of the run
    assert again.identical, again.notes
