"""Replay of a recorded run: identical when nothing changed, the first divergence when it did.

Runs are recorded deterministically: the scripted rover publishes the example trace on an
in-process bus and the manager steps at each of its instants (no clock, no sleeps).
"""

from __future__ import annotations

import json
import re
import shutil
import sqlite3
import threading
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import pytest
from helpers_procs import wait_until

from anunnaki.bus import open_bus
from anunnaki.clock import ManualClock
from anunnaki.errors import AnunnakiError
from anunnaki.managed import ScriptedSystem
from anunnaki.messages import RunStop
from anunnaki.topics import UTU_NODES
from anunnaki.trace import read_trace
from anunnaki.utu import (
    ActionOutcome,
    AutonomicManager,
    BusActuator,
    Knowledge,
    UtuNode,
    build_node,
    parse_config,
)
from anunnaki.utu._replay import decisive
from anunnaki.utu.host import AnalyzeNode, step_nodes
from anunnaki.utu.runlog import (
    KINDS,
    RunLogError,
    export_trace,
    open_run,
    rebuild_goal_state,
    replay,
    run_models,
)

ROVER = Path(__file__).resolve().parents[2] / "examples" / "rover"
SETTINGS = {
    "dwell": 0.0,
    "warmup": 2.0,
    "failsafe": "fail-safe",
    "escalate_to_run_stop": True,
    "run_stop_service": "/rover/stop",
}


class Rover(ScriptedSystem):
    """The scripted rover, telling the test when it has taken a buzzer command.

    It takes commands on a subscriber thread; the recording waits for each one before the
    next instant, so a run records the same inputs however loaded the machine is.
    """

    def __init__(self, bus: Any, trace: Path, **kw: Any) -> None:
        self.heard = threading.Semaphore(0)
        super().__init__(bus, trace, **kw)

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


def config(db: Path, goals: Path | None = None, tactics: Path | None = None) -> str:
    return (
        "anunnaki: utu/1\n"
        "name: rover\n"
        f"goal_model: {goals or ROVER / 'goals.yaml'}\n"
        f"binding: {ROVER / 'binding.yaml'}\n"
        f"tactics: {tactics or ROVER / 'tactics.xml'}\n"
        f"knowledge: {db}\n"
        "warmup: 2.0\n"
        "failsafe: fail-safe\n"
        "run_stop: {service: /rover/stop}\n"
    )


def record_rover(db: Path, goals: Path | None = None, **rover: Any) -> Path:
    """Record the rover example: scripted system on an in-process bus, stepped per instant."""
    cfg = parse_config(config(db, goals))
    with open_bus("inproc") as bus, Rover(bus, ROVER / "trace.jsonl", **rover) as scripted:
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


def goals_without_manual(folder: Path) -> Path:
    """The rover goal model with G11 (manual operation) removed: G3 has only G4."""
    text = (ROVER / "goals.yaml").read_text(encoding="utf-8")
    text = text.replace("children: [G4, G11]", "children: [G4]")
    text, n = re.subn(r"  - id: G11\n(?:    .*\n)+\n", "", text)
    assert n == 1
    path = folder / "goals-no-manual.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def decisions(db: Path) -> list[tuple[float, str, str | None]]:
    with Knowledge(db) as k:
        return [(d.t, d.kind, d.tactic) for d in k.decisions()]


@pytest.fixture(scope="module")
def rover_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return record_rover(tmp_path_factory.mktemp("rover") / "run.db")


@pytest.fixture(scope="module")
def stop_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("stop")
    return record_rover(folder / "run.db", goals_without_manual(folder))


@pytest.fixture
def rover_copy(rover_run: Path, tmp_path: Path) -> Iterator[Path]:
    copy = tmp_path / "copy.db"
    shutil.copyfile(rover_run, copy)
    yield copy


# -- the recorded runs themselves ------------------------------------------------------------
def test_the_rover_run_fires_the_failsafe_at_the_category_1_phase(rover_run: Path) -> None:
    made = decisions(rover_run)
    assert (25.0, "selected", "fail-safe") in made
    assert (25.0, "started", "fail-safe") in made
    assert (25.5, "postcondition_ok", "fail-safe") in made
    assert all(kind in KINDS for _, kind, _ in made)


