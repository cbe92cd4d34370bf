"""The autonomic manager end to end on the in-process bus, driven by step(now)."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from anunnaki.bus import open_bus
from anunnaki.clock import ManualClock, SimClock, WallClock
from anunnaki.goals import load_binding, parse_goal_model
from anunnaki.managed import ScriptedSystem
from anunnaki.tactics import load_tactics, parse_tactics_yaml
from anunnaki.tokens import client_operator_token
from anunnaki.trace import Record
from anunnaki.utu import AutonomicManager, Knowledge, RecordingActuator, parse_config

ROVER = Path(__file__).parents[2] / "examples" / "rover"

#: A reload's reply waits for its service to read and check the tactics file against the goal
#: model (real parsing, tenths of a second of CPU); on a starved machine that took over the bus's
#: default 2 s once. The tests assert what the reply says, not how soon it comes.
RELOAD_TIMEOUT = 30.0


def rover_model(text: str | None = None):  # type: ignore[no-untyped-def]
    binding = load_binding(ROVER / "binding.yaml")
    return parse_goal_model(text or (ROVER / "goals.yaml").read_text(), binding=binding)


@pytest.fixture
def bus() -> Iterator[object]:
    with open_bus("inproc") as b:
        yield b


def run_rover(bus, model, *, until: float = 45.0, **kw):  # type: ignore[no-untyped-def]
    system = ScriptedSystem(bus, ROVER / "trace.jsonl")
    manager = AutonomicManager(
        model,
        load_tactics(ROVER / "tactics.xml"),
        bus=bus,
        failsafe="fail-safe",
        run_stop_service="/rover/stop",
        warmup=2.0,
        **kw,
    )
    for t in system.instants():
        if t > until:
            break
        system.step(t)
        manager.step(t)
    return system, manager


def kinds(
    manager: AutonomicManager, tactic: str | None = None
) -> list[tuple[float, str, str | None]]:
    return [
        (d.t, d.kind, d.tactic)
        for d in manager.knowledge.decisions()
        if tactic is None or d.tactic == tactic
    ]


def test_rover_fail_safe_end_to_end(bus) -> None:  # type: ignore[no-untyped-def]
    system, manager = run_rover(bus, rover_model())
    try:
        ev = manager.analyzer.evaluator
        fs = kinds(manager, "fail-safe")
        assert [k for _, k, _ in fs] == [
            "selected",
            "started",
            "action",
            "action",
            "postcondition_ok",
        ]
        assert fs[1][0] == 25.0  # started the moment A4.category turned 1
        assert system.state()["mode"] == "manual"
        assert system.commands[0][1:] == ("set_mode", {"mode": "manual"})
        # G3 and G1 satisfied again while the category stays 1: the postcondition held
        assert ev.value("A4.category") == 1
        assert ev.state("O1").status is True
        assert ev.state("G3").status is True
        assert ev.state("G1").status is True
        # the verdicts tell the story
        verdicts = [(v.t, v.node, v.status) for v in manager.knowledge.verdicts()]
        assert (25.0, "G3", "unsatisfied") in verdicts
        assert (25.0, "G1", "unsatisfied") in verdicts
        assert any(t > 25.0 and n == "G1" and s == "satisfied" for t, n, s in verdicts)
        # no other tactic had to act
        assert {tac for _, k, tac in kinds(manager) if k == "started"} == {"fail-safe"}
    finally:
        manager.close()
        system.close()


def test_without_the_manual_branch_the_postcondition_fails_and_escalates(bus) -> None:  # type: ignore[no-untyped-def]
    text = (ROVER / "goals.yaml").read_text().replace("children: [G4, G11]", "children: [G4]")
    system, manager = run_rover(bus, rover_model(text))
    try:
        decided = kinds(manager)
        fs = [k for _, k, tac in decided if tac == "fail-safe"]
        assert fs == [
            "selected",
            "started",
            "action",
            "action",
            "postcondition_failed",
            "escalated",
        ]
        failed = next(d for d in manager.knowledge.decisions() if d.kind == "postcondition_failed")
        assert failed.t == pytest.approx(30.0)  # deadline 5 s after the start at 25 s
        assert failed.data["goals"] == {"G3": "unsatisfied"}
        escalated = next(d for d in manager.knowledge.decisions() if d.kind == "escalated")
        assert escalated.data["to"] == "run-stop"  # no other tactic; the fail-safe itself failed
        run_stop = next(d for d in manager.knowledge.decisions() if d.kind == "run_stop")
        assert run_stop.data["caller"] == "escalation:fail-safe"
        assert system.state()["stopped"] is True
        assert manager.run_stopped
    finally:
        manager.close()
        system.close()


TACTICS = """\
anunnaki: tactics/1
tactics:
  - name: hand-over
    priority: 10
    cooldown: {cooldown}
    requires_approval: {approval}
    preconditions: [{{goal: G3, state: unsatisfied}}]
    actions: [{{type: change_mode, service: /rover/set_mode, mode: manual}}]
    postconditions: [{{goal: G3, state: satisfied}}]
    deadline: 2
  - name: beep
    priority: 50
    preconditions: [{{expression: "A4.category >= 1"}}]
    actions: [{{type: publish, topic: /rover/buzzer, payload: {{"on": true}}}}]
