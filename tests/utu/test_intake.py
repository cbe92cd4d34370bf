"""A live step's intake under a flood: a time budget per step (issue #12).

Under a flood a step that took a full queue (1,024 inputs, each recorded and evaluated)
lasted up to 937 ms for a 50 ms period. A live loop now takes from each topic what fits in
half a period at the measured cost of an input; deterministic steps take ``intake``.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from anunnaki.bus import InprocHub, Sample, open_bus
from anunnaki.messages import Clock, Generic
from anunnaki.utu import AutonomicManager, RecordingActuator, parse_config
from anunnaki.utu.host._intake import FIRST, FLOOR, IntakeBudget, SimStamps

ROVER = Path(__file__).parents[2] / "examples" / "rover"


def test_the_limit_follows_the_cost_of_an_input_between_floor_and_ceiling() -> None:
    budget = IntakeBudget(0.025, ceiling=1024, smoothing=1.0)
    assert budget.limit() == FIRST  # nothing measured yet
    budget.spent(64, 0.064)  # 1 ms an input: 25 fit in 25 ms
    assert budget.limit() == 25
    budget.spent(100, 1.0)  # 10 ms an input: 2 would fit, but a topic keeps its floor
    assert budget.limit() == FLOOR
    budget.spent(1000, 0.001)  # cheap again: never above the ceiling
    assert budget.limit() == 1024
    budget.spent(FLOOR - 1, 100.0)  # a small step says little about an input's cost
    assert budget.limit() == 1024
    assert IntakeBudget(0.025, ceiling=8).limit() == 8
    with pytest.raises(ValueError, match="budget must be > 0"):
        IntakeBudget(0.0, ceiling=8)


def test_smoothing_weighs_the_newest_step() -> None:
    budget = IntakeBudget(1.0, ceiling=10_000, smoothing=0.5)
    budget.spent(100, 0.1)  # 1 ms
    budget.spent(100, 0.3)  # 3 ms: the running cost goes half-way, to 2 ms
    assert budget.cost == pytest.approx(0.002)
    assert budget.limit() == 500


class Endless:
    """A monitored topic whose producers refill it as fast as it is emptied."""

    def __init__(self) -> None:
        self.taken = 0

    @property
    def pending(self) -> bool:
        return True

    def try_recv(self) -> Sample:
        self.taken += 1
        msg = Generic(data={"range": 2.0})
        return Sample(
            topic="/rover/ultrasonic", message=msg, sent_at=0.0, sender="x", seq=0, key="k"
        )

    def close(self) -> None:
        pass


def test_a_live_loop_takes_what_fits_its_budget_and_a_driven_step_takes_intake() -> None:
    cfg = parse_config(
        f"anunnaki: utu/1\ngoal_model: {ROVER}/goals.yaml\nbinding: {ROVER}/binding.yaml\n"
        f"tactics: {ROVER}/tactics.xml\nclock: wall\nwarmup: 0.0\n"
    )
    flood = Endless()
    with open_bus("inproc") as bus:
        m = AutonomicManager.from_config(cfg, bus=bus, actuator=RecordingActuator())
        m._pull.subs["/rover/ultrasonic"] = flood
        per_step: list[int] = []
        stop = threading.Event()

        def on_step(_: AutonomicManager) -> None:
            per_step.append(flood.taken - sum(per_step))
            if len(per_step) == 6:
                stop.set()

        try:
            m.spin(stop, on_step=on_step)
            assert per_step[0] == FIRST  # before it knows what an input costs
            assert all(FLOOR <= n <= cfg.intake for n in per_step), per_step
            assert m._budget is not None and m._budget.cost > 0
            before = flood.taken
            m.step()  # driven, not spinning: deterministic, a full ``intake``
            assert flood.taken - before == cfg.intake
        finally:
            m._pull.subs.clear()
            m.close()


# -- simulation time: an input is stamped with the instant it was published in (issue #30) --
def test_sim_stamps_give_the_time_of_the_senders_last_clock_before_a_message() -> None:
    stamps = SimStamps(depth=3, senders=2)
    assert stamps.instant("replay", 5.0) is None  # no /clock heard from it
    for sent_at, t in ((1.0, 10.0), (2.0, 10.5), (3.0, 11.0)):
        stamps.record("replay", sent_at, t)
    assert stamps.instant("replay", 2.5) == 10.5
    assert stamps.instant("replay", 2.0) == 10.5  # published with the clock: its instant
    assert stamps.instant("replay", 9.0) == 11.0  # after the last clock heard
    assert stamps.instant("other", 2.5) is None  # its own clock, not another sender's
    stamps.record("replay", 2.9, 12.0)  # out of order: not kept
    stamps.record("replay", 3.5, 10.0)  # time going back (a looped replay): not kept
    assert stamps.instant("replay", 4.0) == 11.0
    stamps.record("replay", 4.0, 11.5)  # the oldest of depth 3 goes
    assert stamps.instant("replay", 1.5) is None  # before the oldest kept: not known
    stamps.record("a", 5.0, 1.0)
    stamps.record("b", 6.0, 1.0)  # a third sender: the one heard from longest ago goes
    assert stamps.instant("replay", 4.0) is None and stamps.instant("a", 5.0) == 1.0


class Sender:
    """The managed system's bus, with its wall clock (the envelopes' ``sent_at``) in hand."""

    def __init__(self, hub: InprocHub) -> None:
        self.wall = 100.0
        self.bus = open_bus("inproc", hub=hub, name="replay", clock=lambda: self.wall)

    def publish(self, wall: float, topic: str, message: Any) -> None:
        self.wall = wall
        self.bus.publish(topic, message)


SIM_CONFIG = (
    f"anunnaki: utu/1\ngoal_model: {ROVER}/goals.yaml\nbinding: {ROVER}/binding.yaml\n"
    f"tactics: {ROVER}/tactics.xml\nclock: sim\nwarmup: 0.0\n"
)


@pytest.fixture
def live(tmp_path: Path) -> Iterator[tuple[InprocHub, Sender, AutonomicManager]]:
    """A manager on sim time, stepped by hand, and the managed system's bus on its hub."""
    hub = InprocHub()
    rover = Sender(hub)
    cfg = parse_config(SIM_CONFIG + f"knowledge: {tmp_path / 'kb.db'}\n")
    with open_bus("inproc", hub=hub, name="utu") as bus:
        m = AutonomicManager.from_config(cfg, bus=bus, actuator=RecordingActuator())
        try:
            yield hub, rover, m
        finally:
            m.close()
            rover.bus.close()


