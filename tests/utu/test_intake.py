"""A live step's intake under a flood: a time budget per step (issue #12).

Under a flood a step that took a full queue (1,024 inputs, each recorded and evaluated)
lasted up to 937 ms for a 50 ms period. A live loop now takes from each topic what fits in
half a period at the measured cost of an input; deterministic steps take ``intake``.
"""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from anunnaki.bus import Sample, open_bus
from anunnaki.messages import Generic
from anunnaki.utu import AutonomicManager, RecordingActuator, parse_config
from anunnaki.utu.host._intake import FIRST, FLOOR, IntakeBudget

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