"""


def feed_nominal(
    m: AutonomicManager, t: float, category: int = 0, mode: str = "autonomous"
) -> None:
    m.feed("/rover/status", {"mode": mode, "buzzer": False, "bumper": False})
    m.feed("/rover/camera/info", {"seq": int(t * 10)})
    m.feed("/rover/ultrasonic", {"range": 3.0})
    m.feed("/utu/oracle/output", {"category": category, "confidence": 0.9})


def make(cooldown: float = 0.0, approval: bool = False, dwell: float = 0.0, **kw: object):  # type: ignore[no-untyped-def]
    tactics = parse_tactics_yaml(TACTICS.format(cooldown=cooldown, approval=str(approval).lower()))
    act = RecordingActuator()
    m = AutonomicManager(rover_model(), tactics, actuator=act, dwell=dwell, warmup=0.5, **kw)
    return m, act


def drive(
    m: AutonomicManager, times: list[float], category_at=lambda t: 0, mode_at=lambda t: "autonomous"
) -> None:  # type: ignore[no-untyped-def]
    for t in times:
        feed_nominal(m, t, category_at(t), mode_at(t))
        m.step(t)


def ticks(a: float, b: float, dt: float = 0.1) -> list[float]:
    n = round((b - a) / dt)
    return [round(a + i * dt, 6) for i in range(n + 1)]


def test_priority_order_and_expression_preconditions() -> None:
    m, act = make()
    drive(m, ticks(0, 1.0))
    drive(m, ticks(1.1, 1.5), category_at=lambda t: 1)
    started = [tac for _, k, tac in kinds(m) if k == "started"]
    assert started[:2] == ["beep", "hand-over"]  # priority 50 before 10
    assert act.calls[0] == ("publish", "/rover/buzzer", {"on": True})
    assert act.calls[1] == ("request", "/rover/set_mode", {"mode": "manual"})


def test_dwell_hysteresis_ignores_a_flickering_input() -> None:
    m, act = make(dwell=0.5)
    drive(m, ticks(0, 1.0))
    # category flickers 1/0 every 0.1 s: never holds for 0.5 s
    drive(m, ticks(1.1, 3.0), category_at=lambda t: round(t * 10) % 2)
    assert [k for _, k, _ in kinds(m) if k == "started"] == []
    assert act.calls == []
    # then it holds: the tactics start once, 0.5 s after it began holding
    drive(m, ticks(3.1, 4.0), category_at=lambda t: 1)
    starts = [(t, tac) for t, k, tac in kinds(m) if k == "started"]
    assert {tac for _, tac in starts} == {"beep", "hand-over"}
    assert all(t == pytest.approx(3.6) for t, _ in starts)


def test_cooldown_defers_a_repeat() -> None:
    m, _ = make(cooldown=10.0)
    drive(m, ticks(0, 1.0))
    drive(m, ticks(1.1, 1.2), category_at=lambda t: 1)  # hand-over starts at 1.1
    drive(m, ticks(1.3, 3.5), category_at=lambda t: 1)  # postcondition fails at 3.1
    handover = [(t, k) for t, k, tac in kinds(m, "hand-over")]
    assert (1.1, "started") in handover
    assert any(k == "postcondition_failed" for _, k in handover)
    drive(m, ticks(3.6, 4.0))
    drive(m, ticks(4.1, 4.3), category_at=lambda t: 1)  # eligible again within the cooldown
    deferred = [
        d for d in m.knowledge.decisions() if d.kind == "deferred" and d.tactic == "hand-over"
    ]
    assert deferred and deferred[-1].data["reason"].startswith("cooldown until")
    assert [k for _, k in handover].count("started") == 1


def test_requires_approval_waits_for_an_operator() -> None:
    m, act = make(approval=True)
    drive(m, ticks(0, 1.0))
    drive(m, ticks(1.1, 1.5), category_at=lambda t: 1)
    assert [k for _, k, _ in kinds(m, "hand-over")] == ["selected", "pending_approval"]
    assert m.planner.queue()[0] == {
        "tactic": "hand-over",
        "priority": 10,
        "state": "pending",
        "deadline": None,
    }
    # The state query carries the queue: a display that starts now sees the pending approval.
    assert m._query({"what": "state"})["queue"] == m.planner.queue()
    m.approve("hand-over", caller="operator-ana")
    drive(m, ticks(1.6, 1.6), category_at=lambda t: 1)
    approved = next(d for d in m.knowledge.decisions() if d.kind == "approved")
    assert approved.data["caller"] == "operator-ana"
    assert ("request", "/rover/set_mode", {"mode": "manual"}) in act.calls


def test_rejected_tactic_does_not_run_until_its_preconditions_recur() -> None:
    m, act = make(approval=True)
    drive(m, ticks(0, 1.0))
    drive(m, ticks(1.1, 1.2), category_at=lambda t: 1)
    m.approve("hand-over", approve=False, caller="operator-bo")
    drive(m, ticks(1.3, 2.0), category_at=lambda t: 1)
    assert ("request", "/rover/set_mode", {"mode": "manual"}) not in act.calls
    assert any(
        d.kind == "rejected" and d.data["caller"] == "operator-bo" for d in m.knowledge.decisions()
    )
    drive(m, ticks(2.1, 2.5))  # the condition clears ...
    drive(m, ticks(2.6, 2.7), category_at=lambda t: 1)  # ... and recurs: asked again
    assert [k for _, k, _ in kinds(m, "hand-over")].count("pending_approval") == 2


def test_pause_resume_and_run_stop_are_recorded_with_their_caller() -> None:
    m, _ = make()
    drive(m, ticks(0, 1.0))
    m.pause(caller="dashboard:ana")
    drive(m, ticks(1.1, 1.5), category_at=lambda t: 1)
    assert [k for _, k, _ in kinds(m) if k == "started"] == []
    m.resume(caller="dashboard:ana")
    drive(m, ticks(1.6, 1.7), category_at=lambda t: 1)
    assert {tac for _, k, tac in kinds(m) if k == "started"} == {"beep", "hand-over"}
    m.run_stop(caller="safety-officer", reason="test")
    drive(m, ticks(1.8, 1.8), category_at=lambda t: 1)
    rs = next(d for d in m.knowledge.decisions() if d.kind == "run_stop")
    assert rs.data["caller"] == "safety-officer"
    assert m.run_stopped and m.paused
    calls = [
        d.data.get("caller")
        for d in m.knowledge.decisions()
        if d.kind in ("paused", "resumed_adaptation")
    ]
    assert calls == ["dashboard:ana", "dashboard:ana"]


def test_operator_services_on_the_bus(bus) -> None:  # type: ignore[no-untyped-def]
    tactics = parse_tactics_yaml(TACTICS.format(cooldown=0, approval="true"))
    m = AutonomicManager(rover_model(), tactics, bus=bus, actuator=RecordingActuator())
    try:
        assert bus.request("/utu/ready", {}).to_body()["ready"] is True
        token = client_operator_token()  # Utu's own, as every client reads it
        reply = bus.request("/utu/pause", {"caller": "ops-console", "token": token}).to_body()
        assert reply == {"ok": True, "queued": "pause", "caller": "ops-console"}
        bad = bus.request("/utu/approve", {"caller": "x", "token": token}).to_body()
        assert bad["ok"] is False
        m.step(1.0)
        assert m.paused
        # run-stop announced by another node on the topic
        from anunnaki.messages import RunStop

        bus.publish("/utu/run_stop", RunStop(reason="e-stop pressed", caller="teleop-node"))
        deadline = time.monotonic() + 5
        while not m.desk.pending and time.monotonic() < deadline:
            time.sleep(0.005)
        m.step(2.0)
        rs = next(d for d in m.knowledge.decisions() if d.kind == "run_stop")
        assert rs.data["caller"] == "teleop-node"
        q = bus.request("/utu/knowledge/query", {"what": "decisions", "limit": 5}).to_body()
        assert q["ok"] and q["decisions"][-1]["kind"] == "run_stop"
    finally:
        m.close()


def test_hot_reload_swaps_valid_files_and_refuses_invalid_ones(tmp_path: Path) -> None:
    m, _ = make(reload_dirs=[tmp_path])
    drive(m, ticks(0, 1.0))
    bad = tmp_path / "bad.yaml"
    bad.write_text(TACTICS.format(cooldown=0, approval="false").replace("G3", "G99"))
    problems = m.reload(tactics=str(bad))
    assert problems and "unknown goal 'G99'" in problems[0]
    assert any(d.kind == "reload_refused" for d in m.knowledge.decisions())
    assert {t.name for t in m.tactics.tactics} == {"hand-over", "beep"}  # the old set stays
    good = tmp_path / "good.yaml"
    good.write_text(
        TACTICS.format(cooldown=0, approval="false").replace("name: beep", "name: chirp")
    )
    assert m.reload(tactics=str(good)) == []
    assert {t.name for t in m.tactics.tactics} == {"hand-over", "chirp"}
    # the loop goes on with the new tactics and the old inputs (rates too)
    drive(m, ticks(1.1, 1.3), category_at=lambda t: 1)
    assert "chirp" in {tac for _, k, tac in kinds(m) if k == "started"}
    assert m.analyzer.evaluator.value("rate(A3)") is not None


def on_knowledge(db: Path, cooldown: float) -> tuple[AutonomicManager, RecordingActuator]:
    """A manager on the TACTICS set (warm-up 0.5 s) whose knowledge is the file ``db``."""
    actuator = RecordingActuator()
    tactics = parse_tactics_yaml(TACTICS.format(cooldown=cooldown, approval="false"))
    m = AutonomicManager(
        rover_model(), tactics, knowledge=Knowledge(db), actuator=actuator, warmup=0.5
    )
    return m, actuator


def test_manager_resumes_tactic_state_from_its_knowledge(tmp_path: Path) -> None:
    db = tmp_path / "run.db"
    m, _ = on_knowledge(db, cooldown=30)
    drive(m, ticks(0, 1.0))
    drive(m, ticks(1.1, 1.2), category_at=lambda t: 1)  # hand-over awaiting its postcondition
    assert m.planner.runtimes["hand-over"].state == "awaiting"
    deadline = m.planner.runtimes["hand-over"].deadline
    m.knowledge.close()  # as if the process died here (the DB is all that remains)
    m2, act2 = on_knowledge(db, cooldown=30)
    rt = m2.planner.runtimes["hand-over"]
    assert rt.state == "awaiting" and rt.deadline == deadline
    resumed = [d for d in m2.knowledge.decisions() if d.kind == "resumed"]
    assert resumed[0].tactic == "hand-over" and resumed[0].data["deadline"] == deadline
    drive(m2, ticks(1.3, 3.5), category_at=lambda t: 1)
    assert act2.calls.count(("request", "/rover/set_mode", {"mode": "manual"})) == 0  # not rerun
    assert any(
        d.kind == "postcondition_failed" and d.t == pytest.approx(3.1)
        for d in m2.knowledge.decisions()
    )
    m2.close()


def test_a_restarted_manager_warms_up_again_before_unknown_goals_count(tmp_path: Path) -> None:
    # Down long enough for every restored value to go stale: at its first step the restarted
    # manager knows nothing fresh. Unknown goals count only after `warmup` from that step
    # (as at a start), so it does not act on its own outage; then they count as before.
    db = tmp_path / "run.db"
    m, _ = on_knowledge(db, cooldown=0)
    drive(m, ticks(0, 1.0))
    assert kinds(m) == []
    m.knowledge.close()  # as if the process died here
    m2, _ = on_knowledge(db, cooldown=0)
    for t in ticks(6.0, 6.4):  # no inputs arrive: G3 is unknown
        m2.step(t)
    assert m2.analyzer.evaluator.state("G3").status is None
    assert [k for _, k, _ in kinds(m2) if k == "started"] == []  # warming up again
    for t in ticks(6.5, 6.7):
        m2.step(t)
    started = [(t, tac) for t, k, tac in kinds(m2) if k == "started"]
    assert started == [(6.5, "hand-over")]  # unknown counts again, warm-up over
    m2.close()


def test_config_builds_a_manager(tmp_path: Path) -> None:
    cfg = parse_config(
        "anunnaki: utu/1\nname: rover\ngoal_model: goals.yaml\nbinding: binding.yaml\n"
        "tactics: tactics.xml\nknowledge: ':memory:'\nfailsafe: fail-safe\n"
        "run_stop: {service: /rover/stop}\n",
        base=ROVER,
    )
    m = AutonomicManager.from_config(cfg, clock=ManualClock())
    try:
        assert m.failsafe == "fail-safe"
        assert set(m.knowledge.models_at()) == {"goal_model", "binding", "tactics"}
        assert m.warmup == 2.0
    finally:
        m.close()


def _sim_trace(seconds: float) -> list[Record]:
    recs = []
    for k in range(int(seconds * 10) + 1):
        t = round(k * 0.1, 4)
        recs.append(Record(t, "/rover/ultrasonic", {"range": 3.0}))
        if k % 2 == 0:
            recs.append(
                Record(t, "/rover/status", {"mode": "autonomous", "buzzer": False, "bumper": False})
            )
            recs.append(Record(t, "/rover/camera/info", {"seq": k}))
            recs.append(Record(t, "/utu/oracle/output", {"category": 0, "confidence": 0.9}))
    return recs


@pytest.mark.slow
@pytest.mark.parametrize("use_sim_time", [True, False])
def test_slow_simulation_on_sim_time_has_no_spurious_violations(use_sim_time: bool) -> None:
    """At 0.3x real time, sim time keeps 10 Hz at 10 Hz; the wall clock would see 3 Hz."""
    with open_bus("inproc") as bus:
        system = ScriptedSystem(bus, _sim_trace(2.0), publish_clock=True)
        clock = SimClock() if use_sim_time else WallClock()
        manager = AutonomicManager(
            rover_model(), load_tactics(ROVER / "tactics.xml"), bus=bus, clock=clock, warmup=0.5
        )
        if isinstance(clock, SimClock):
            bus.subscribe("/clock", lambda s: clock.update(s.message.time), queue=4)
        stop = threading.Event()
        spinner = threading.Thread(target=manager.spin, args=(stop,), kwargs={"rate": 50})
        spinner.start()
        try:
            system.run(speed=0.3)
            deadline = time.monotonic() + 2
            while time.monotonic() < deadline and manager._inputs:
                time.sleep(0.01)
        finally:
            stop.set()
            spinner.join(5)
        g6 = [v.status for v in manager.knowledge.verdicts() if v.node == "G6"]
        started = [d.tactic for d in manager.knowledge.decisions() if d.kind == "started"]
        manager.close()
        system.close()
        assert isinstance(bus.stats().totals(), dict)
    if use_sim_time:
        assert "unsatisfied" not in g6
        assert started == []
    else:  # the control: the same run on the wall clock sees the sensor at 3 Hz
        assert "unsatisfied" in g6


def test_bus_actuator_sees_refusals_in_generic_and_service_replies(bus) -> None:  # type: ignore[no-untyped-def]
    from anunnaki.messages import ServiceReply
    from anunnaki.utu import BusActuator

    bus.service("/a/generic", lambda m: {"ok": False, "error": "unknown mode 'x'"})
    bus.service("/a/accepts", lambda m: {"ok": True, "mode": "manual"})
    bus.service("/a/typed", lambda m: ServiceReply(ok=True, body={"model": "fog-1"}))
    act = BusActuator(bus)
    refused = act.request("/a/generic", {"mode": "x"}, 2.0)
    assert not refused.ok and refused.detail == "unknown mode 'x'"
    assert act.request("/a/accepts", {}, 2.0).reply == {"ok": True, "mode": "manual"}
    typed = act.request("/a/typed", {}, 2.0)
    assert typed.ok and typed.reply == {"model": "fog-1"}
    timeout = act.request("/a/nobody", {}, 0.2)
    assert not timeout.ok


def test_reload_service_swaps_tactics_while_spinning(bus, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    tactics = parse_tactics_yaml(TACTICS.format(cooldown=0, approval="false"))
    m = AutonomicManager(
        rover_model(), tactics, bus=bus, actuator=RecordingActuator(), reload_dirs=[tmp_path]
    )
    stop = threading.Event()
    spinner = threading.Thread(target=m.spin, args=(stop,), kwargs={"rate": 100})
    spinner.start()
    try:
        ops = {"caller": "ops", "token": client_operator_token()}
        good = tmp_path / "good.yaml"
        good.write_text(
            TACTICS.format(cooldown=0, approval="false").replace("name: beep", "name: chirp")
        )
        bad = tmp_path / "bad.yaml"
        bad.write_text("anunnaki: tactics/1\ntactics: [{name: x}]\n")
        refused = bus.request(
            "/utu/reload", {"tactics": str(bad), **ops}, timeout=RELOAD_TIMEOUT
        ).to_body()
        assert refused["ok"] is False and refused["status"] == "refused"
        assert str(bad) in refused["error"]  # the reply names the file and what is wrong
        accepted = bus.request(
            "/utu/reload", {"tactics": str(good), **ops}, timeout=RELOAD_TIMEOUT
        ).to_body()
        assert accepted["ok"] is True and accepted["status"] == "accepted"
        assert bus.request("/utu/reload", ops, timeout=RELOAD_TIMEOUT).to_body()["ok"] is False
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and {t.name for t in m.tactics.tactics} != {
            "hand-over",
            "chirp",
        }:
            time.sleep(0.01)
    finally:
        stop.set()
        spinner.join(5)
    kinds_ = [d.kind for d in m.knowledge.decisions()]
    assert kinds_.count("reload_requested") == 2
    assert "reload_refused" in kinds_ and "reloaded" in kinds_
    assert kinds_.index("reload_refused") < kinds_.index("reloaded")
    assert {t.name for t in m.tactics.tactics} == {"hand-over", "chirp"}
    m.close()


@pytest.mark.parametrize("forged", ["/clock", "batch"])
def test_one_forged_time_neither_freezes_nor_steers_utu(forged: str, tmp_path: Path) -> None:
    """A /clock (or a monitor batch) stamped 1e12 is refused; the run's times go on."""
    from anunnaki.messages import Clock, MonitorBatch

    cfg = tmp_path / "utu.yaml"
    cfg.write_text(
        f"anunnaki: utu/1\ngoal_model: {ROVER / 'goals.yaml'}\nbinding: {ROVER / 'binding.yaml'}\n"
        f"tactics: {ROVER / 'tactics.xml'}\nclock: sim\nwarmup: 0\n"
    )
    with open_bus("inproc") as bus:
        manager = AutonomicManager.from_config(
            parse_config(cfg.read_text(), base=tmp_path), bus=bus
        )
        for t in (1.0, 2.0):
            bus.publish("/clock", Clock(time=t))
            manager.step()
        if forged == "/clock":
            bus.publish("/clock", Clock(time=1e12))
            manager.step()
        else:
            # as a forged /utu/monitor/input reaches the analyze node of a per-node run
            batch = MonitorBatch(origin="", seq=99, t=1e12, inputs=[], ops=[])
            assert manager.analyze_stage.analyze(batch) is None  # refused whole
        for t in (25.0, 45.8):
            bus.publish("/clock", Clock(time=t))
            manager.step()
        now = manager.analyze_stage.now
        refused = manager.clock.refused if forged == "/clock" else manager.analyze_stage.refused
        manager.close()
    assert refused == 1
    assert now == 45.8  # the run's last instant, not 1e12


