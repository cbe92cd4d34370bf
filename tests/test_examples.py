"""The examples are tests: both check clean, and their traces go through the phases they claim."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from anunnaki.check import check_files
from anunnaki.cli.main import main
from anunnaki.goals import Evaluator, load_binding, load_goal_model, parse_goal_model
from anunnaki.trace import Phase, Record, read_trace

ROOT = Path(__file__).parents[1]
EXAMPLES = ROOT / "examples"


@pytest.mark.parametrize(
    ("name", "tactics"),
    [("rover", "tactics.xml"), ("rover", "tactics.yaml"), ("uav", "tactics.yaml")],
)
def test_examples_check_clean(name: str, tactics: str) -> None:
    d = EXAMPLES / name
    result = check_files(d / "goals.yaml", d / "binding.yaml", d / tactics)
    assert [f.render() for f in result.findings] == []
    assert result.exit_code == 0


@pytest.mark.parametrize("tactics", ["tactics.xml", "tactics.yaml"])
@pytest.mark.parametrize("binding", ["binding.yaml", "binding-ros.yaml"])
def test_rover_tactics_check_unchanged_against_either_binding(tactics: str, binding: str) -> None:
    """The tactics name logical endpoints (set_mode, stop, buzzer) that each binding maps."""
    d = EXAMPLES / "rover"
    result = check_files(d / "goals.yaml", d / binding, d / tactics)
    assert [f.render() for f in result.findings] == []
    model = result.model
    assert model is not None
    where = {"binding.yaml": "/rover/set_mode", "binding-ros.yaml": "/rover/controller/set_mode"}
    assert model.endpoint_name("set_mode") == where[binding]
    assert model.endpoint_name("/rover/anything") == "/rover/anything"


def test_rover_goal_model_serves_another_platform_by_swapping_the_binding() -> None:
    d = EXAMPLES / "rover"
    result = check_files(d / "goals.yaml", d / "binding-ros.yaml")
    assert result.exit_code == 0
    model = load_goal_model(d / "goals.yaml", d / "binding-ros.yaml")
    ev = Evaluator(model)
    ev.observe("/rover/controller/state", {"control_mode": "manual", "buzzer_on": True}, 0.0)
    assert ev.value("A1.mode") == "manual"
    assert ev.state("G11").status is True


@pytest.mark.parametrize("name", ["rover", "uav"])
def test_committed_traces_match_their_generators(name: str, tmp_path: Path) -> None:
    script = EXAMPLES / name / "make_trace.py"
    copy = tmp_path / "make_trace.py"
    copy.write_text(script.read_text().replace("parents[2]", f"parents[0] / {str(ROOT)!r}"))
    subprocess.run([sys.executable, str(copy)], check=True, capture_output=True)
    assert (tmp_path / "trace.jsonl").read_text() == (EXAMPLES / name / "trace.jsonl").read_text()


def replay(model_text: str | None, name: str) -> dict[str, dict[str, str | None]]:
    """Replay an example's trace; return each phase's goal statuses at its end."""
    d = EXAMPLES / name
    binding = load_binding(d / "binding.yaml")
    text = model_text if model_text is not None else (d / "goals.yaml").read_text()
    ev = Evaluator(parse_goal_model(text, binding=binding))
    out: dict[str, dict[str, str | None]] = {}
    phase = None
    for item in read_trace(d / "trace.jsonl").items:
        ev.tick(item.t)
        if isinstance(item, Phase):
            if phase:
                out[phase] = {n: ev.state(n).status_name for n in ev.ids}
            phase = item.phase
            continue
        assert isinstance(item, Record)
        ev.observe(item.topic, item.msg, item.t)
    assert phase is not None
    ev.tick(item.t)
    out[phase] = {n: ev.state(n).status_name for n in ev.ids}
    return out


def test_rover_trace_phases() -> None:
    phases = replay(None, "rover")
    assert phases["nominal"]["G1"] == "satisfied"
    # 4.8 Hz: the RELAX-ed G6 holds (utility 0.6 >= 0.5)
    assert phases["ultrasonic-4.8Hz"]["G6"] == "satisfied"
    assert phases["ultrasonic-4.8Hz"]["G1"] == "satisfied"
    assert phases["pedestrian-near"]["G13"] == "unsatisfied"
    assert phases["pedestrian-near"]["G12"] == "satisfied"  # the buzzer warns
    # category 1: O1 holds, G4, G3, G2 and G1 fail
    dim = phases["dim-light"]
    assert dim["O1"] == "satisfied"  # an obstacle's status says it holds
    assert [dim[g] for g in ("G4", "G3", "G2", "G1")] == ["unsatisfied"] * 4
    # manual mode: G3 holds through G11 while the category stays 1
    manual = phases["manual"]
    assert manual["O1"] == "satisfied"
    assert manual["G11"] == manual["G3"] == manual["G1"] == "satisfied"
    # silence: stale range -> unknown, rate decays -> G6 violated
    silent = phases["ultrasonic-silent"]
    assert silent["G13"] == "unknown"
    assert silent["G6"] == "unsatisfied"
    assert silent["G1"] == "unknown"


def test_rover_trace_against_a_crisp_g6_violates_it() -> None:
    text = (EXAMPLES / "rover" / "goals.yaml").read_text()
    crisp = text.replace(
        "    utility: rate(A3)\n    relax: {operator: as_close_as_possible_to_frequency, "
        "target: 5.0, tolerance: 0.5, side: at_least, unit: Hz}\n    threshold: 0.5\n",
        "    utility: rate(A3) >= 5.0\n",
    )
    assert crisp != text
    phases = replay(crisp, "rover")
    assert phases["ultrasonic-4.8Hz"]["G6"] == "unsatisfied"
    assert phases["ultrasonic-4.8Hz"]["G1"] == "unsatisfied"


def test_uav_trace_phases() -> None:
    phases = replay(None, "uav")
    assert phases["nominal"]["G1"] == "satisfied"
    assert phases["gusts"]["G3"] == "satisfied"  # 34 m at the end: relaxed utility 0.6
    assert phases["fog"]["O1"] == "satisfied"  # the obstacle holds...
    assert phases["fog"]["G9"] == "satisfied"  # ...but the fog model resolves it
    assert phases["fog"]["G6"] == "satisfied"
    assert phases["dense-fog"]["G6"] == "unsatisfied"
    assert phases["dense-fog"]["G1"] == "unsatisfied"
    assert phases["failsafe-f1"]["G5"] == "satisfied"
    assert phases["low-battery"]["O2"] == "satisfied"
    assert phases["low-battery"]["G8"] == "unsatisfied"
    assert phases["return-home"]["G8"] == "satisfied"
    assert phases["return-home"]["G1"] == "satisfied"


def test_uav_gust_at_36_m_violates_the_relaxed_altitude_goal() -> None:
    d = EXAMPLES / "uav"
    ev = Evaluator(load_goal_model(d / "goals.yaml", d / "binding.yaml"))
    ev.observe("/uav/status", {"mode": "auto", "altitude": 36.0}, 0.0)
    assert ev.state("G3").utility == pytest.approx(0.4)
    assert ev.state("G3").status is False
    ev.observe("/uav/status", {"mode": "auto", "altitude": 34.0}, 0.5)
    assert ev.state("G3").utility == pytest.approx(0.6)
    assert ev.state("G3").status is True


def test_evaluate_json_output_follows_the_phases(capsys: pytest.CaptureFixture[str]) -> None:
    d = EXAMPLES / "rover"
    code = main(
        [
            "evaluate",
            str(d / "goals.yaml"),
            "-b",
            str(d / "binding.yaml"),
            "-t",
            str(d / "trace.jsonl"),
            "--json",
            "--explain",
            "G1",
        ]
    )
    assert code == 0
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    summary = lines[-1]["summary"]
    assert [row["root"] for row in summary] == [
        "satisfied",
        "satisfied",
        "satisfied",
        "unsatisfied",
        "satisfied",
        "unknown",
    ]
    violation = next(x for x in lines[:-1] if x["nodes"]["G1"]["status"] == "unsatisfied")
    assert violation["t"] == 25.0
    assert violation["phase"] == "dim-light"
    assert violation["explanation"]["leaves"]["A4.category"] == 1


def test_uav_g3_applies_while_cruising_not_on_the_ground_or_in_the_climb() -> None:
    """G13 = G3 OR G14: at 0 m on the ground and in the climb the route goal G2 holds (the
    take-off is not a violation), while cruising at 0 m or 12 m it does not."""
    d = EXAMPLES / "uav"
    ev = Evaluator(load_goal_model(d / "goals.yaml", d / "binding.yaml"))
    for k in range(11):  # GPS at 10 Hz, so that G4 holds
        ev.observe("/uav/gps", {"lat": 42.7, "lon": -84.4}, k / 10)
    status = {"mode": "auto", "delivered": False}
    for t, altitude, phase, g13 in [
        (1.0, 0.0, "takeoff", True),
        (1.1, 12.0, "takeoff", True),
        (1.2, 12.0, "hover", True),
        (1.3, 12.0, "waypoint 1", False),
        (1.4, 30.0, "waypoint 1", True),
        (1.5, 10.0, "deliver", True),
        (1.6, 0.0, "landed", True),
    ]:
        ev.observe("/uav/status", {**status, "altitude": altitude, "phase": phase}, t)
        assert ev.state("G3").status is (abs(altitude - 30.0) <= 5.0), (t, phase)
        assert ev.state("G13").status is g13, (t, phase)
        assert ev.state("G2").status is g13, (t, phase)


def test_uav_g9_holds_for_the_model_of_the_perceived_condition() -> None:
    """G9 (O1's resolution): the active model's domain is the oracle's context, a
    composition's domain named as an identifier (context rain+brightness, domain
    rain_brightness), and the oracle does not call the model compromised."""
    d = EXAMPLES / "uav"
    ev = Evaluator(load_goal_model(d / "goals.yaml", d / "binding.yaml"))
    oracle, active = "/utu/oracle/output", "/lm_manager/active"
    for t, (context, category, model, domain, g9) in enumerate(
        [
            ("fog", 1, "uav-fog", "fog", True),
            ("fog", 2, "uav-fog", "fog", False),
            ("rain+brightness", 1, "uav-rain_brightness", "rain_brightness", True),
            ("rain+brightness", 0, "uav-fog", "fog", False),
            ("fog", 0, "uav-rain_brightness", "rain_brightness", False),
        ]
    ):
        ev.observe(
            oracle,
            {"category": category, "confidence": 0.9, "context": {"phenomenon": context}},
            float(t),
        )
        ev.observe(active, {"model": model, "domain": domain}, float(t))
        assert ev.state("G9").status is g9, (context, category, domain)