def test_the_manager_records_its_policy_settings(rover_run: Path) -> None:
    with Knowledge(rover_run) as k:
        assert k.meta("settings") == SETTINGS


def test_without_the_manual_branch_the_failsafe_fails_and_escalates(stop_run: Path) -> None:
    made = decisions(stop_run)
    assert (30.0, "postcondition_failed", "fail-safe") in made
    assert (30.0, "escalated", "fail-safe") in made
    assert (30.0, "run_stop", None) in made
    with Knowledge(stop_run) as k:
        esc = next(d for d in k.decisions() if d.kind == "escalated")
        assert esc.data == {"to": "run-stop"}


def test_a_refused_action_fails_its_tactic_and_replays_identically(tmp_path: Path) -> None:
    """The rover refuses manual mode: action_failed and a run-stop at once, replayed alike."""
    run = record_rover(tmp_path / "refused.db", modes=("autonomous",))
    made = decisions(run)
    assert made.index((25.0, "action_failed", "fail-safe")) < made.index((25.0, "run_stop", None))
    assert not any(kind == "postcondition_failed" for _, kind, _ in made)
    report = replay(run)
    assert report.identical, report.summary()


# -- replay --------------------------------------------------------------------------------------
def test_replay_of_the_rover_run_is_identical(rover_run: Path) -> None:
    report = replay(rover_run)
    assert report.identical, report.summary()
    assert report.exit_code == 0
    assert (
        report.summary() == f"identical ({report.decisions} decisions, {report.verdicts} verdicts)"
    )
    assert report.decisions == report.replayed_decisions >= 5
    assert report.verdicts == report.replayed_verdicts > 100
    assert report.settings == SETTINGS
    assert report.notes == ()


def test_replay_of_the_run_stop_run_is_identical(stop_run: Path) -> None:
    report = replay(stop_run)
    assert report.identical, report.summary()
    assert report.decisions >= 7


def test_altering_one_input_makes_the_replay_diverge_there(rover_copy: Path) -> None:
    with sqlite3.connect(rover_copy) as con:
        row = con.execute(
            "SELECT id, msg FROM inputs WHERE topic='/utu/oracle/output' AND t=25.0"
        ).fetchone()
        msg = json.loads(row[1])
        assert msg["category"] == 1
        msg["category"] = 0
        con.execute("UPDATE inputs SET msg=? WHERE id=?", (json.dumps(msg), row[0]))
    con.close()
    report = replay(rover_copy)
    assert not report.identical and report.exit_code == 1
    d = report.divergence
    assert d is not None
    assert d.t == 25.0
    assert d.expected is not None and d.expected["kind"] == "selected"
    assert d.expected["tactic"] == "fail-safe"
    assert any(m.startswith("started fail-safe") for m in d.missing), d.missing
    assert d.extra == ()
    assert report.summary() == "diverged at decision #0 (t = 25.000 s)"
    assert "started fail-safe" in d.render()
    assert report.verdict_divergence is not None and report.verdict_divergence.t == 25.0


def test_a_degraded_oracle_that_never_reports_means_no_failsafe(rover_copy: Path) -> None:
    with sqlite3.connect(rover_copy) as con:
        n = con.execute(
            "UPDATE inputs SET msg=json_set(msg, '$.category', 0) "
            "WHERE topic='/utu/oracle/output' AND t>=25.0"
        ).rowcount
        assert n > 10
    con.close()
    report = replay(rover_copy)
    d = report.divergence
    assert d is not None and d.t == 25.0
    assert {m.split(" (")[0] for m in d.missing} >= {
        "selected fail-safe",
        "started fail-safe",
        "action fail-safe",
    }
    assert report.replayed_decisions < report.decisions


def test_replay_never_reads_the_recorded_decisions(rover_copy: Path) -> None:
    with sqlite3.connect(rover_copy) as con:
        con.execute("DELETE FROM decisions")
        con.execute("DELETE FROM tactics")
    con.close()
    report = replay(rover_copy)
    assert report.decisions == 0
    assert report.replayed_decisions >= 5  # it decided all the same
    d = report.divergence
    assert d is not None and d.index == 0 and d.expected is None
    assert d.got is not None and d.got["kind"] == "selected" and d.t == 25.0
    assert report.verdict_divergence is None