@pytest.mark.parametrize("target", ["fifo", "/dev/zero", "outside", "symlink-out", "huge"])
def test_a_reload_reads_only_small_regular_files_in_its_folders(
    bus, tmp_path: Path, target: str
) -> None:  # type: ignore[no-untyped-def]
    """A named pipe hung the loop; /dev/zero grew memory to 1.86 GB (issue #12)."""
    allowed, elsewhere = tmp_path / "run", tmp_path / "elsewhere"
    allowed.mkdir()
    elsewhere.mkdir()
    good = (ROVER / "tactics.yaml").read_text()
    (elsewhere / "t.yaml").write_text(good)
    path = {
        "fifo": allowed / "pipe.yaml",
        "/dev/zero": Path("/dev/zero"),
        "outside": elsewhere / "t.yaml",
        "symlink-out": allowed / "link.yaml",
        "huge": allowed / "huge.yaml",
    }[target]
    if target == "fifo":
        os.mkfifo(path)
    elif target == "symlink-out":
        path.symlink_to(elsewhere / "t.yaml")
    elif target == "huge":
        path.write_text(good + "#" * (5 << 20))
    tactics = load_tactics(ROVER / "tactics.yaml")
    act = RecordingActuator()
    m = AutonomicManager(rover_model(), tactics, bus=bus, actuator=act, reload_dirs=[allowed])
    try:
        body = {"tactics": str(path), "caller": "x", "token": client_operator_token()}
        reply = bus.request("/utu/reload", body, timeout=RELOAD_TIMEOUT).to_body()
        m.step(1.0)
        assert reply["ok"] is False and reply["status"] == "refused"
        assert "refused:" in reply["error"]
        kinds = [d.kind for d in m.knowledge.decisions()]
        assert "reload_refused" in kinds and "reloaded" not in kinds
    finally:
        m.close()


