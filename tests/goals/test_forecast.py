"""Anticipatory attributes (a binding's ``forecasts:``): the extrapolation, its wiring into the
evaluator, and the errors a bad forecast gets."""

from __future__ import annotations

from pathlib import Path

import pytest

from anunnaki.errors import ModelFileError
from anunnaki.goals import Evaluator, GoalModel, load_goal_model, parse_binding, parse_goal_model
from anunnaki.goals._forecast import Forecaster, forecast

UAV = Path(__file__).parents[2] / "examples" / "uav"

GOALS = """\
anunnaki: goal-model/1
name: power
agents:
  - id: A1
  - id: A3
goals:
  - id: G1
    description: the rest of the route leaves 5 % at its end
    utility: A3.at_end >= 5
    agents: [A3]
"""

BINDING = """\
anunnaki: binding/1
platform: lab
agents:
  A1:
    topics: [{topic: /lab/status, attributes: [route_m, cruise]}]
  A3:
    topics: [{topic: /lab/battery, attributes: [level]}]
    staleness: 3.0
    forecasts:
      at_end: {of: level, window: 4, distance: A1.route_m, speed: A1.cruise}
"""


def model(binding: str = BINDING, goals: str = GOALS) -> GoalModel:
    return parse_goal_model(goals, binding=parse_binding(binding, source="lab.yaml"))


def findings(binding: str) -> list[str]:
    m = parse_goal_model(GOALS, binding=parse_binding(binding, source="lab.yaml"), strict=False)
    return [f.render() for f in m.findings if f.severity == "error"]


# -- the extrapolation -------------------------------------------------------------------------
def test_the_rate_is_the_change_over_the_window_of_samples() -> None:
    f = Forecaster(window=4.0)
    assert f.rate() is None  # no sample
    f.sample(0.0, 50.0)
    assert f.rate() is None  # one instant
    for t, level in [(1.0, 50.0), (2.0, 49.0), (3.0, 47.0), (4.0, 45.0), (5.0, 43.0)]:
        f.sample(t, level)
    # the window holds 1..5 s: (43 - 50) / 4
    assert f.rate() == pytest.approx(-7.0 / 4.0)
    f.sample(6.0, 41.0)  # the window moves on: 2..6 s, (41 - 49) / 4
    assert f.rate() == pytest.approx(-2.0)
    f.sample(6.5, "low")  # not a number: skipped
    f.sample(7.0, True)  # a boolean is no level either
    assert f.samples[-1] == (6.0, 41.0)


def test_the_value_is_the_field_after_distance_over_speed_seconds() -> None:
    assert forecast(40.0, -0.5, 120.0, 6.0) == pytest.approx(30.0)  # 20 s at -0.5 %/s
    f = Forecaster(window=10.0)
    for t in range(6):
        f.sample(float(t), 40.0 - 0.5 * t)
    assert f.value(37.5, 120.0, 6.0) == pytest.approx(27.5)
    assert f.value(37.5, 240.0, 6.0) == pytest.approx(17.5)  # twice as far
    assert f.value(37.5, 120.0, 12.0) == pytest.approx(32.5)  # twice as fast
    assert f.value(37.5, 0.0, 6.0) == pytest.approx(37.5)  # there
    for unknown in [(None, 120.0, 6.0), (37.5, None, 6.0), (37.5, 120.0, None)]:
        assert f.value(*unknown) is None
    assert f.value(37.5, 120.0, 0.0) is None  # a platform standing still reaches nothing


def test_forecasts_are_deterministic_from_the_message_times() -> None:
    """The same messages at the same (simulated) times give the same forecasts, whenever and
    however often the evaluator is ticked in between: nothing reads a wall clock."""

    def run(extra_ticks: bool) -> list[float | None]:
        ev = Evaluator(model())
        out = []
        for k in range(12):
            t = 0.5 * k
            ev.observe("/lab/status", {"route_m": 120.0 - 3.0 * t, "cruise": 6.0}, t)
            if k % 2 == 0:
                ev.observe("/lab/battery", {"level": 40.0 - 0.7 * t}, t)
            if extra_ticks:
                ev.tick(t + 0.25)
            out.append(ev.value("A3.at_end"))
        return out

    first, second = run(False), run(True)
    assert first == second
    assert first[0] is None and first[1] is None  # one battery sample: no rate yet
    assert first[-1] == pytest.approx((40.0 - 0.7 * 5.0) - 0.7 * (120.0 - 3.0 * 5.5) / 6.0)


# -- in the evaluator --------------------------------------------------------------------------
def test_a_goal_reads_the_forecast_and_changes_with_the_distance_left() -> None:
    ev = Evaluator(model())
    for t in range(5):  # 1 %/s drain
        ev.observe("/lab/battery", {"level": 30.0 - t}, float(t))
    ev.observe("/lab/status", {"route_m": 60.0, "cruise": 6.0}, 4.0)  # 10 s left: 26 - 10
    assert ev.value("A3.at_end") == pytest.approx(16.0)
    assert ev.state("G1").status is True
    ev.observe("/lab/status", {"route_m": 150.0, "cruise": 6.0}, 4.1)  # 25 s left: 26 - 25
    assert ev.value("A3.at_end") == pytest.approx(1.0)
    assert ev.state("G1").status is False
    assert "A3.at_end" in ev.values()
    assert "A3.at_end" in ev.explain("G1").render()