def test_an_actions_outcome_is_replayed_and_its_detail_is_not_decisive(rover_copy: Path) -> None:
    with sqlite3.connect(rover_copy) as con:
        con.execute("UPDATE decisions SET data=json_set(data, '$.detail', 'x') WHERE kind='action'")
    con.close()
    assert replay(rover_copy).identical  # what the system said is not a choice of the loop
    assert decisive("action", {"ok": False, "detail": "x", "index": 0}) == {"index": 0}
    assert decisive("started", {"deadline": 30.0}) == {"deadline": 30.0}
    with sqlite3.connect(rover_copy) as con:  # a failed action escalates: the replay fails it
        con.execute("UPDATE decisions SET data=json_set(data, '$.ok', json('false'))")
    con.close()
    report = replay(rover_copy)
    assert not report.identical  # the log says ok but recorded no action_failed: altered


def test_floats_are_compared_with_a_tolerance(rover_copy: Path) -> None:
    with sqlite3.connect(rover_copy) as con:
        con.execute("UPDATE verdicts SET utility = utility + 1e-9 WHERE utility IS NOT NULL")
    con.close()
    assert replay(rover_copy).identical
    report = replay(rover_copy, tolerance=0.0)
    assert report.verdict_divergence is not None


def test_missing_settings_are_noted_and_can_be_given(rover_copy: Path) -> None:
    with sqlite3.connect(rover_copy) as con:
        con.execute("DELETE FROM meta WHERE key='settings'")
    con.close()
    report = replay(rover_copy)
    assert any("did not record its policy settings" in n for n in report.notes)
    assert not report.identical  # warm-up 0: the unknown goals fire the fail-safe at t=0
    assert report.divergence is not None and report.divergence.t == 0.0
    fixed = replay(rover_copy, overrides={k: v for k, v in SETTINGS.items() if k != "dwell"})
    assert fixed.identical, fixed.summary()


def test_what_if_overrides_and_unknown_settings(rover_run: Path) -> None:
    report = replay(rover_run, overrides={"failsafe": None, "warmup": 0.0})
    assert report.settings["warmup"] == 0.0 and not report.identical
    with pytest.raises(AnunnakiError, match="unknown setting"):
        replay(rover_run, overrides={"speed": 2})


def run_past_the_trace(
    cfg: Any, at_instant: Callable[[AutonomicManager, float], None] | None = None
) -> list[Any]:
    """Step a manager at the rover trace's instants, then 6 s of time alone; the records.

    ``at_instant(manager, t)`` runs before each step (operator calls).
    """
    records = read_trace(ROVER / "trace.jsonl").records
    manager = AutonomicManager.from_config(cfg)
    try:
        instants = sorted({r.t for r in records} | {50.0 + k / 10 for k in range(60)})
        i = 0
        for t in instants:
            while i < len(records) and records[i].t <= t:
                manager.feed(records[i].topic, records[i].msg)
                i += 1
            if at_instant is not None:
                at_instant(manager, t)
            manager.step(t)
    finally:
        manager.close()
    return list(records)


def test_operator_calls_and_time_only_steps_replay_identically(tmp_path: Path) -> None:
    """No bus: inputs fed directly; approval, pause, resume, liveliness and run-stop calls."""
    tactics = tmp_path / "tactics.xml"
    text = (ROVER / "tactics.xml").read_text(encoding="utf-8")
    tactics.write_text(text.replace('requires_approval="false"', 'requires_approval="true"'))
    db = tmp_path / "ops.db"

    def operator(manager: AutonomicManager, t: float) -> None:
        if t == 26.0:
            manager.approve("fail-safe", caller="alice")
            manager.approve("no-such-tactic", caller="bob")
        if t == 30.0:
            manager.pause("alice")
        if t == 32.0:
            manager.resume("alice")
        if t == 40.0:
            manager.desk.enqueue({"op": "node_lost", "node": "/oracle", "caller": "liveliness"})
        if t == 52.0:
            manager.run_stop(caller="alice", reason="end of the test")

    records = run_past_the_trace(parse_config(config(db, tactics=tactics)), operator)
    made = decisions(db)
    kinds = {k for _, k, _ in made}
    assert {"pending_approval", "approved", "operator_refused", "paused"} <= kinds
    assert {"resumed_adaptation", "liveliness_lost", "run_stop"} <= kinds
    with Knowledge(db) as k:
        ticks = [r.t for r in k.inputs(since=50.0) if r.topic == "__tick__"]
    assert ticks, "time alone changed something after the trace ended"
    report = replay(db)
    assert report.identical, report.summary()
    assert report.inputs > 0 and report.steps > len({r.t for r in records})