def test_a_flood_does_not_hold_a_step(tmp_path: Path) -> None:
    """The intake kept pulling while messages arrived: 4 cycles in 10 s under a flood
    (issue #12). A step now takes at most one queue's worth per topic, so it returns."""
    from anunnaki.bus import Sample
    from anunnaki.messages import Generic

    class Endless:
        """A monitored topic whose producers refill it as fast as it is emptied."""

        taken = 0
        pending = True

        def try_recv(self) -> Sample:
            Endless.taken += 1
            msg = Generic(data={"mode": "autonomous", "buzzer": False, "bumper": False})
            return Sample(
                topic="/rover/status", message=msg, sent_at=0.0, sender="x", seq=0, key="k"
            )

        def close(self) -> None:
            pass

    with open_bus("inproc") as bus:
        m = AutonomicManager(
            rover_model(), load_tactics(ROVER / "tactics.xml"), bus=bus, queue=16,
            actuator=RecordingActuator(),
        )  # fmt: skip
        m._pull.subs["/rover/status"] = Endless()
        try:
            for t in (1.0, 2.0, 3.0):
                m.step(t)  # returns: the flood is taken a queue at a time
            assert Endless.taken == 3 * 16
            assert m.monitor.topics["/rover/status"].count == 3 * 16  # all analysed
        finally:
            m._pull.subs.clear()
            m.close()
    # ``intake`` bounds it below the queue (a deployment that expects floods).
    Endless.taken = 0
    with open_bus("inproc") as bus:
        m = AutonomicManager.from_config(
            parse_config(
                f"anunnaki: utu/1\ngoal_model: {ROVER}/goals.yaml\n"
                f"binding: {ROVER}/binding.yaml\ntactics: {ROVER}/tactics.xml\nintake: 64\n"
            ),
            bus=bus,
            actuator=RecordingActuator(),
        )
        m._pull.subs["/rover/status"] = Endless()
        try:
            m.step(1.0)
            assert Endless.taken == m.parts.config.intake == 64
        finally:
            m._pull.subs.clear()
            m.close()


