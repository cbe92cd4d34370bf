"""``anunnaki run`` with a live assurance case, and ``anunnaki assurance status --knowledge``.

The scripted rover (examples/rover/utu.yaml): at t = 25 s the oracle reports category 1,
G3 (and with it G2) is unsatisfied until the fail-safe has switched to manual mode at 25.5 s.
A small criteria file develops G2's leaves with a passing figure, so G2 holds at the start,
loses its support at 25 s and regains it at 25.5 s: the decision log says so, once each.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from anunnaki.cli.main import main
from anunnaki.utu import Knowledge
from live_rover import LIVE_LAG, LIVE_SPEED

ROOT = Path(__file__).resolve().parents[2]
LAUNCH = ROOT / "examples" / "rover" / "utu.yaml"
CLI = [sys.executable, "-m", "anunnaki.cli.main"]


@pytest.fixture(scope="module")
def case_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("case")
    (tmp / "fig.json").write_text('{"x": 1.0}')
    item = "[{kind: result, file: fig.json, path: x, text: a figure, at_least: 0.5}]"
    lines = [
        "anunnaki: assurance/1",
        "case: rover-scripted",
        f"goal_model: {ROOT / 'examples/rover/goals.yaml'}",
        "evidence:",
        *(f"  {g}: {item}" for g in ("G5", "G6", "G7", "G8", "G11", "O1")),
    ]
    (tmp / "crit.yaml").write_text("\n".join(lines) + "\n")
    out = tmp / "case"
    build = ["assurance", "build", str(LAUNCH), "--criteria", str(tmp / "crit.yaml")]
    code = main([*build, "--root", str(tmp), "--out", str(out)])
    assert code == 1  # G1 is not supported: G12's leaves are undeveloped
    return out


def _run(case_dir: Path, db: Path) -> list[tuple[float, dict[str, object]]]:
    code = main(
        [
            "run",
            str(LAUNCH),
            "--case",
            str(case_dir),
            "--knowledge",
            str(db),
            "--fresh",
            "--speed",
            "50",
        ]
    )
    assert code == 0
    kb = Knowledge(db)
    try:
        return [(d.t, d.data) for d in kb.decisions() if d.kind == "assurance"]
    finally:
        kb.close()


def test_a_run_records_when_a_top_claim_loses_and_regains_support(
    case_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rows = _run(case_dir, tmp_path / "run.db")
    printed = capsys.readouterr().out
    assert "assurance: case rover (33 nodes" in printed and "evaluated live" in printed
    initial = {d["claim"]: d["status"] for t, d in rows if d["support"] == "initial"}
    assert initial == {"G1": "undeveloped", "G2": "supported", "G12": "undeveloped"}
    changes = [
        (t, d["claim"], d["support"], d["status"]) for t, d in rows if d["support"] != "initial"
    ]
    assert changes == [
        (25.0, "G2", "lost", "violated"),
        (25.5, "G2", "regained", "supported"),
    ]
    lost = next(d for t, d in rows if d["support"] == "lost")
    assert lost["reason"] == "the goal model finds it unsatisfied"
    # the same run again: the same record (one deterministic program on sim time)
    assert _run(case_dir, tmp_path / "again.db") == rows
    capsys.readouterr()

    # status from the knowledge file, at an instant and at the end
    status = [
        "assurance",
        "status",
        "--case",
        str(case_dir),
        "--knowledge",
        str(tmp_path / "run.db"),
    ]
    code = main([*status, "--at", "25.2"])
    out = capsys.readouterr().out
    assert code == 1  # G1 does not hold
    assert "top-level claim G1 violated" in out
    assert " *G2                 violated     the goal model finds it unsatisfied" in out
    assert "25.000  G2 support lost (violated)" in out and "25.500" not in out
    code = main([*status, "--json", "--all"])
    body = json.loads(capsys.readouterr().out)
    assert body["nodes"]["G2"][0] == "supported" and body["nodes"]["S-G2"][0] == "supported"
    assert [c["support"] for c in body["changes"]] == ["lost", "regained"]
    # explain says how the top claims stood; a replay neither makes nor compares them
    assert main(["explain", str(tmp_path / "run.db"), "--at", "25.2"]) == 0
    out = capsys.readouterr().out
    assert "top-level claims as recorded: G1 undeveloped (initial at 0.000 s); G2 violated " in out
    assert main(["replay", str(tmp_path / "run.db")]) == 0


def test_no_case_and_a_missing_case(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = tmp_path / "run.db"
    code = main(["run", str(LAUNCH), "--no-case", "--knowledge", str(db), "--speed", "50"])
    assert code == 0 and "assurance:" not in capsys.readouterr().out
    kb = Knowledge(db)
    assert not [d for d in kb.decisions() if d.kind == "assurance"]
    kb.close()
    code = main(["run", str(LAUNCH), "--case", str(tmp_path / "nowhere"), "--speed", "50"])
    assert code == 2
    assert "no assurance case here" in capsys.readouterr().err


def test_processes_record_too(case_dir: Path, tmp_path: Path) -> None:
    """One process per node: the launch's own connection records (and commits) the claims.

    A live run (tests/live_rover.py): G2 loses its support at the latest ``LIVE_LAG``
    simulated seconds after the light dims (sooner if G6 reads as violated first) and
    regains it once the fail-safe has switched to manual; a goal gone unknown for a moment
    under load may lose and regain it again, always in turn.
    """
    db = tmp_path / "run.db"
    args = ["run", str(LAUNCH), "--processes", "--case", str(case_dir), "--knowledge", str(db)]
    assert main([*args, "--speed", str(LIVE_SPEED)]) == 0
    kb = Knowledge(db)
    rows = [
        (d.t, d.data["claim"], d.data["support"]) for d in kb.decisions() if d.kind == "assurance"
    ]
    kb.close()
    changes = [r for r in rows if r[2] != "initial"]  # the first step's, at 0 or later
    assert changes and {claim for _, claim, _ in changes} == {"G2"}, rows
    supports = [support for _, _, support in changes]
    assert supports == ["lost", "regained"] * (len(supports) // 2) and supports, rows
    (lost, _, _), (regained, _, _) = changes[:2]
    assert lost < 25.0 + LIVE_LAG and lost < regained <= lost + 5.0, rows  # fail-safe deadline


def test_status_asks_a_running_launch_over_its_bus(case_dir: Path, tmp_path: Path) -> None:
    rover = ROOT / "examples" / "rover"
    port = free_port()
    text = (rover / "utu-processes.yaml").read_text()
    for name in ("goals.yaml", "binding.yaml", "tactics.yaml", "trace.jsonl"):
        text = text.replace(f": {name}", f": {rover / name}")
    launch = tmp_path / "launch.yaml"
    launch.write_text(text.replace("7447", str(port)))
    proc = subprocess.Popen(
        [*CLI, "run", str(launch), "--case", str(case_dir)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            if line.startswith("ready:"):
                break
        out = subprocess.run(
            [*CLI, "assurance", "status", str(launch), "--json", "--timeout", "30"],
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )
        body = json.loads(out.stdout)
        assert out.returncode == 1, out.stderr  # G1 does not hold (G12 undeveloped)
        assert body["case"] == "rover" and body["root"] == "G1"
        assert body["nodes"]["G12"][0] == "undeveloped" and body["kinds"]["S-G2"] == "strategy"
        assert "svg" not in body
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        if proc.stdout is not None:
            proc.stdout.close()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_the_launch_file_names_its_case_or_none(
    case_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rover = ROOT / "examples" / "rover"
    text = (rover / "utu.yaml").read_text()
    for name in ("goals.yaml", "binding.yaml", "tactics.yaml", "trace.jsonl"):
        text = text.replace(f": {name}", f": {rover / name}")
    (tmp_path / "cases").mkdir()
    (tmp_path / "cases" / "rover").symlink_to(case_dir)
    launch = tmp_path / "launch.yaml"
    launch.write_text(text + "assurance: cases/rover\n")  # relative to the launch file
    assert main(["run", str(launch), "--speed", "50", "--knowledge", str(tmp_path / "a.db")]) == 0
    assert "assurance: case rover (33 nodes" in capsys.readouterr().out
    launch.write_text(text + "assurance: false\n")
    assert main(["run", str(launch), "--speed", "50"]) == 0
    assert "assurance:" not in capsys.readouterr().out