def test_a_stale_field_makes_the_forecast_unknown() -> None:
    ev = Evaluator(model())
    ev.observe("/lab/status", {"route_m": 60.0, "cruise": 6.0}, 0.0)
    ev.observe("/lab/battery", {"level": 30.0}, 0.0)
    ev.observe("/lab/battery", {"level": 29.0}, 1.0)
    assert ev.value("A3.at_end") == pytest.approx(19.0)
    ev.tick(4.5)  # the battery silent past its 3 s
    assert ev.value("A3.level") is None and ev.value("A3.at_end") is None
    assert ev.state("G1").status is None


def test_numbers_stand_in_for_distance_and_speed() -> None:
    fixed = BINDING.replace("distance: A1.route_m, speed: A1.cruise", "distance: 60, speed: 6")
    ev = Evaluator(model(fixed))
    ev.observe("/lab/battery", {"level": 30.0}, 0.0)
    ev.observe("/lab/battery", {"level": 28.0}, 2.0)
    assert ev.value("A3.at_end") == pytest.approx(18.0)


def test_the_uav_binding_forecasts_the_battery_at_home() -> None:
    m = load_goal_model(UAV / "goals.yaml", UAV / "binding.yaml")
    assert set(m.agents["A3"].forecasts) == {"after_mission", "after_return"}
    ev = Evaluator(m)
    status = {"mode": "auto", "altitude": 30.0, "delivered": False, "phase": "to delivery"}
    for t in range(6):
        ev.observe("/uav/battery", {"level": 40.0 - 1.2 * t}, float(t))
    ev.observe("/uav/status", {**status, "route_m": 150.0, "home_m": 60.0, "cruise_speed": 6.0}, 5)
    assert ev.value("A3.after_mission") == pytest.approx(34.0 - 1.2 * 25.0)  # 4 %: below 5
    assert ev.value("A3.after_return") == pytest.approx(34.0 - 1.2 * 10.0)
    assert ev.state("G15").status is False and ev.state("G8").status is False
    ev.observe("/uav/status", {**status, "route_m": 120.0, "home_m": 60.0, "cruise_speed": 6.0}, 5)
    assert ev.state("G15").status is True and ev.state("G8").status is True


# -- bad forecasts -----------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            "distance: A1.route_m",
            "distance: A1.route_m + 5",
            "'distance' must be a number or an agent's attribute written Agent.attribute",
        ),
        ("speed: A1.cruise", "speed: 0", "'speed' as a number must be finite and > 0"),
        ("window: 4", "window: 0", "window"),
        ("of: level", "of: A3.level", "of"),
        ("window: 4,", "window: 4, horizon: 3,", "horizon"),
    ],
)
def test_a_malformed_forecast_names_the_file_and_element(old: str, new: str, message: str) -> None:
    bad = BINDING.replace(old, new)
    assert bad != BINDING
    with pytest.raises(ModelFileError) as err:
        parse_binding(bad, source="lab.yaml")
    text = str(err.value)
    assert "lab.yaml:10" in text and "agents.A3.forecasts.at_end" in text and message in text


@pytest.mark.parametrize(
    ("old", "new", "finding"),
    [
        (
            "of: level",
            "of: charge",
            "lab.yaml:10: error: agents.A3.forecasts.at_end.of: forecast 'at_end' extrapolates "
            "'charge', which A3 does not publish (hint: 'of' names one of A3's attributes: level)",
        ),
        (
            "distance: A1.route_m",
            "distance: A9.route_m",
            "lab.yaml:10: error: agents.A3.forecasts.at_end.distance: forecast 'at_end' reads "
            "distance from unknown agent 'A9' (hint: known: A1, A3)",
        ),
        (
            "speed: A1.cruise",
            "speed: A1.speed",
            "lab.yaml:10: error: agents.A3.forecasts.at_end.speed: forecast 'at_end' reads speed "
            "from 'A1.speed', which A1 does not publish (hint: A1 publishes: cruise, route_m (a "
            "forecast reads published attributes, or takes a number))",
        ),
        (
            "at_end: {",
            "level: {",
            "lab.yaml:10: error: agents.A3.forecasts.level.of: forecast 'level' of A3 has the "
            "name of an attribute A3 publishes (hint: rename the forecast, e.g. level_forecast)",
        ),
    ],
)
def test_a_forecast_reading_what_is_not_published_is_an_error(
    old: str, new: str, finding: str
) -> None:
    bad = BINDING.replace(old, new)
    assert bad != BINDING
    assert finding in findings(bad)
    with pytest.raises(ModelFileError):
        parse_goal_model(GOALS, binding=parse_binding(bad, source="lab.yaml"))


def test_a_goal_reading_an_unknown_forecast_names_the_forecasts() -> None:
    goals = GOALS.replace("A3.at_end", "A3.at_home")
    m = parse_goal_model(goals, binding=parse_binding(BINDING, source="lab.yaml"), strict=False)
    rendered = [f.render() for f in m.findings]
    assert any(
        "unknown attribute 'A3.at_home'" in r and "A3 publishes: at_end, level" in r
        for r in rendered
    ), rendered