def test_the_watchdog_run_stops_a_stuck_loop(tmp_path: Path) -> None:
    """A loop that has not finished a step within ``watchdog`` s run-stops the platform
    from the watchdog's thread; the loop records it once it moves again (issue #12).

    As a node's watchdog does (one behaviour, ``host/_desk.py``): through the run-stop
    service on the bus, not the actuator (which may be what hangs), announced on
    ``/utu/run_stop`` with caller ``watchdog:<name>``.
    """
    from helpers_procs import wait_until

    from anunnaki.messages import RunStop

    cfg = parse_config(
        f"anunnaki: utu/1\ngoal_model: {ROVER}/goals.yaml\nbinding: {ROVER}/binding.yaml\n"
        f"tactics: {ROVER}/tactics.xml\nrun_stop: {{service: /rover/stop}}\n"
        "watchdog: 0.3\nrate: 50\n"
    )
    release = threading.Event()
    rounds: list[int] = []

    def on_step(m: AutonomicManager) -> None:
        rounds.append(1)
        if len(rounds) == 3:
            release.wait(30)  # the loop is stuck here (a hung handler, a deadlock, ...)

    with open_bus("inproc") as bus:
        heard: list[RunStop] = []
        stops: list[dict[str, object]] = []
        bus.subscribe("/utu/run_stop", lambda s: heard.append(s.message), queue=8)
        bus.service("/rover/stop", lambda m: stops.append(m.to_body()) or {"ok": True})
        act = RecordingActuator()
        m = AutonomicManager.from_config(cfg, bus=bus, actuator=act)
        stop = threading.Event()
        spinner = threading.Thread(target=m.spin, args=(stop,), kwargs={"on_step": on_step})
        spinner.start()
        try:
            wait_until(lambda: bool(stops), 10, "the watchdog's run-stop request")
            assert len(rounds) == 3  # still stuck: the platform was told from outside the loop
            assert stops == [{"reason": "run-stop"}]
            assert act.calls == []  # not through the actuator
            wait_until(lambda: any("watchdog" in r.reason for r in heard), 10, "its announcement")
            assert heard[0].caller == "watchdog:utu"
            release.set()
            wait_until(lambda: m.run_stopped, 10, "the loop recording the run-stop")
        finally:
            release.set()
            stop.set()
            spinner.join(10)
            made = [(d.kind, d.data.get("caller")) for d in m.knowledge.decisions()]
            m.close()
    assert ("run_stop", "watchdog:utu") in made