def test_a_log_that_ends_mid_step_is_finished(rover_copy: Path) -> None:
    with sqlite3.connect(rover_copy) as con:
        last = con.execute("SELECT MAX(id) FROM inputs").fetchone()[0]
        con.execute("DELETE FROM inputs WHERE id=?", (last,))  # the last __tick__
    con.close()
    report = replay(rover_copy)
    assert report.identical
    assert any("ends mid-step" in n for n in report.notes)


def test_a_log_cut_after_a_steps_analysis_replays_that_analysis(rover_copy: Path) -> None:
    # A copy taken (or a kill) after a step's verdicts were written and before its end
    # marker: the replay analyses that step as far as the run went (it left it, and its
    # verdicts diverged: a by-hand node test's snapshot hit this).
    with sqlite3.connect(rover_copy) as con:
        tick_id, at = next(
            (i, t)
            for i, t in con.execute(
                "SELECT id, t FROM inputs WHERE topic='__tick__' AND t > 5 ORDER BY id"
            )
            if con.execute("SELECT COUNT(*) FROM verdicts WHERE t=?", (t,)).fetchone()[0]
            and not con.execute("SELECT COUNT(*) FROM decisions WHERE t=?", (t,)).fetchone()[0]
        )
        con.execute("DELETE FROM inputs WHERE id>=?", (tick_id,))
        con.execute("DELETE FROM verdicts WHERE t>?", (at,))
        con.execute("DELETE FROM decisions WHERE t>?", (at,))
    con.close()
    report = replay(rover_copy)
    assert report.identical, report.summary()
    assert any("finished that step as far as the run went" in n for n in report.notes)


def test_a_log_cut_after_a_time_only_analysis_replays_that_analysis(tmp_path: Path) -> None:
    # Issue 21: plan killed at trace time 34.6, the launch stopped the rest; the analyze node
    # had recorded a verdict at 34.792 in a cycle of time alone (no input) whose end marker
    # never came (execute never answered). No input followed the last marker, so the replay
    # saw no step cut short, left the verdict out and diverged.
    db = tmp_path / "cut.db"
    records = run_past_the_trace(parse_config(config(db)))
    last_record = max(r.t for r in records)
    with sqlite3.connect(db) as con:
        tick_id, at = next(
            (i, t)
            for i, t in con.execute(
                "SELECT id, t FROM inputs WHERE topic='__tick__' AND t > ? ORDER BY id",
                (last_record,),
            )
            if con.execute("SELECT COUNT(*) FROM verdicts WHERE t=?", (t,)).fetchone()[0]
            and not con.execute("SELECT COUNT(*) FROM decisions WHERE t=?", (t,)).fetchone()[0]
        )
        assert not con.execute(  # a step of time alone: no input since the marker before it
            "SELECT COUNT(*) FROM inputs WHERE topic NOT LIKE '\\_\\_%' ESCAPE '\\' AND t > ?",
            (last_record,),
        ).fetchone()[0]
        con.execute("DELETE FROM inputs WHERE id>=?", (tick_id,))
        con.execute("DELETE FROM verdicts WHERE t>?", (at,))
        con.execute("DELETE FROM decisions WHERE t>?", (at,))
    con.close()
    report = replay(db)
    assert report.identical, report.summary()
    cut = f"a cycle of time alone at t = {at - report.origin:.3f} s"
    assert any(cut in n for n in report.notes), report.notes


# -- the goal model at an instant --------------------------------------------------------------
@pytest.mark.parametrize("at", [0.0, 1.05, 10.0, 20.3, 25.0, 27.0, 45.9, 47.0, 49.8, 60.0])
def test_the_rebuilt_goal_state_agrees_with_the_recorded_verdicts(
    rover_run: Path, at: float
) -> None:
    with open_run(rover_run) as k:
        state = rebuild_goal_state(k, rover_run, at)
    assert state.disagreements() == []
    assert state.as_of is not None and state.as_of <= at


