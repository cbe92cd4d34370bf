"""Event-driven reaction: a violation is acted on at once; nominal floods decide nothing.

Live (``spin``) on the in-process bus, the manager reacts in the thread that delivers the
message: no thread hop on a violation's path. A message that changes nothing is recorded
and left for the next time-driven step. Nodes act on arrival, not on a rate tick.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import pytest

from anunnaki.bus import Executor, open_bus
from anunnaki.clock import SimClock, WallClock
from anunnaki.goals import load_binding, parse_goal_model
from anunnaki.messages import AnalysisState, Clock, MonitorBatch
from anunnaki.tactics import load_tactics
from anunnaki.utu import (
    NODE_NAMES,
    ActionOutcome,
    AutonomicManager,
    Knowledge,
    RecordingActuator,
    build_node,
    parse_config,
)

ROVER = Path(__file__).parents[2] / "examples" / "rover"
NOMINAL = {
    "/rover/status": {"mode": "autonomous", "buzzer": False, "bumper": False, "lights": True},
    "/rover/camera/info": {"seq": 1},
    "/utu/oracle/output": {"category": 0, "confidence": 0.9},
}


def wait_for(predicate: Callable[[], bool], timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    pause = threading.Event()
    while not predicate():
        if time.monotonic() > deadline:
            return False
        pause.wait(0.001)
    return True


class ThreadActuator(RecordingActuator):
    """Records the thread each request runs in."""

    def __init__(self) -> None:
        super().__init__()
        self.threads: list[int] = []

    def request(self, service: str, payload: Mapping[str, Any], timeout: float) -> ActionOutcome:
        self.threads.append(threading.get_ident())
        return super().request(service, payload, timeout)


@pytest.fixture
def live() -> Iterator[tuple[Any, AutonomicManager, ThreadActuator]]:
    model = parse_goal_model(
        (ROVER / "goals.yaml").read_text(), binding=load_binding(ROVER / "binding.yaml")
    )
    actuator = ThreadActuator()
    with open_bus("inproc") as bus:
        m = AutonomicManager(
            model,
            load_tactics(ROVER / "tactics.xml"),
            bus=bus,
            actuator=actuator,
            clock=WallClock(),
            failsafe="fail-safe",
            warmup=2.0,  # inputs still arriving at start are no violation
            rate=2.0,  # time-driven steps twice a second: a reaction must not wait for one
        )
        stop = threading.Event()
        spinner = threading.Thread(target=m.spin, args=(stop,), daemon=True)
        spinner.start()
        try:
            yield bus, m, actuator
        finally:
            stop.set()
            m.wake()
            spinner.join(5.0)
            m.close()


def nominal(bus: Any, n: int = 12, period: float = 0.1) -> None:
    pause = threading.Event()
    for _ in range(n):
        for topic, msg in NOMINAL.items():
            bus.publish(topic, msg)
        bus.publish("/rover/ultrasonic", {"range": 3.0})
        pause.wait(period)


def test_a_violation_is_acted_on_in_the_publishing_thread(live) -> None:  # type: ignore[no-untyped-def]
    bus, m, actuator = live
    nominal(bus)
    assert wait_for(lambda: m.analyzer.evaluator.state("G1").status is True)
    decided = m.knowledge.decisions_written
    bus.publish("/utu/oracle/output", {"category": 1, "confidence": 0.97})
    # The reaction ran inside publish(): the action is there the moment it returns, made
    # in this very thread, although the manager's own time-driven step comes every 0.5 s.
    assert actuator.threads == [threading.get_ident()]
    assert actuator.calls[0] == ("request", "/rover/set_mode", {"mode": "manual"})
    kinds = [d.kind for d in m.knowledge.decisions()][decided:]
    assert kinds[:3] == ["selected", "started", "action"]


def test_nominal_traffic_decides_nothing_and_keeps_rates(live) -> None:  # type: ignore[no-untyped-def]
    bus, m, actuator = live
    nominal(bus, n=8)
    assert wait_for(lambda: m.analyzer.evaluator.state("G1").status is True)
    before = m.knowledge.decisions_written
    # A burst far faster than the time-driven rate: every input keeps its own arrival
    # time, so rate(A3) stays known and nothing fires.
    for k in range(2000):
        bus.publish("/rover/ultrasonic", {"range": 3.0 + (k % 7) * 0.01})
        if k % 50 == 0:
            for topic, msg in NOMINAL.items():
                bus.publish(topic, msg)
    assert wait_for(lambda: not any(q.pending for q in m.input_queues()))
    m.wake()
    # The inputs a step took at once share its instant; the rate is measured over the time
    # since then (anunnaki.goals RateEstimator): known again by the next step at the latest.
    assert wait_for(lambda: m.analyzer.evaluator.value("rate(A3)") is not None, 2.0)
    assert m.knowledge.decisions_written == before
    assert actuator.calls == []


def test_nodes_react_on_arrival_not_on_their_rate(tmp_path: Path) -> None:
    """Five nodes at 0.5 Hz each: a violation still reaches the action at once."""
    cfg = parse_config(
        f"anunnaki: utu/1\nname: rover\ngoal_model: {ROVER}/goals.yaml\n"
        f"binding: {ROVER}/binding.yaml\ntactics: {ROVER}/tactics.xml\n"
        f"failsafe: fail-safe\nwarmup: 1.0\nknowledge: {tmp_path}/kb.db\n"
    )
    actuator = ThreadActuator()
    states: list[dict[str, Any]] = []
    with open_bus("inproc") as bus:
        bus.subscribe("/utu/analyze/state", lambda s: states.append(s.message.to_body()))
        kb = Knowledge(cfg.knowledge)
        nodes = []
        for name in NODE_NAMES:
            kw: dict[str, Any] = {"actuator": actuator} if name == "execute" else {}
            nodes.append(build_node(name, cfg, bus=bus, knowledge=kb, rate=0.5, **kw))
        stop = threading.Event()
        threads = [threading.Thread(target=n.spin, args=(stop,), daemon=True) for n in nodes]
        for th in threads:
            th.start()
        try:
            nominal(bus, n=15)
            assert wait_for(lambda: bool(states) and states[-1]["nodes"]["G1"][1] == "satisfied")
            calls = len(actuator.calls)
            start = time.monotonic()
            bus.publish("/utu/oracle/output", {"category": 1, "confidence": 0.97})
            assert wait_for(lambda: len(actuator.calls) > calls, timeout=10.0)
            # A rate-gated pipeline would wait for a 2 s tick at each node; event-driven, not.
            assert time.monotonic() - start < 1.5
            assert actuator.calls[calls] == ("request", "/rover/set_mode", {"mode": "manual"})
        finally:
            stop.set()
            for n in nodes:
                n.wake()
            for th in threads:
                th.join(5.0)
            for n in nodes:
                n.close()
            kb.close()


def test_forged_and_malformed_cycle_messages_are_dropped_at_the_boundary(tmp_path: Path) -> None:
    cfg = parse_config(
        f"anunnaki: utu/1\nname: rover\ngoal_model: {ROVER}/goals.yaml\n"
        f"binding: {ROVER}/binding.yaml\ntactics: {ROVER}/tactics.xml\n"
        f"failsafe: fail-safe\nknowledge: {tmp_path}/kb.db\n"
    )
    with open_bus("inproc") as bus, open_bus("inproc", hub=bus.hub) as attacker:
        kb = Knowledge(cfg.knowledge)
        analyze = build_node("analyze", cfg, bus=bus, knowledge=kb, pace=False)
        execute = build_node("execute", cfg, bus=bus, knowledge=kb, expect_plan=False)
        try:
            attacker.publish("/utu/monitor/input", {"seq": 1, "t": 1e12, "inputs": "x"})
            attacker.publish("/utu/analyze/state", {"t": 5.0, "eligible": ["fail-safe"]})
            attacker.publish("/utu/execute/status", {"nonsense": True})
            assert analyze.step() is True  # a cycle on its own clock; the forgery is gone
            execute.step()  # executes analyze's own (valid) cycle only
            assert analyze.stage.now < 1e12
            assert bus.stats().totals()["malformed"] >= 2
            assert [d.kind for d in kb.decisions()] == []
            # A well-formed batch from anyone but the monitor node is refused (issue #12) ...
            pause = [{"op": "pause", "caller": "op"}]
            attacker.publish(
                "/utu/monitor/input", MonitorBatch(origin="mon", seq=1, t=2.0, ops=pause)
            )
            assert analyze.step() is True
            execute.step()
            assert [d.kind for d in kb.decisions()] == [] and analyze.foreign == 1
            # ... and one from the monitor node (its readiness names its origin) goes through.
            bus.service("/utu/monitor/ready", lambda m: {"ready": True, "origin": "mon"})
            attacker.publish(
                "/utu/monitor/input", MonitorBatch(origin="mon", seq=2, t=2.0, ops=pause)
            )
            assert analyze.step() is True
            assert execute.step() is True
            assert [d.kind for d in kb.decisions()] == ["paused"]
            state = AnalysisState.model_validate({"t": 1.0, "root": "G1"})
            assert not state.is_cycle  # a display update is never taken for a cycle
        finally:
            execute.close()
            analyze.close()
            kb.close()


def test_a_service_handler_that_publishes_does_not_react_inline(live) -> None:  # type: ignore[no-untyped-def]
    """A handler publishing a monitored topic hands the step to the spinning thread.

    (A step in the handler's thread could request that very service and wait on itself.)
    """
    bus, m, actuator = live
    nominal(bus)
    assert wait_for(lambda: m.analyzer.evaluator.state("G1").status is True)

    handler_threads: list[int] = []

    def handler(request: Any) -> dict[str, Any]:
        handler_threads.append(threading.get_ident())
        bus.publish("/utu/oracle/output", {"category": 1, "confidence": 0.97})
        return {"ok": True}

    bus.service("/test/trigger", handler)
    assert bus.request("/test/trigger", {}, timeout=2.0).to_body()["ok"] is True
    assert wait_for(lambda: bool(actuator.threads))
    assert actuator.threads[0] not in (handler_threads[0], threading.get_ident())


def test_a_live_run_that_ends_normally_replays_without_a_cut_step(tmp_path: Path) -> None:
    """Issue 21: ``anunnaki replay`` of a run that ended normally said ``the log ends
    mid-step … (the run was killed?)``: the inputs of the last reactions (which decide
    nothing and leave the step's end to the next time-driven step) had no step end after
    them when the loop stopped. A loop that stops normally ends its step."""
    from anunnaki.utu import replay

    db = tmp_path / "run.db"
    cfg = parse_config(
        f"anunnaki: utu/1\ngoal_model: {ROVER}/goals.yaml\nbinding: {ROVER}/binding.yaml\n"
        f"tactics: {ROVER}/tactics.xml\nknowledge: {db}\nrate: 0.5\nwarmup: 2.0\n"
    )
    with open_bus("inproc") as bus:
        m = AutonomicManager.from_config(cfg, bus=bus, actuator=RecordingActuator())
        stop = threading.Event()
        spinner = threading.Thread(target=m.spin, args=(stop,), daemon=True)
        spinner.start()
        try:
            nominal(bus, n=4, period=0.02)  # reactions; the time-driven step is 2 s away
            assert wait_for(lambda: not any(q.pending for q in m.input_queues()))
        finally:
            stop.set()
            m.wake()
            spinner.join(5.0)
            m.close()
    report = replay(db)
    assert not [n for n in report.notes if "mid-step" in n], report.notes
    assert report.identical, report.notes


def test_on_an_executor_every_message_is_taken_at_its_instant() -> None:
    """``run_on(executor)``: Utu steps in the executor's drain, once at each new instant.

    The race this replaces: a message that came while the spinning thread held the step was
    left for that thread's next round; a simulation that had moved its clock on meanwhile
    had it stamped an instant late (a 10 Hz GPS then looked slower than 10 Hz, and the UAV
    hovered before take-off). On the executor nothing runs in between: the message is taken
    in the drain of the instant that published it, and the step at the next instant runs
    in that instant's drain.
    """
    model = parse_goal_model(
        (ROVER / "goals.yaml").read_text(), binding=load_binding(ROVER / "binding.yaml")
    )
    clock = SimClock()
    executor = Executor()
    with open_bus("inproc", executor=executor) as bus:
        m = AutonomicManager(
            model,
            load_tactics(ROVER / "tactics.xml"),
            bus=bus,
            actuator=RecordingActuator(),
            clock=clock,
            failsafe="fail-safe",
            warmup=2.0,
            rate=20.0,
        )
        threads = threading.active_count()
        detach = m.run_on(executor)
        try:
            bus.publish("/clock", Clock(time=1.0))
            executor.spin_until_idle()
            assert m.now == 1.0  # a step at the present instant, in the drain
            bus.publish("/rover/ultrasonic", {"range": 3.0})
            assert m.monitor.snapshot(m.now)["/rover/ultrasonic"]["count"] == 0  # not yet
            executor.spin_until_idle()
            ultrasonic = m.monitor.snapshot(m.now)["/rover/ultrasonic"]
            assert ultrasonic["count"] == 1 and ultrasonic["last_t"] == 1.0  # this instant's
            bus.publish("/clock", Clock(time=1.025))  # the simulation moves on
            executor.spin_until_idle()
            assert m.now == 1.025
            assert executor.spin_until_idle() == 0  # nothing left: no step without a cause
            assert threading.active_count() == threads  # no thread of the manager's ran
        finally:
            detach()
            m.close()