# -- the cycle, told once -----------------------------------------------------------------
def entries(m: AutonomicManager) -> list[str]:
    """Record every entry into a stage of ``m`` (in the list returned, in call order)."""
    calls: list[str] = []
    stages = {
        "monitor": (m.monitor_stage, "batch"),
        "analyze": (m.analyze_stage, "analyze"),
        "execute.begin": (m.execute_stage, "begin"),
        "plan": (m.plan_stage, "plan"),
        "execute.complete": (m.execute_stage, "complete"),
    }
    for label, (stage, method) in stages.items():
        original = getattr(stage, method)

        def entered(*args, _label=label, _original=original, **kwargs):  # type: ignore[no-untyped-def]
            calls.append(_label)
            return _original(*args, **kwargs)

        setattr(stage, method, entered)
    return calls


CYCLE = ["monitor", "analyze", "execute.begin", "plan", "execute.complete"]


def test_a_goal_update_enters_each_stage_once_in_order() -> None:
    """One goal update: monitor, analyze, plan and execute each entered once per step.

    Execute's two halves frame plan: ``begin`` settles what is in flight (operator calls,
    outcomes, postconditions, escalation) so that plan selects among what is left, and
    ``complete`` starts plan's choice. Nothing else of a stage runs: no second analysis,
    no copy of the tactic runtimes between plan and execute.
    """
    m, act = make()
    calls = entries(m)
    drive(m, ticks(0, 1.0))
    steps = 11
    assert calls == CYCLE * steps
    calls.clear()
    feed_nominal(m, 1.1, category=1)  # the goal update: A4.category turns 1
    m.step(1.1)
    assert calls == CYCLE  # each once, in order, for the update that starts two tactics
    assert [tac for _, k, tac in kinds(m) if k == "started"] == ["beep", "hand-over"]
    assert act.calls[:2] == [
        ("publish", "/rover/buzzer", {"on": True}),
        ("request", "/rover/set_mode", {"mode": "manual"}),
    ]
    ends = [r.t for r in m.knowledge.inputs() if r.topic == "__tick__"]
    assert ends.count(1.1) == 1  # the step's end is marked once, after execute


