"""One definition of a topic's freshness: the evaluator, Utu's Monitor and displays agree."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from anunnaki.goals import RateEstimator, TopicFreshness, is_stale, load_goal_model
from anunnaki.tactics import TacticSet
from anunnaki.utu import AutonomicManager, RecordingActuator

ROVER = Path(__file__).parents[2] / "examples" / "rover"


def test_stale_strictly_after_the_deadline() -> None:
    assert is_stale(None, 0.0, 1.0)
    assert not is_stale(10.0, 11.0, 1.0)  # exactly the staleness ago still counts
    assert is_stale(10.0, 11.0001, 1.0)
    f = TopicFreshness(0.5)
    assert f.stale(0.0) and f.deadline() is None and f.rate(0.0) is None
    f.arrive(2.0)
    assert not f.stale(2.5) and f.stale(2.6) and f.deadline() == 2.5 and f.count == 1


def test_rate_is_n_over_span_and_decays_through_a_silence() -> None:
    r = RateEstimator(window=4)
    for k in range(10):
        r.arrive(k * 0.2)  # 5 Hz
    assert r.rate(1.8) == pytest.approx(5.0)
    assert r.rate(2.0) == pytest.approx(5.0)  # within the mean interval: no decay
    assert r.rate(3.0) == pytest.approx(4 / (0.8 + 1.2 - 0.2))  # the open gap counts
    assert r.in_gap(3.0) and not r.in_gap(1.9)


@given(st.lists(st.floats(0.001, 1.0), min_size=2, max_size=40), st.floats(0.0, 5.0))
def test_rate_is_positive_and_never_rises_while_silent(gaps: list[float], silence: float) -> None:
    r = RateEstimator(window=10)
    t = 0.0
    for g in gaps:
        t += g
        r.arrive(t)
    now = r.rate(t)
    later = r.rate(t + silence)
    assert now is not None and later is not None
    assert 0 < later <= now + 1e-9


def test_arrivals_stamped_at_one_instant_give_a_rate_once_time_passes() -> None:
    # A backlog a step takes at once is stamped at that step's instant: the rate is the
    # arrivals over the time since then (it was unknown until ten new arrivals spread out).
    r = RateEstimator(window=10)
    for _ in range(11):
        r.arrive(5.0)
    assert r.rate(5.0) is None  # no time has passed: unknown
    assert r.rate(5.5) == pytest.approx(10 / 0.5)
    assert r.rate(7.0) == pytest.approx(10 / 2.0)  # and it decays through a silence


def test_the_monitor_and_the_goal_model_see_the_same_rate() -> None:
    model = load_goal_model(ROVER / "goals.yaml", binding=ROVER / "binding.yaml")
    m = AutonomicManager(model, TacticSet(tactics=[]), actuator=RecordingActuator())
    try:
        t = 0.0
        for k in range(30):
            t = k * 0.21  # 4.76 Hz: G6's RELAX-ed range
            m.feed("/rover/ultrasonic", {"range": 3.0}, t=t)
        m.step(t)
        m.step(t + 0.9)  # a silence: both decay alike
        shown = m.snapshot()["monitor"]["/rover/ultrasonic"]["rate"]
        judged = m.analyzer.evaluator.value("rate(A3)")
        assert shown == pytest.approx(judged) and 0 < judged < 4.76
    finally:
        m.close()


def test_the_dashboard_shows_the_rate_the_goal_model_judges() -> None:
    from anunnaki.dashboard import DashboardState

    model = load_goal_model(ROVER / "goals.yaml", binding=ROVER / "binding.yaml")
    state = DashboardState(model, TacticSet(tactics=[]), clock=lambda: 0.0)
    t = 0.0
    for k in range(30):
        t = k * 0.21
        state.take_input("/rover/ultrasonic", {"range": 3.0}, t=t)
    m = AutonomicManager(model, TacticSet(tactics=[]), actuator=RecordingActuator())
    try:
        for k in range(30):
            m.feed("/rover/ultrasonic", {"range": 3.0}, t=k * 0.21)
        m.step(t)
        m_eval = m.analyzer.evaluator.value("rate(A3)")
    finally:
        m.close()
    rows = {r["topic"]: r for r in state.snapshot()["monitor"]}
    ev = rows["/rover/ultrasonic"]
    assert ev["rate"] == pytest.approx(m_eval) and ev["stale"] is False