def test_the_rebuilt_state_at_the_category_1_phase(rover_run: Path, stop_run: Path) -> None:
    with open_run(rover_run) as k:
        state = rebuild_goal_state(k, rover_run, 27.0)
    ev = state.evaluator
    assert ev.state("O1").status is True
    assert ev.state("G4").status is False
    assert ev.state("G3").status is True  # through G11: the fail-safe switched to manual
    assert "A1.mode" in ev.explain("G3").leaves
    with open_run(stop_run) as k:
        state = rebuild_goal_state(k, stop_run, 30.0)
    assert state.evaluator.state("G3").status is False
    assert state.evaluator.explain("G3").leaves["A4.category"] == 1


def test_the_rebuilt_state_comes_from_inputs_not_verdicts(rover_copy: Path) -> None:
    with sqlite3.connect(rover_copy) as con:
        con.execute("DELETE FROM verdicts")
    con.close()
    with open_run(rover_copy) as k:
        state = rebuild_goal_state(k, rover_copy, 27.0)
    assert state.evaluator.state("O1").status is True
    assert state.recorded == {}


def test_before_the_first_step_nothing_is_known(rover_run: Path) -> None:
    with open_run(rover_run) as k:
        state = rebuild_goal_state(k, rover_run, -1.0)
    assert state.as_of is None and state.inputs == 0
    assert state.evaluator.root.status is None


# -- export --------------------------------------------------------------------------------------
def test_export_writes_the_messages_without_markers(rover_run: Path, tmp_path: Path) -> None:
    out = tmp_path / "out.jsonl"
    with open_run(rover_run) as k:
        n = export_trace(k, out, header={"name": "x"})
    trace = read_trace(out)
    assert trace.header["name"] == "x"
    assert len(trace.records) == n
    assert not trace.phases
    assert {r.topic for r in trace.records} == {
        "/rover/status",
        "/rover/camera/info",
        "/rover/ultrasonic",
        "/utu/oracle/output",
    }
    original = read_trace(ROVER / "trace.jsonl").records
    assert [(r.t, r.topic) for r in trace.records] == [(r.t, r.topic) for r in original]
    with open_run(rover_run) as k:
        part = export_trace(k, tmp_path / "part.jsonl", since=20.0, until=25.0)
    assert 0 < part < n
    assert all(20.0 <= r.t <= 25.0 for r in read_trace(tmp_path / "part.jsonl").records)


def test_export_marks_time_only_steps_on_request(rover_run: Path, tmp_path: Path) -> None:
    db = tmp_path / "ticks.db"
    shutil.copyfile(rover_run, db)
    with sqlite3.connect(db) as con:  # a step after the trace in which only time passed
        con.execute("INSERT INTO inputs (t, topic, msg) VALUES (55.0, '__tick__', '{}')")
    con.close()
    with open_run(db) as k:
        export_trace(k, tmp_path / "a.jsonl")
        export_trace(k, tmp_path / "b.jsonl", mark_ticks=True)
    assert read_trace(tmp_path / "a.jsonl").phases == []
    phases = read_trace(tmp_path / "b.jsonl").phases
    assert [p.t for p in phases] == [55.0]


# -- robustness ----------------------------------------------------------------------------------
def test_a_missing_file_is_named(tmp_path: Path) -> None:
    missing = tmp_path / "nope.db"
    with pytest.raises(RunLogError, match=r"nope\.db: no such file"):
        replay(missing)
    assert not missing.exists()  # not created by looking


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"this is not a database at all, just text" * 100, "unreadable database"),
        (b"", "not an Anunnaki decision log"),
    ],
)
def test_a_corrupt_file_is_named(tmp_path: Path, content: bytes, message: str) -> None:
    bad = tmp_path / "bad.db"
    bad.write_bytes(content)
    with pytest.raises(RunLogError, match=message) as info:
        replay(bad)
    assert str(bad) in str(info.value)
    assert bad.read_bytes() == content  # untouched


def test_a_foreign_sqlite_database_is_refused_untouched(tmp_path: Path) -> None:
    other = tmp_path / "other.db"
    with sqlite3.connect(other) as con:
        con.execute("CREATE TABLE x (a)")
    con.close()
    with pytest.raises(RunLogError, match="no table 'decisions'"):
        open_run(other)
    with sqlite3.connect(other) as con:
        tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master")}
    con.close()
    assert tables == {"x"}


