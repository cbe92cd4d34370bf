"""The UAV flies on to its delivery point or returns home as the battery forecast says.

The shipped power goal (examples/uav/goals.yaml: G8 = G15 or G10, O2 obstructing G15), the
shipped forecasts (examples/uav/binding.yaml: A3.after_mission) and the shipped
``return-home`` tactic, on a simulated UAV without a detector (a 32 × 32 camera at 2 Hz: the
power decision needs none), flat out (``--speed 0``) and ended at the touch-down
(``--until-landed``). Two missions with the same battery and the same drain differ only in
how far the delivery point is: to the near one the forecast leaves the 5 % reserve at home
and the UAV delivers; to the far one it does not, and the UAV turns home while its battery
still reads far above O2's 20 % — the forecast decided, not the level.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
import yaml

from anunnaki.cli.main import main
from anunnaki.launch import load_launch, run_launch
from anunnaki.managed import DrawsScenarios, SimKind
from anunnaki.messages import body_of
from anunnaki.utu import replay

UAV = Path(__file__).parents[2] / "examples" / "uav"

#: 40 % at take-off, 10 m/s, climbing at 10 m/s to 20 m; from 3 s the battery drains
#: 1.5 %/s more (about 1.8 %/s in flight).
MISSION: dict[str, Any] = {
    "anunnaki": "scenario/1",
    "platform": "uav",
    "name": "power",
    "layout": 0,
    "duration": 60,
    "camera": {"rate": 2, "width": 32, "height": 32},
    "mission": {
        "home": [0, 0],
        "waypoints": [[10, 0]],
        "delivery": [30, 0],
        "cruise_altitude": 20,
        "speed": 10,
        "climb_rate": 10,
        "battery": 40,
        "deliver_time": 1,
    },
    "faults": [{"at": 3, "fault": "battery_drain", "rate": 1.5}],
}


def power_launch(tmp: Path, scenario: dict[str, Any]) -> Path:
    """A launch of the shipped power goal, forecasts and return-home on ``scenario``."""
    goals = yaml.safe_load((UAV / "goals.yaml").read_text())
    keep = {"G8", "G15", "G10", "O2"}
    goals["root"] = "G8"
    goals["goals"] = [g for g in goals["goals"] if g["id"] in keep]
    goals["obstacles"] = [o for o in goals["obstacles"] if o["id"] in keep]
    goals["agents"] = [a for a in goals["agents"] if a["id"] in ("A1", "A3")]
    binding = yaml.safe_load((UAV / "binding.yaml").read_text())
    binding["agents"] = {k: v for k, v in binding["agents"].items() if k in ("A1", "A3")}
    assert "after_mission" in binding["agents"]["A3"]["forecasts"]
    tactics = yaml.safe_load((UAV / "tactics.yaml").read_text())
    tactics["tactics"] = [t for t in tactics["tactics"] if t["name"] == "return-home"]
    launch = {
        "anunnaki": "launch/1",
        "name": "uav-power",
        "utu": {
            "goal_model": "goals.yaml",
            "binding": "binding.yaml",
            "tactics": "tactics.yaml",
            "knowledge": ":memory:",
            "clock": "sim",
            "warmup": 2.0,
            "run_stop": {"service": "/uav/stop"},
        },
        "bus": {"kind": "inproc"},
        "managed": {
            "sim": {"scenario": "scenario.yaml", "models": None, "oracle": None, "report": False}
        },
    }
    for name, doc in [
        ("goals.yaml", goals),
        ("binding.yaml", binding),
        ("tactics.yaml", tactics),
        ("scenario.yaml", scenario),
        ("launch.yaml", launch),
    ]:
        (tmp / name).write_text(yaml.safe_dump(doc, sort_keys=False))
    return tmp / "launch.yaml"


def fly(tmp: Path, delivery: list[float], knowledge: str | None = None) -> dict[str, Any]:
    """One flight to ``delivery``: the report's flight, battery statuses and decisions."""
    scenario = {**MISSION, "mission": {**MISSION["mission"], "delivery": delivery}}
    launch = load_launch(power_launch(tmp, scenario))
    assert isinstance(launch.managed, SimKind)
    launch.managed.with_scenario(until_landed=True)
    launch.managed.with_reports(report=str(tmp / "report.json"), plot=None)
    levels: list[tuple[float, float]] = []

    def attach(bus: Any) -> None:
        def keep(sample: Any) -> None:
            body = body_of(sample.message)
            levels.append((float(body["t"]), float(body["battery"])))

        bus.subscribe("/uav/status", keep, queue=1024)

    result = run_launch(
        launch,
        speed=0,
        handle_signals=False,
        on_bus=attach,
        out=_Quiet(),
        knowledge=knowledge,
        fresh=knowledge is not None,
    )
    report = json.loads((tmp / "report.json").read_text())
    started = [d for d in result.decisions if d.kind == "started"]
    return {"flight": report["flight"], "started": started, "levels": levels, "result": result}


