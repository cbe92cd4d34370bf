"""``anunnaki log | explain | replay``: output, filters, exit codes, the export round trip."""

from __future__ import annotations

import json
import re
import shutil
import sqlite3
import threading
from collections.abc import Mapping
from itertools import groupby
from pathlib import Path
from typing import Any

import pytest

from anunnaki.bus import open_bus
from anunnaki.cli.main import main
from anunnaki.launch import format_decision
from anunnaki.managed import ScriptedSystem
from anunnaki.trace import read_trace
from anunnaki.utu import (
    ActionOutcome,
    AutonomicManager,
    BusActuator,
    Knowledge,
    RecordingActuator,
    parse_config,
)

ROVER = Path(__file__).resolve().parents[2] / "examples" / "rover"
ESC = "\x1b["


class Rover(ScriptedSystem):
    """The scripted rover, telling the test when it has taken a buzzer command.

    It takes commands on a subscriber thread; the recording waits for each one before the
    next instant, so a run records the same inputs however loaded the machine is.
    """

    def __init__(self, bus: Any, trace: Path) -> None:
        self.heard = threading.Semaphore(0)
        super().__init__(bus, trace)

    def _buzzer(self, sample: Any) -> None:
        super()._buzzer(sample)
        self.heard.release()

    def __enter__(self) -> Rover:
        return self


class CountingActuator(BusActuator):
    """Counts the buzzer commands the manager sends."""

    def __init__(self, bus: Any) -> None:
        super().__init__(bus)
        self.buzzes = 0

    def publish(self, topic: str, payload: Mapping[str, Any]) -> ActionOutcome:
        outcome = super().publish(topic, payload)
        if topic == "/rover/buzzer":
            self.buzzes += 1
        return outcome


def config(db: Path, goals: Path | None = None) -> str:
    return (
        "anunnaki: utu/1\n"
        f"goal_model: {goals or ROVER / 'goals.yaml'}\n"
        f"binding: {ROVER / 'binding.yaml'}\n"
        f"tactics: {ROVER / 'tactics.xml'}\n"
        f"knowledge: {db}\n"
        "warmup: 2.0\n"
        "failsafe: fail-safe\n"
        "run_stop: {service: /rover/stop}\n"
    )


def record(db: Path, goals: Path | None = None) -> Path:
    """Record the rover example on an in-process bus, one step per trace instant."""
    cfg = parse_config(config(db, goals))
    with open_bus("inproc") as bus, Rover(bus, ROVER / "trace.jsonl") as scripted:
        actuator = CountingActuator(bus)
        manager = AutonomicManager.from_config(cfg, bus=bus, actuator=actuator)
        try:
            for t in scripted.instants():
                scripted.step(t)
                before = actuator.buzzes
                manager.step(t)
                for _ in range(actuator.buzzes - before):
                    assert scripted.heard.acquire(timeout=10.0), "the rover missed a command"
        finally:
            manager.close()
    return db


@pytest.fixture(scope="module")
def run_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return record(tmp_path_factory.mktemp("log") / "run.db")