def test_a_corrupt_record_is_an_error_naming_the_file(rover_copy: Path) -> None:
    with sqlite3.connect(rover_copy) as con:
        con.execute("UPDATE inputs SET msg='{not json' WHERE id=5")
    con.close()
    with pytest.raises(RunLogError, match="corrupt record") as info:
        replay(rover_copy)
    assert str(rover_copy) in str(info.value)


def test_an_empty_run_says_so(tmp_path: Path) -> None:
    db = tmp_path / "empty.db"
    AutonomicManager.from_config(parse_config(config(db))).close()
    report = replay(db)
    assert report.identical and report.empty
    assert "empty run" in report.summary()
    assert run_models(db).initial.keys() == {"goal_model", "binding", "tactics"}


def test_a_run_without_model_texts_cannot_be_replayed(rover_copy: Path) -> None:
    with sqlite3.connect(rover_copy) as con:
        con.execute("DELETE FROM models")
    con.close()
    with pytest.raises(RunLogError, match="no goal-model text"):
        replay(rover_copy)


def test_a_reload_is_noted(rover_copy: Path) -> None:
    with sqlite3.connect(rover_copy) as con:
        con.execute(
            "INSERT INTO models (t, kind, path, text) "
            "SELECT 40.0, kind, path, text FROM models WHERE kind='tactics'"
        )
    con.close()
    assert run_models(rover_copy).reloads == (40.0,)
    report = replay(rover_copy)
    assert any("reloaded its models at t = 40.000" in n for n in report.notes)


def test_recording_is_deterministic(rover_run: Path, tmp_path: Path) -> None:
    again = record_rover(tmp_path / "again.db")
    with Knowledge(rover_run) as a, Knowledge(again) as b:
        assert [(d.t, d.kind, d.tactic) for d in a.decisions()] == [
            (d.t, d.kind, d.tactic) for d in b.decisions()
        ]
        assert a.verdicts() == b.verdicts()
        assert [(r.t, r.topic, r.msg) for r in a.inputs()] == [
            (r.t, r.topic, r.msg) for r in b.inputs()
        ]


def test_a_run_stop_that_execute_never_acted_on_is_not_acted_on_in_replay(
    tmp_path: Path,
) -> None:
    """Issue #12: a run-stop reached the monitor after the execute node had gone.

    The analyze node recorded the operator call and ended the step; nothing acted on it (the
    execute node was dead), so a replay must not either — it diverged (23 of 24 trials in
    the fault benchmark). The step's marker says that execute was gone.
    """
    db = tmp_path / "run.db"
    cfg = parse_config(config(db))
    kb = Knowledge(db)
    with open_bus("inproc") as bus, Rover(bus, ROVER / "trace.jsonl") as rover:
        nodes: dict[str, UtuNode] = {
            name: build_node(name, cfg, bus=bus, knowledge=kb, clock=ManualClock())
            for name in UTU_NODES
        }
        analyze = nodes["analyze"]
        assert isinstance(analyze, AnalyzeNode)
        try:
            alive = analyze.execute_up
            wait_until(alive, 10.0, "the analyze node to see execute up")  # watch's thread
            for t in rover.instants():
                if t > 27.0:
                    break
                rover.step(t)
                step_nodes(nodes, t)
            nodes.pop("execute").close()  # as kill -9 withdraws its token
            wait_until(lambda: not alive(), 10.0, "the analyze node to see execute gone")
            bus.publish("/utu/run_stop", RunStop(reason="node plan died", caller="launch:rover"))
            desk = nodes["monitor"].desk  # type: ignore[attr-defined]
            wait_until(lambda: desk.pending, 10.0, "the monitor to queue the run-stop")
            step_nodes(nodes, 27.05)
        finally:
            for node in nodes.values():
                node.close()
            rover.close()
    ticks = [r for r in kb.inputs() if r.topic == "__tick__" and r.t == 27.05]
    ops = [r for r in kb.inputs() if r.topic == "__operator__"]
    assert [r.msg for r in ticks] == [{"executed": False}]
    assert [r.msg["op"] for r in ops] == ["run_stop"]
    assert not [d for d in kb.decisions() if d.kind == "run_stop"]  # nobody acted on it
    kb.close()
    report = replay(db)
    assert report.identical, report.summary()
    assert report.replayed_decisions == report.decisions > 0