def test_a_rover_run_enters_each_stage_once_per_step(bus) -> None:  # type: ignore[no-untyped-def]
    """Over the rover's whole scenario (fail-safe, escalation-free), every step is one cycle."""
    system = ScriptedSystem(bus, ROVER / "trace.jsonl")
    manager = AutonomicManager(
        rover_model(), load_tactics(ROVER / "tactics.xml"), bus=bus, failsafe="fail-safe",
        run_stop_service="/rover/stop", warmup=2.0,
    )  # fmt: skip
    calls = entries(manager)
    try:
        steps = 0
        for t in system.instants():
            if t > 45.0:
                break
            system.step(t)
            manager.step(t)
            steps += 1
        assert steps > 100
        assert calls == CYCLE * steps
        assert "postcondition_ok" in [k for _, k, _ in kinds(manager, "fail-safe")]
    finally:
        manager.close()
        system.close()


def test_plan_and_execute_share_one_store_of_tactic_runtimes(tmp_path: Path) -> None:
    """One owner per piece of state: one Planner holds every tactic's runtime.

    Plan selects among the execute stage's runtimes (it writes only the selection fields);
    neither copies the other's — the copies a plan and an execute node in different
    processes keep (``mirror``) are never taken in one process — and a restarted part
    takes up the same store.
    """
    m, _ = make(cooldown=10.0, knowledge=Knowledge(tmp_path / "k.db"))
    store = m.planner
    assert m.plan_stage.planner is store
    assert m.execute_stage.planner is store
    runtimes = dict(store.runtimes)

    def no_copy(*args: object) -> None:
        raise AssertionError("a copy of the tactic runtimes was taken in one process")

    m.plan_stage.mirror = no_copy  # type: ignore[method-assign]
    m.execute_stage.mirror = no_copy  # type: ignore[method-assign]
    drive(m, ticks(0, 1.0))
    drive(m, ticks(1.1, 1.5), category_at=lambda t: 1)  # hand-over starts, then awaits
    handover = store.runtimes["hand-over"]
    assert handover is runtimes["hand-over"]
    assert handover.state == "awaiting" and handover.fired
    for part in ("plan", "execute"):
        m.restart_part(part)
        assert m.plan_stage.planner is m.execute_stage.planner is store
    assert handover.state == "awaiting"  # execute took its fields up again from Knowledge
    assert not handover.fired  # a restarted plan forgets what only selection knew
    drive(m, ticks(1.6, 3.5), category_at=lambda t: 1)  # postcondition fails at its deadline
    made = [k for _, k, _ in kinds(m, "hand-over")]
    assert made.count("started") == 1 and "postcondition_failed" in made
    assert handover.cooldown_until == pytest.approx(13.1)  # set by execute, seen by plan:
    assert handover.state == "queued" and made[-1] == "deferred"  # still applicable, waits
    m.close()