@pytest.fixture(scope="module")
def stop_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A run whose goal model lacks the manual branch: the fail-safe fails, run-stop."""
    folder = tmp_path_factory.mktemp("stop")
    text = (ROVER / "goals.yaml").read_text(encoding="utf-8")
    text = text.replace("children: [G4, G11]", "children: [G4]")
    text, n = re.subn(r"  - id: G11\n(?:    .*\n)+\n", "", text)
    assert n == 1
    goals = folder / "goals.yaml"
    goals.write_text(text, encoding="utf-8")
    return record(folder / "run.db", goals)


def cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def rows(out: str) -> list[list[str]]:
    """The table rows of plain output: lines that start with a time."""
    result = []
    for line in out.splitlines():
        parts = line.split()
        if parts and "." in parts[0] and parts[0].replace(".", "", 1).isdigit():
            result.append(parts)
    return result


# -- anunnaki log --------------------------------------------------------------------------------
def test_log_prints_the_decisions_as_a_plain_table_when_piped(
    run_db: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = cli(capsys, "log", str(run_db))
    assert code == 0
    assert ESC not in out
    assert out.splitlines()[0].startswith(f"{run_db}: ")
    assert "t (s)" in out and "details" in out
    table = rows(out)
    assert table[1][:3] == ["25.000", "started", "fail-safe"]
    assert any(r[:3] == ["25.500", "postcondition_ok", "fail-safe"] for r in table)
    assert all(line == line.rstrip() for line in out.splitlines())
    with Knowledge(run_db) as k:
        assert len(table) == len(k.decisions())


def test_log_colours_failures_escalations_and_run_stop_on_a_terminal(
    stop_db: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("FORCE_COLOR", "1")
    monkeypatch.delenv("NO_COLOR", raising=False)
    code, out, _ = cli(capsys, "log", str(stop_db), "--kind", "postcondition_failed,run_stop")
    assert code == 0
    lines = [line for line in out.splitlines() if "run_stop" in line or "postcondition" in line]
    assert len(lines) == 2
    assert all(ESC in line for line in lines)
    code, out, _ = cli(capsys, "log", str(stop_db))
    assert ESC in next(line for line in out.splitlines() if "escalated" in line)


def test_log_filters(run_db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _, out, _ = cli(capsys, "log", str(run_db), "--tactic", "fail-safe")
    assert rows(out)
    assert all(r[2] == "fail-safe" or "to=fail-safe" in r for r in rows(out))
    assert "of" in out.splitlines()[-1]  # "N of M decisions shown"
    _, out, _ = cli(capsys, "log", str(run_db), "--kind", "started", "--kind", "selected")
    assert {r[1] for r in rows(out)} == {"started", "selected"}
    _, out, _ = cli(capsys, "log", str(run_db), "--since", "25.2", "--until", "30")
    assert [r[:2] for r in rows(out)] == [["25.500", "postcondition_ok"]]
    _, out, _ = cli(capsys, "log", str(run_db), "--until", "1")
    assert "no decisions match" in out


def test_log_refuses_an_unknown_kind(run_db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = cli(capsys, "log", str(run_db), "--kind", "startd")
    assert code == 2
    assert "startd" in err and "started" in err


def test_log_interleaves_verdicts(run_db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _, out, _ = cli(capsys, "log", str(run_db), "--verdicts", "--since", "25", "--until", "25")
    table = rows(out)
    kinds = [r[1] for r in table]
    assert "verdict" in kinds and "started" in kinds
    assert kinds.index("verdict") < kinds.index("selected")  # the verdicts led to it
    o1 = next(r for r in table if r[1] == "verdict" and r[2] == "O1")
    assert o1[3] == "satisfied"


def test_log_json(run_db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = cli(capsys, "log", str(run_db), "--json", "--verdicts", "--until", "25")
    assert code == 0
    objs = [json.loads(line) for line in out.splitlines()]
    assert {o["type"] for o in objs} == {"decision", "verdict"}
    started = next(o for o in objs if o.get("kind") == "started")
    assert started["tactic"] == "fail-safe" and started["data"]["deadline"] == 30.0
    assert [o["t"] for o in objs] == sorted(o["t"] for o in objs)


# -- export round trip ---------------------------------------------------------------------------
def transitions(seq: list[tuple[float, str, float | None]]) -> list[tuple[float, str, Any]]:
    """Drop entries that repeat the previous state of the node."""
    out: list[tuple[float, str, Any]] = []
    for t, status, utility in seq:
        u = None if utility is None else round(utility, 9)
        if out and out[-1][1:] == (status, u):
            continue
        out.append((t, status, u))
    return out


def test_exported_trace_evaluates_to_the_recorded_verdicts(
    run_db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run.jsonl"
    code, text, _ = cli(capsys, "log", str(run_db), "--export-trace", str(out))
    assert code == 0 and "wrote 718 messages" in text and "anunnaki evaluate" in text
    out.write_text("mine\n")  # an existing file is not overwritten without --force
    code, _, err = cli(capsys, "log", str(run_db), "--export-trace", str(out))
    assert code == 2 and f"{out} exists already" in err and "--force" in err
    assert out.read_text() == "mine\n"
    code, text, _ = cli(capsys, "log", str(run_db), "--export-trace", str(out), "--force")
    assert code == 0 and "wrote 718 messages" in text
    code, text, _ = cli(
        capsys,
        "evaluate",
        str(ROVER / "goals.yaml"),
        "--binding",
        str(ROVER / "binding.yaml"),
        "--trace",
        str(out),
        "--json",
        "--delta",
        "0",
    )
    assert code == 0
    replayed: dict[str, list[tuple[float, str, float | None]]] = {}
    for line in text.splitlines():
        obj = json.loads(line)
        for c in obj.get("changed", []):
            replayed.setdefault(c["node"], []).append((obj["t"], c["to"], c["utility"]))
    recorded: dict[str, list[tuple[float, str, float | None]]] = {}
    with Knowledge(run_db) as k:
        for v in k.verdicts():
            recorded.setdefault(v.node, []).append((v.t, v.status, v.utility))
    assert recorded.keys() == replayed.keys()
    for node, seq in recorded.items():
        assert transitions(replayed[node]) == transitions(seq), node
    assert transitions(recorded["O1"])[-1][:2] == (25.0, "satisfied")


# -- anunnaki explain ----------------------------------------------------------------------------
def test_explain_shows_the_tree_the_reason_and_the_decisions(
    stop_db: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = cli(capsys, "explain", str(stop_db), "--at", "30", "--goal", "G3")
    assert code == 0
    assert "as of the manager's step at t = 30.000 s" in out
    assert "G3 unsatisfied" in out and "⊘ O1 holds" in out  # the tree
    assert "why G3 is unsatisfied:" in out
    assert "A4.category >= 1 with A4.category = 1" in out  # the deciding leaf value
    assert "A4.category=1" in out
    assert "agrees with the recorded verdicts" in out
    decided = [r for r in rows(out.replace("▶", "")) if r[0] == "30.000"]
    assert [r[1] for r in decided] == ["postcondition_failed", "escalated", "run_stop"]


def test_explain_defaults_to_the_root(run_db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = cli(capsys, "explain", str(run_db), "--at", "27", "--window", "0")
    assert code == 0
    assert "why G1 is satisfied:" in out
    assert "no decisions from t = 27.000 to 27.000 s" in out


def test_explain_json(run_db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = cli(capsys, "explain", str(run_db), "--at", "25", "--json")
    assert code == 0
    obj = json.loads(out)
    assert obj["nodes"]["O1"] == {"utility": 1.0, "status": "satisfied"}
    assert obj["explanation"]["node"] == "G1"
    assert obj["agrees_with_record"] is True
    assert any(d["kind"] == "started" for d in obj["decisions"])


def test_explain_an_unknown_goal(run_db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = cli(capsys, "explain", str(run_db), "--at", "25", "--goal", "G99")
    assert code == 2 and "G99" in err and "G1" in err


# -- one time base per log ----------------------------------------------------------------------
EPOCH = 1_795_749_868.136  # a wall-clock run: Utu's times are seconds since the epoch


@pytest.fixture(scope="module")
def wall_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The rover on the wall clock: inputs stamped as they arrive, each step 0.4 ms later."""
    db = tmp_path_factory.mktemp("wall") / "run.db"
    manager = AutonomicManager.from_config(parse_config(config(db)), actuator=RecordingActuator())
    try:
        for t, records in groupby(read_trace(ROVER / "trace.jsonl").records, lambda r: r.t):
            for r in records:
                manager.feed(r.topic, r.msg, t=EPOCH + t)
            manager.step(EPOCH + t + 0.0004)
    finally:
        manager.close()
    return db


