"""Actions off the loop's path (issue #12, item 2): a slow or hung service never holds Utu."""

from __future__ import annotations

import threading
from concurrent.futures import Future
from pathlib import Path
from typing import Any

from helpers_procs import wait_until

from anunnaki.bus import open_bus
from anunnaki.managed import ScriptedSystem
from anunnaki.utu import ActionOutcome, AutonomicManager, Knowledge, parse_config, replay
from anunnaki.utu.cycle import RecordedOutcome, ReplayRunner
from anunnaki.utu.host import BusActuator, ThreadRunner

ROVER = Path(__file__).resolve().parents[2] / "examples" / "rover"


# -- the runners ---------------------------------------------------------------------------------
def test_a_thread_runner_hands_back_outcomes_in_order_and_fails_a_hung_action() -> None:
    gate = threading.Event()
    woken = threading.Event()
    runner = ThreadRunner(on_done=woken.set, settle=0.0, grace=0.05)
    try:
        slow = runner.submit("t1", 0, lambda: (gate.wait(), ActionOutcome(True, "late"))[1], 5.0, 0)
        hung = runner.submit(
            "t2", 1, lambda: (threading.Event().wait(30), ActionOutcome(True))[1], 0.1, 0
        )
        assert slow is None and hung is None and runner.in_flight == 2
        # The hung one is failed after its timeout and grace, whatever its thread does.
        wait_until(lambda: runner.has_outcomes, 5.0, "the hung action's deadline")
        done = runner.finished(0.0)
        assert [(d.tactic, d.index, d.outcome.ok) for d in done] == [("t2", 1, False)]
        assert "no reply within 0.1 s" in done[0].outcome.detail
        gate.set()
        assert woken.wait(5.0)
        wait_until(lambda: runner.has_outcomes, 5.0, "the slow action's reply")
        assert [(d.tactic, d.outcome) for d in runner.finished(0.0)] == [
            ("t1", ActionOutcome(True, "late"))
        ]
        assert runner.in_flight == 0
        # An action that raises is a failed outcome, never an exception in the loop.
        settled = ThreadRunner(settle=5.0)
        try:
            out = settled.submit("t3", 0, lambda: 1 / 0, 1.0, 0)  # type: ignore[arg-type,return-value]
            assert out is not None and not out.ok and "ZeroDivisionError" in out.detail
        finally:
            settled.close()
    finally:
        gate.set()
        runner.close()


def test_a_thread_runner_sends_a_request_that_does_not_wait_from_the_step_itself() -> None:
    """``start`` (the bus actuator's ``request_start``): no worker thread between the step
    and the request; the reply completes it, and one with no reply fails at its timeout."""
    woken = threading.Event()
    runner = ThreadRunner(on_done=woken.set, settle=0.0, grace=30.0)
    threads: list[str] = []
    replies: list[Future[ActionOutcome]] = []

    def start() -> Future[ActionOutcome]:
        threads.append(threading.current_thread().name)
        replies.append(Future())
        return replies[-1]

    def unused() -> ActionOutcome:
        raise AssertionError("a request with a start never runs on a worker thread")

    try:
        assert runner.submit("t1", 0, unused, 5.0, 0, start=start) is None
        assert runner.submit("t2", 0, unused, 0.05, 0, start=start) is None
        assert threads == [threading.current_thread().name] * 2 and runner.in_flight == 2
        replies[0].set_result(ActionOutcome(True, "replied"))
        assert woken.wait(5.0)
        assert [(d.tactic, d.outcome) for d in runner.finished(0.0)] == [
            ("t1", ActionOutcome(True, "replied"))
        ]
        # No thread to overrun its timeout: failed at the timeout itself, not after the grace.
        wait_until(lambda: runner.has_outcomes, 5.0, "the unanswered request's timeout")
        done = runner.finished(0.0)
        assert [(d.tactic, d.outcome) for d in done] == [
            ("t2", ActionOutcome(False, "no reply within 0.05 s"))
        ]
        # A reply already in (the in-process bus answering within the send) is taken at once,
        # settle 0 or not; a start that raises is a failed outcome, never an exception.
        answered: Future[ActionOutcome] = Future()
        answered.set_result(ActionOutcome(True, "at once"))
        assert runner.submit("t3", 0, unused, 1.0, 0, start=lambda: answered) == ActionOutcome(
            True, "at once"
        )
        out = runner.submit("t4", 0, unused, 1.0, 0, start=lambda: 1 / 0)  # type: ignore[arg-type,return-value]
        assert out is not None and not out.ok and "ZeroDivisionError" in out.detail
        assert runner.in_flight == 0
    finally:
        runner.close()


def test_the_bus_actuator_sends_without_waiting_and_maps_the_reply() -> None:
    with open_bus("inproc") as bus:
        release = threading.Event()
        bus.service("/rover/set_mode", lambda r: {"mode": r["mode"]} if release.wait(10) else None)
        bus.service("/rover/stop", lambda r: {"ok": False, "error": "already stopped"})
        actuator = BusActuator(bus)
        pending = actuator.request_start("/rover/set_mode", {"mode": "manual"}, 5.0)
        assert not pending.done()
        release.set()
        assert pending.result(5.0) == ActionOutcome(
            True, "/rover/set_mode replied", {"mode": "manual"}
        )
        refused = actuator.request_start("/rover/stop", {}, 5.0).result(5.0)
        assert refused == actuator.request("/rover/stop", {}, 5.0)
        assert not refused.ok and refused.detail == "already stopped"
        nobody = actuator.request_start("/nobody", {}, 5.0).result(5.0)
        assert not nobody.ok and "it is not up" in nobody.detail