class _Quiet:
    def write(self, text: str) -> int:
        return len(text)

    def flush(self) -> None:
        pass


@pytest.mark.timeout(300)
def test_the_forecast_lets_the_uav_deliver_to_the_near_point(tmp_path: Path) -> None:
    run = fly(tmp_path, [30, 0])
    flight = run["flight"]
    assert run["result"].reason == "the UAV landed"
    assert flight["delivered"] is True
    assert flight["landing"] == "home" and flight["landed_home"] is True
    assert flight["battery_at_landing"] >= 5.0  # the reserve, as forecast
    # no return before the drop (O2 may send it home on the way back: the same path)
    assert all(d.t > flight["delivered_at"] for d in run["started"]), run["started"]


@pytest.mark.timeout(300)
def test_the_forecast_turns_the_uav_home_before_the_far_point(tmp_path: Path) -> None:
    """...and the run's decision log replays it: the forecasts are computed again from the
    recorded inputs (the binding's text is in the log) and give the same decisions."""
    run = fly(tmp_path, [80, 0], knowledge=str(tmp_path / "run.db"))
    flight, started = run["flight"], run["started"]
    assert [d.tactic for d in started] == ["return-home"], started
    turned = started[0].t
    level = [v for t, v in run["levels"] if t <= turned][-1]
    assert level > 25.0  # far above O2's 20 %: the forecast turned it, not the level
    assert flight["delivered"] is False
    assert flight["landing"] == "home" and flight["battery_at_landing"] >= 5.0
    assert flight["landed_xy"] == [0.0, 0.0]
    again = replay(tmp_path / "run.db")
    assert again.identical, again.summary()
    assert again.decisions == again.replayed_decisions >= 4  # selected, started, action, …


@pytest.mark.timeout(300)
def test_run_seed_draws_the_scenario_and_until_landed_ends_at_the_touch_down(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``anunnaki run --seed N --until-landed --report``: the seed draws the drain again (the
    same seed the same flight, another seed another), the run ends at the touch-down, and the
    report has the mission's outcome."""
    varied = {**MISSION, "vary": {"drain": 0.5}}
    launch = power_launch(tmp_path, varied)

    def landed_with(seed: int, name: str) -> dict[str, Any]:
        report = tmp_path / name
        args = ["run", str(launch), "--speed", "0", "--seed", str(seed), "--until-landed"]
        assert main([*args, "--report", str(report)]) == 0
        assert "stopped (the UAV landed)" in capsys.readouterr().out
        return json.loads(report.read_text())["flight"]

    first, again = landed_with(1, "a.json"), landed_with(1, "b.json")
    other = landed_with(2, "c.json")
    assert first == again
    assert first["battery_at_landing"] != other["battery_at_landing"]
    for flight in (first, other):
        assert flight["landing"] in ("home", "elsewhere", "forced")
        assert flight["landed"] is not None and flight["landed_xy"] is not None
        assert flight["track"][-1]["t"] <= flight["landed"] + 0.5  # nothing after it


def test_seed_and_until_landed_need_a_simulated_system(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    launch = load_launch(power_launch(tmp_path, MISSION))
    assert isinstance(launch.managed, DrawsScenarios)
    launch.managed.with_scenario(seed=7, until_landed=True)
    assert launch.managed.options.scenario_seed == 7 and launch.managed.options.until_landed
    launch.managed.with_scenario()  # nothing given: both kept
    assert launch.managed.options.scenario_seed == 7 and launch.managed.options.until_landed
    rover = UAV.parent / "rover" / "utu.yaml"  # a scripted managed system
    assert main(["run", str(rover), "--seed", "3"]) == 2
    assert "--seed and --until-landed need a simulated managed system" in capsys.readouterr().err
    assert main(["run", str(tmp_path / "launch.yaml"), "--seed", "-1"]) == 2
    assert "a seed is 0 or more" in capsys.readouterr().err