def test_a_wall_clock_log_reads_in_seconds_from_the_start(
    wall_db: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Before: epoch times in ``log`` (deadlines too) and ``explain --at 25`` found no step."""
    code, out, _ = cli(capsys, "log", str(wall_db))
    assert code == 0 and "from t = 0.000 to 49.800 s after the start (2026-11-27" in out
    assert [(r[0], r[1]) for r in rows(out) if r[1] in ("started", "run_stop")] == [
        ("25.000", "started"),
        ("30.000", "run_stop"),  # the rover here never switched: the fail-safe failed
    ]
    assert "deadline=30 " in out  # on the same base as t
    code, out, _ = cli(capsys, "log", str(wall_db), "--since", "26", "--json")
    assert (
        code == 0 and [round(json.loads(line)["t"], 3) for line in out.splitlines()] == [30.0] * 3
    )
    code, out, _ = cli(capsys, "replay", str(wall_db), "--json")
    report = json.loads(out)
    assert report["identical"] and report["origin"] == pytest.approx(EPOCH)
    kb = Knowledge(str(wall_db))  # what 'anunnaki run' prints as the run goes
    started = next(d for d in kb.decisions() if d.kind == "started")
    line = format_decision(started, t0=kb.time_origin())
    kb.close()
    assert line.split()[:2] == ["25.000", "started"] and "deadline=30.0 " in line


def test_explain_at_a_printed_decision_time_explains_that_decision(
    wall_db: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Before: at its own printed time a decision's step (0.4 ms later) was left out, its
    inputs taken anyway, and the rebuilt state differed from the recorded verdicts."""
    code, out, _ = cli(capsys, "log", str(wall_db))
    printed = sorted({r[0] for r in rows(out)})
    assert printed == ["25.000", "30.000"]
    for at in printed:
        code, out, _ = cli(capsys, "explain", str(wall_db), "--at", at, "--json")
        obj = json.loads(out)
        assert code == 0 and f"{obj['as_of']:.3f}" == at, at
        assert obj["agrees_with_record"] is True, (at, obj["disagreements"])
        assert {d["kind"] for d in obj["decisions"] if f"{d['t']:.3f}" == at}
    code, out, _ = cli(capsys, "explain", str(wall_db), "--at", "25")
    assert "as of the manager's step at t = 25.000 s" in out
    assert "agrees with the recorded verdicts" in out
    assert [r[1] for r in rows(out.replace("▶", "")) if r[0] == "25.000"][:2] == [
        "selected",
        "started",
    ]


# -- anunnaki replay -----------------------------------------------------------------------------
def test_replay_identical(run_db: Path, stop_db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for db in (run_db, stop_db):
        code, out, _ = cli(capsys, "replay", str(db))
        assert code == 0
        assert "identical (" in out and "decisions" in out


def test_replay_diverged(run_db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = tmp_path / "altered.db"
    shutil.copyfile(run_db, db)
    with sqlite3.connect(db) as con:
        con.execute(
            "UPDATE inputs SET msg=json_set(msg, '$.category', 0) "
            "WHERE topic='/utu/oracle/output' AND t>=25.0"
        )
    con.close()
    code, out, _ = cli(capsys, "replay", str(db))
    assert code == 1
    assert "diverged at decision #0 (t = 25.000 s)" in out
    assert "started fail-safe" in out
    code, out, _ = cli(capsys, "replay", str(db), "--json")
    assert code == 1
    report = json.loads(out)
    assert report["identical"] is False and report["divergence"]["t"] == 25.0


def test_replay_what_if(run_db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = cli(capsys, "replay", str(run_db), "--warmup", "0")
    assert code == 1 and "what if: warmup=0" in out


# -- robustness ----------------------------------------------------------------------------------
@pytest.mark.parametrize("command", ["log", "replay", "explain"])
def test_missing_and_corrupt_files_exit_2_naming_the_file(
    command: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    extra = ["--at", "1"] if command == "explain" else []
    missing = tmp_path / "missing.db"
    code, _, err = cli(capsys, command, str(missing), *extra)
    assert code == 2 and str(missing) in err and "no such file" in err
    corrupt = tmp_path / "corrupt.db"
    corrupt.write_bytes(b"\x00garbage" * 1000)
    code, _, err = cli(capsys, command, str(corrupt), *extra)
    assert code == 2 and str(corrupt) in err
    assert "Traceback" not in err


def test_a_corrupt_row_exits_2(
    run_db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = tmp_path / "row.db"
    shutil.copyfile(run_db, db)
    with sqlite3.connect(db) as con:
        con.execute("UPDATE decisions SET data='{' WHERE id=1")
    con.close()
    code, _, err = cli(capsys, "log", str(db))
    assert code == 2 and str(db) in err and "corrupt" in err


def test_an_empty_run_says_so(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = tmp_path / "empty.db"
    AutonomicManager.from_config(parse_config(config(db))).close()
    for argv in (["log"], ["replay"], ["explain", "--at", "3"]):
        code, out, _ = cli(capsys, argv[0], str(db), *argv[1:])
        assert code == 0, argv
        assert "empty run" in out, argv
    out_trace = tmp_path / "empty.jsonl"
    code, out, _ = cli(capsys, "log", str(db), "--export-trace", str(out_trace))
    assert code == 0 and "empty run: wrote no messages" in out


# -- docs/decision-log.md says what the code does ------------------------------------------------
DOC = (Path(__file__).resolve().parents[2] / "docs" / "decision-log.md").read_text(encoding="utf-8")


def test_the_doc_lists_every_kind_of_decision() -> None:
    from anunnaki.utu.runlog import KINDS

    table = DOC[DOC.index("### Kinds of decisions") : DOC.index("## `anunnaki log`")]
    documented = {
        k
        for cell in re.findall(r"^\| ([^|]+) \|", table, re.M)
        for k in re.findall(r"`(\w+)`", cell)
    }
    assert documented == set(KINDS)


@pytest.mark.parametrize(
    "command",
    [
        "anunnaki log rover-no-manual.db",
        "anunnaki explain rover-no-manual.db --at 30 --goal G3 --window 0.5",
    ],
)
def test_the_doc_excerpts_are_real_output(
    command: str,
    stop_db: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    block = next(
        b
        for b in re.findall(r"^```console\n(.*?)^```", DOC, re.M | re.S)
        if b.startswith(f"$ {command}\n")
    )
    expected = block.splitlines()[1:]
    shutil.copyfile(stop_db, tmp_path / "rover-no-manual.db")
    monkeypatch.chdir(tmp_path)
    code, out, _ = cli(capsys, *command.split()[1:])
    assert code == 0
    assert out.splitlines() == expected
