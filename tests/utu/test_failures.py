"""Failures of the managed system's inputs, each met by the configured policy.

The example rover (its goal model, binding and tactics: ``tests/data/utu/utu-rover.yaml``)
under Utu. Whatever goes wrong with the behavior oracle's topic — it falls silent, its node
dies, it carries garbage — G3 ("the rover detects obstacles") becomes unknown, unknown counts
as unsatisfied (the model's default policy), and the fail-safe tactic starts: switch to
manual mode. Each test then shows the manager still running: it takes the rover's next
messages (the postcondition is verified once the rover is in manual mode) and answers
``/utu/ready``.

The silent-topic and garbage tests are deterministic: an in-process bus, the scripted rover
and the manager both stepped by the test at the same instants (``step(now)``). The
liveliness test kills a real oracle process with SIGKILL over zenoh.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from helpers_procs import (
    DATA,
    Child,
    LiveRover,
    Rover,
    find,
    of,
    read_decisions,
    rover_trace,
    wait_until,
)

from anunnaki.bus import Bus, InprocHub, Publisher, open_bus
from anunnaki.messages import Generic, ModeRequest
from anunnaki.utu import AutonomicManager, UtuConfig, load_config

ORACLE = "/utu/oracle/output"
ROVER = Path(__file__).resolve().parents[2] / "examples" / "rover"
STALENESS = 2.0  # s: the rover model's default, which the oracle's agent A4 keeps
RATE = 10  # Hz: the rover's messages, and the manager's steps, in the stepped tests


def config(name: str = "utu-rover.yaml", **update: Any) -> UtuConfig:
    return load_config(DATA / name).model_copy(update=update)


@dataclass
class Stepped:
    """A manager and the scripted rover on one in-process bus, stepped together."""

    manager: AutonomicManager
    rover: Rover
    client: Bus  # another node: publishes on the oracle topic, asks the manager's services
    oracle: Publisher

    def step(self, t: float) -> None:
        """The rover publishes what its trace holds up to ``t``, then the manager steps."""
        self.rover.step(t)
        self.manager.step(t)

    def status(self, node: str) -> str:
        return self.manager.analyzer.evaluator.state(node).status_name

    def decisions(self, kind: str) -> list[Any]:
        return of(self.manager.knowledge.decisions(), kind)

    def started_at(self) -> float | None:
        started = self.decisions("started")
        return started[0].t if started else None

    def ready(self) -> bool:
        reply = self.client.request("/utu/ready", {}, timeout=5.0)
        return isinstance(reply, Generic) and reply.data.get("ready") is True


@pytest.fixture
def stepped() -> Iterator[Stepped]:
    """The rover reports nominal status, camera and ultrasonic at 10 Hz for 12 s, no oracle."""
    hub = InprocHub()
    with (
        open_bus("inproc", hub=hub, name="utu") as utu_bus,
        open_bus("inproc", hub=hub, name="rover") as rover_bus,
        open_bus("inproc", hub=hub, name="oracle") as client,
    ):
        rover = Rover(rover_bus, rover_trace(12.0, rate=RATE))
        manager = AutonomicManager.from_config(config(), bus=utu_bus)
        try:
            yield Stepped(manager, rover, client, client.publisher(ORACLE))
        finally:
            manager.close()
            rover.close()


def after(t: float, steps: int = 1) -> float:
    """The step instant ``steps`` after ``t`` (``(i + steps) / RATE``: no float drift)."""
    return (round(t * RATE) + steps) / RATE


def instants(start: float, stop: float) -> Iterator[float]:
    """The step instants ``i / RATE`` from ``start`` to ``stop`` inclusive (exact decimals)."""
    for i in range(round(start * RATE), round(stop * RATE) + 1):
        yield i / RATE


def assert_fail_safe_then_recovery(s: Stepped, at: float) -> None:
    """The fail-safe started at ``at`` (once); the rover obeyed; the manager saw it."""
    assert s.started_at() == at
    assert s.rover.mode_requests() == 1
    (action,) = [d for d in s.decisions("action") if d.data["index"] == 0]
    assert (action.data["service"], action.data["mode"], action.data["ok"]) == (
        "/rover/set_mode",
        "manual",
        True,
    )
    s.step(after(at))  # the rover's next status reports manual mode
    assert s.status("G11") == "satisfied"
    assert s.status("G3") == "satisfied"
    (ok,) = s.decisions("postcondition_ok")
    assert ok.t == after(at)
    assert s.ready()


# --- 1. a topic falls silent ------------------------------------------------------------------


def test_silent_oracle_starts_fail_safe_the_step_after_its_deadline(stepped: Stepped) -> None:
    s = stepped
    last_word = 3.0
    for t in instants(0.0, last_word):
        s.oracle.put({"category": 0, "confidence": 0.9})
        s.step(t)
    assert s.status("G3") == "satisfied"
    # Silence: the last values hold until the deadline, inclusive ...
    for t in instants(after(last_word), last_word + STALENESS):
        s.step(t)
        assert s.status("G3") == "satisfied", t
    assert s.started_at() is None
    # ... and are unknown at the first step past it: G3 is unknown, counted as unsatisfied.
    t_fail = after(last_word + STALENESS)
    s.step(t_fail)
    assert s.status("O1") == "unknown"
    assert s.status("G3") == "unknown"
    assert s.manager.analyzer.evaluator.satisfied_for_tactics("G3") is False
    (selected,) = s.decisions("selected")
    assert selected.t == t_fail
    assert_fail_safe_then_recovery(s, t_fail)


# --- 2. the oracle's node dies ----------------------------------------------------------------


def g3_status(bus: Bus) -> str | None:
    reply = bus.request("/utu/knowledge/query", {"what": "state"}, timeout=10.0)
    assert isinstance(reply, Generic)
    nodes = reply.data.get("nodes")
    g3 = nodes.get("G3") if isinstance(nodes, dict) else None
    return str(g3[1]) if isinstance(g3, list) else None


@pytest.mark.slow
def test_lost_liveliness_starts_fail_safe_long_before_staleness(tmp_path: Path) -> None:
    db = tmp_path / "knowledge.db"
    cfg = config("utu-liveliness.yaml", knowledge=str(db))
    assert cfg.failsafe == "fail-safe"
    with (
        open_bus("zenoh", name="rover") as rover_bus,
        open_bus("zenoh", name="utu", connect=list(rover_bus.endpoints)) as utu_bus,
    ):
        endpoints = ["--connect", rover_bus.endpoints[0], "--connect", utu_bus.endpoints[0]]
        rover = Rover(rover_bus, rover_trace(120.0))  # the oracle is another process
        oracle = Child("oracle_node.py", *endpoints, log=tmp_path / "oracle.log")
        with LiveRover(rover), oracle:
            wait_until(oracle.ready, 30, "the oracle process")
            manager = AutonomicManager.from_config(cfg, bus=utu_bus)
            stop = threading.Event()
            spinner = threading.Thread(target=manager.spin, args=(stop,), kwargs={"rate": 20})
            spinner.start()
            try:
                staleness = manager.model.agents["A4"].staleness
                assert (manager.model.agents["A4"].node, staleness) == ("/oracle", 30.0)
                wait_until(lambda: g3_status(rover_bus) == "satisfied", 30, "G3 satisfied")
                wait_until(lambda: not manager.analyzer.warming_up, 30, "the end of warm-up")
                assert of(read_decisions(db), "started") == []

                killed_at = time.time()
                oracle.kill()
                lost = wait_until(
                    lambda: find(db, "liveliness_lost", tactic=None), 20, "liveliness_lost"
                )
                started = wait_until(lambda: find(db, "started"), 20, "the fail-safe")
                ok = wait_until(lambda: find(db, "postcondition_ok"), 20, "manual mode seen")
                wait_until(lambda: g3_status(rover_bus) == "satisfied", 20, "G3 satisfied again")
                assert "/oracle" not in utu_bus.alive_nodes()
            finally:
                stop.set()
                spinner.join(timeout=30)
                manager.close()
            assert not spinner.is_alive()

    assert (lost.data["node"], lost.data["agents"]) == ("/oracle", ["A4"])
    # The loss, not the (30 s) staleness, explains the start: both in the same step.
    assert killed_at - 0.5 <= lost.t < killed_at + staleness / 3
    assert started.t == lost.t
    assert started.id > lost.id
    assert started.data["reason"] == "preconditions hold"
    assert ok.t <= started.data["deadline"]
    assert rover.mode_requests() == 1


# --- 3. garbage on a topic --------------------------------------------------------------------


def envelope(type_name: str, body: dict[str, Any], v: int = 1) -> bytes:
    """A well-formed envelope (as the bus writes it) around any type name and body."""
    env = {"v": v, "type": type_name, "t": 0.0, "seq": 0, "sender": "oracle", "body": body}
    return json.dumps(env).encode()


GARBAGE = [
    b"\xff\xfe\x00\x01 not an envelope at all",
    b'{"v": 1, "type": "Generic", "t": 0',  # cut short
    envelope("NoSuchMessage", {"category": 0, "confidence": 0.9}),  # unknown type
    envelope("Generic", {"category": 0, "confidence": 0.9}, v=99),  # unknown version
    envelope("ModeRequest", {"mode": 7}),  # known type, invalid body
    envelope("Generic", {"category": 0}).replace(b"0}", b"NaN}"),  # JSON has no NaN
]


def test_undecodable_messages_are_dropped_counted_and_keep_no_topic_alive(
    stepped: Stepped,
) -> None:
    s = stepped
    last_word = 3.0
    for t in instants(0.0, last_word):
        s.oracle.put({"category": 0, "confidence": 0.9})
        s.step(t)
    taken = s.manager.monitor.topics[ORACLE].count
    # From now on only garbage arrives on the oracle's topic, at the same rate.
    fail_at = after(last_word + STALENESS)
    for t in instants(after(last_word), fail_at):
        for raw in GARBAGE:
            s.oracle.put_raw(raw)
        s.step(t)
        if t < fail_at:
            assert s.status("G3") == "satisfied", t
    sent = len(GARBAGE) * round((fail_at - last_word) * RATE)
    malformed = s.manager.bus.stats().malformed  # type: ignore[union-attr]
    assert malformed == {ORACLE: sent}  # each dropped and counted once
    assert s.manager.bus.stats().dropped == {}  # type: ignore[union-attr]
    assert s.manager.monitor.topics[ORACLE].count == taken  # none reached the monitor
    recorded = [r.msg for r in s.manager.knowledge.inputs() if r.topic == ORACLE]
    assert recorded == [{"category": 0, "confidence": 0.9}] * taken  # no garbage in the log
    # Garbage does not vouch for the oracle: its values went unknown at the deadline.
    assert s.status("O1") == "unknown"
    assert_fail_safe_then_recovery(s, fail_at)
    # And good messages are taken again.
    s.oracle.put({"category": 0, "confidence": 0.9})
    s.step(after(fail_at, 2))
    assert s.manager.monitor.topics[ORACLE].count == taken + 1
    assert s.status("O1") == "unsatisfied"  # the obstacle does not hold


@pytest.mark.parametrize(
    "bad",
    [
        {"category": "banana", "confidence": 0.9},
        {"category": [2], "confidence": "high"},
        {"category": False, "confidence": 0.9},  # a bool is no category (not 0)
        {"category": True, "confidence": 0.9},  # nor 1
        {"confidence": 0.9},  # the category is missing
        ModeRequest(mode="manual"),  # a valid message of another type
    ],
    ids=["banana", "list", "false", "true", "missing", "other-type"],
)
def test_wrong_value_types_become_unknown_at_once(stepped: Stepped, bad: Any) -> None:
    s = stepped
    at = 3.0
    for t in instants(0.0, after(at, -1)):
        s.oracle.put({"category": 0, "confidence": 0.9})
        s.step(t)
    assert s.status("G3") == "satisfied"
    taken = s.manager.monitor.topics[ORACLE].count
    s.oracle.put(bad)
    s.step(at)  # the very step that takes it: no waiting for a deadline
    assert s.manager.monitor.topics[ORACLE].count == taken + 1  # it is a valid message
    assert s.status("O1") == "unknown"
    assert s.status("G3") == "unknown"
    assert s.manager.bus.stats().malformed == {}  # type: ignore[union-attr]
    assert_fail_safe_then_recovery(s, at)
    s.oracle.put({"category": 0, "confidence": 0.9})
    s.step(after(at, 2))
    assert s.status("O1") == "unsatisfied"


# --- 4. the detector's node dies (the model manager, agent A6) ----------------------------------


def test_a_dead_detector_starts_the_fail_safe_in_the_step_that_sees_it() -> None:
    """kill -9 of the LEC process: manual mode came 4.3-7.1 s later (issue #12), since G3 did
    not depend on A6. In goals-lm.yaml G4 needs G18 (A6 has model): the fail-safe starts in
    the step that sees the node's liveliness token vanish."""
    rover_dir = DATA.parents[2] / "examples" / "rover"
    cfg = UtuConfig(
        anunnaki="utu/1",
        goal_model=str(rover_dir / "goals-lm.yaml"),
        binding=str(rover_dir / "binding-lm.yaml"),
        tactics=str(rover_dir / "tactics-lm.yaml"),
        warmup=1.0,
        failsafe="fail-safe",
    )
    hub = InprocHub()
    with (
        open_bus("inproc", hub=hub, name="utu") as utu_bus,
        open_bus("inproc", hub=hub, name="rover") as rover_bus,
        open_bus("inproc", hub=hub, name="lm") as lm_bus,
    ):
        rover = Rover(rover_bus, rover_trace(12.0, rate=RATE))
        manager = AutonomicManager.from_config(cfg, bus=utu_bus)
        oracle_token = lm_bus.liveliness_token("/oracle_ground_truth")
        detector = lm_bus.liveliness_token("/lm_manager")
        assessment = {"category": 0, "confidence": 0.9, "context": {"phenomenon": "clear"}}
        active = {"lec": "detector", "model": "rover-default", "domain": "default"}
        try:
            for t in instants(0.0, 3.0):
                lm_bus.publish(ORACLE, assessment)
                lm_bus.publish("/lm_manager/active", active)
                rover.step(t)
                manager.step(t)
            state = manager.analyzer.evaluator.state
            assert (state("G18").status_name, state("G3").status_name) == ("satisfied",) * 2
            assert of(manager.knowledge.decisions(), "started") == []
            detector.close()  # as kill -9 withdraws it
            # Heard on the bus's liveliness thread: queued before the next step.
            wait_until(lambda: len(manager.desk) == 1, 10, "the loss of /lm_manager queued")
            lm_bus.publish(ORACLE, assessment)  # the oracle lives on and sees nothing wrong
            t_kill = after(3.0)
            rover.step(t_kill)
            manager.step(t_kill)
            made = [(d.t, d.kind, d.tactic) for d in manager.knowledge.decisions()]
        finally:
            oracle_token.close()
            manager.close()
            rover.close()
    assert (t_kill, "liveliness_lost", None) in made
    assert made.index((t_kill, "liveliness_lost", None)) < made.index(
        (t_kill, "started", "fail-safe")
    )
    assert rover.mode_requests() == 1


def test_tactics_that_all_fail_at_once_end_in_a_run_stop_not_a_recursion() -> None:
    # A stopped rover refuses every action: fail-safe (G3) and collision-stop (G5) used to
    # hand over to each other forever (RecursionError in the execute node, issue #12).
    from anunnaki.goals import load_goal_model
    from anunnaki.tactics import load_tactics
    from anunnaki.utu import Knowledge, RecordingActuator

    model = load_goal_model(ROVER / "goals.yaml", ROVER / "binding.yaml")
    tactics = load_tactics(ROVER / "tactics.xml")
    refusing = RecordingActuator(outcomes=[(False, "the system is stopped (run-stop)")] * 50)
    manager = AutonomicManager(
        model,
        tactics,
        knowledge=Knowledge(),
        actuator=refusing,
        failsafe="fail-safe",
        run_stop_service="/rover/stop",
    )
    with manager:
        manager.feed("/rover/status", {"mode": "autonomous", "buzzer": False, "bumper": True}, t=1)
        manager.feed("/rover/camera/info", {"seq": 1, "width": 128, "height": 128}, t=1)
        manager.feed("/rover/ultrasonic", {"range": 3.0}, t=1)
        manager.feed("/utu/oracle/output", {"category": 2, "confidence": 0.9}, t=1)
        manager.step(1.0)
        made = [(d.kind, d.tactic, d.data.get("to")) for d in manager.knowledge.decisions()]
    started = [tactic for kind, tactic, _ in made if kind == "started"]
    assert sorted(started) == ["collision-stop", "fail-safe"]  # each tried once
    assert made[-2:] == [("escalated", made[-2][1], "run-stop"), ("run_stop", None, None)]
    assert manager.run_stopped