def ultrasonic(m: AutonomicManager) -> list[tuple[float, float]]:
    return [(r.t, r.msg["range"]) for r in m.knowledge.inputs() if r.topic == "/rover/ultrasonic"]


def test_a_live_step_on_sim_time_stamps_a_late_input_with_its_instant(live) -> None:  # type: ignore[no-untyped-def]
    """An input of t=1.0 taken by the step of t=1.025 is recorded at 1.0, not 1.025.

    Before, a live host on simulation time stamped every input with the time of the step
    that took it: a 4.8 Hz sensor whose samples arrived an instant late looked slower than
    its goal's rate, and the rover failed safe before the light dimmed.
    """
    _, rover, m = live
    rover.publish(100.0, "/clock", Clock(time=1.0))
    m.step()
    rover.publish(100.01, "/rover/ultrasonic", {"range": 3.0})  # t=1.0's, taken late
    rover.publish(100.02, "/clock", Clock(time=1.025))
    rover.publish(100.03, "/rover/ultrasonic", {"range": 3.1})  # t=1.025's
    m.step()
    assert m.now == 1.025
    assert ultrasonic(m) == [(1.0, 3.0), (1.025, 3.1)]


def test_a_late_input_is_stamped_no_earlier_than_the_previous_step(live) -> None:  # type: ignore[no-untyped-def]
    """The stamp stays in [previous step, this step]: an input of t=1.0 taken by the step of
    t=3.0, whose previous step ran at 2.0, is recorded at 2.0 (that step's verdicts stand).
    One whose sender published no ``/clock`` takes the step's time, as before."""
    hub, rover, m = live
    rover.publish(100.0, "/clock", Clock(time=1.0))
    rover.publish(101.0, "/clock", Clock(time=2.0))
    m.step()
    rover.publish(100.5, "/rover/ultrasonic", {"range": 3.0})  # published at t=1.0
    rover.publish(102.0, "/clock", Clock(time=3.0))
    with open_bus("inproc", hub=hub, name="stranger") as stranger:
        stranger.publish("/rover/ultrasonic", {"range": 3.1})
        m.step()
    assert ultrasonic(m) == [(2.0, 3.0), (3.0, 3.1)]


def test_the_monitor_node_stamps_a_late_input_with_its_instant(tmp_path: Path) -> None:
    """The monitor node of a per-node run stamps as the composed manager does."""
    from anunnaki import topics
    from anunnaki.utu.host import build_node

    hub = InprocHub()
    rover = Sender(hub)
    cfg = parse_config(SIM_CONFIG)
    with open_bus("inproc", hub=hub, name="utu") as bus:
        batches = bus.subscribe(topics.MONITOR_INPUT, queue=8)
        node = build_node("monitor", cfg, bus=bus)
        try:
            rover.publish(100.0, "/clock", Clock(time=1.0))
            node.step()
            rover.publish(100.01, "/rover/ultrasonic", {"range": 3.0})  # t=1.0's, taken late
            rover.publish(100.02, "/clock", Clock(time=1.025))
            node.step()
            got = []
            while (sample := batches.try_recv()) is not None:
                got += [(i.t, i.msg["range"]) for i in sample.message.inputs]
        finally:
            node.close()
            rover.bus.close()
    assert got == [(1.0, 3.0)]