def test_a_replay_runner_gives_recorded_outcomes_at_their_instants() -> None:
    runner = ReplayRunner(
        [
            RecordedOutcome(1.0, "a", 0, True, "at once"),
            RecordedOutcome(3.0, "b", 0, False, "refused"),
            RecordedOutcome(2.5, "a", 0, True, "second attempt, later"),
        ]
    )
    assert runner.submit("a", 0, lambda: ActionOutcome(True), 1.0, 1.0) == ActionOutcome(
        True, "at once"
    )
    assert runner.submit("b", 0, lambda: ActionOutcome(True), 1.0, 2.0) is None
    assert runner.submit("a", 0, lambda: ActionOutcome(True), 1.0, 2.0) is None
    assert [d.tactic for d in runner.finished(2.4)] == []
    assert [d.tactic for d in runner.finished(2.5)] == ["a"]
    assert [(d.tactic, d.outcome.ok) for d in runner.finished(9.0)] == [("b", False)]
    assert runner.submit("c", 0, lambda: ActionOutcome(False), 1.0, 9.0) == ActionOutcome(
        True, "not recorded (the log ends first)"
    )


# -- in the loop ---------------------------------------------------------------------------------
class SlowRover(ScriptedSystem):
    """The scripted rover whose mode service takes as long as the test says."""

    def __init__(self, bus: Any, trace: Path) -> None:
        self.gate = threading.Event()
        self.asked = threading.Event()
        super().__init__(bus, trace)

    def _set_mode(self, message: Any) -> dict[str, Any]:
        self.asked.set()
        self.gate.wait(30.0)
        return super()._set_mode(message)


def utu_config(db: Path) -> str:
    return (
        "anunnaki: utu/1\nname: rover\n"
        f"goal_model: {ROVER / 'goals.yaml'}\nbinding: {ROVER / 'binding.yaml'}\n"
        f"tactics: {ROVER / 'tactics.xml'}\nknowledge: {db}\n"
        "warmup: 2.0\nfailsafe: fail-safe\nrun_stop: {service: /rover/stop}\n"
    )


def run_with_slow_rover(db: Path, *, answer: bool) -> tuple[list[tuple[float, str, Any]], float]:
    """Step the rover example; the fail-safe's mode change (t = 25) waits on the rover.

    Returns the decisions and the last instant stepped while the action was in flight.
    """
    with open_bus("inproc") as bus, SlowRover(bus, ROVER / "trace.jsonl") as rover:
        manager = AutonomicManager.from_config(parse_config(utu_config(db)), bus=bus)
        runner = manager.actions
        assert isinstance(runner, ThreadRunner)
        runner.settle = 0.0  # as a live loop on the wall clock, with no time to wait
        stepped_in_flight = 0.0
        try:
            for t in rover.instants():
                rover.step(t)
                if runner.in_flight and t >= 30.0 and not runner.has_outcomes:
                    if answer:
                        rover.gate.set()
                    wait_until(lambda: runner.has_outcomes, 10.0, "the mode change's outcome")
                if runner.in_flight:
                    stepped_in_flight = t
                manager.step(t)
        finally:
            rover.gate.set()
            manager.close()
    with Knowledge(db) as kb:
        return [(d.t, d.kind, d.data) for d in kb.decisions()], stepped_in_flight


def test_a_slow_service_does_not_hold_the_loop_and_its_reply_continues_the_tactic(
    tmp_path: Path,
) -> None:
    made, in_flight_until = run_with_slow_rover(tmp_path / "slow.db", answer=True)
    kinds = [(t, k) for t, k, _ in made]
    # Started at 25; the loop went on stepping (inputs, verdicts) while the rover was busy.
    assert (25.0, "started") in kinds
    assert in_flight_until >= 29.0
    action = next((t, d) for t, k, d in made if k == "action")
    assert action[0] > 29.0 and action[1]["ok"] is True
    # The reply continued the tactic: its postconditions were then checked as before.
    assert any(k in ("postcondition_ok", "postcondition_failed") for _, k in kinds)
    assert not any(k == "action_failed" for _, k in kinds)
    report = replay(tmp_path / "slow.db")
    assert report.identical, report.summary()


def test_a_hung_service_fails_the_action_and_escalates(tmp_path: Path) -> None:
    made, _ = run_with_slow_rover(tmp_path / "hung.db", answer=False)
    kinds = [k for _, k, _ in made]
    failed = next(d for _, k, d in made if k == "action")
    assert failed["ok"] is False and "no reply" in failed["detail"]
    assert "within 2.0 s" in failed["detail"]
    assert kinds.index("action_failed") < kinds.index("run_stop")
    report = replay(tmp_path / "hung.db")
    assert report.identical, report.summary()
