"""Guideline H1: the goal models and bindings of the examples run against the simulators.

Utu (the autonomic manager) monitors the simulated platform through the binding's topics
and commands it through its services, exactly as it does the scripted stand-in. Agents
that other nodes publish (A4 the oracle, A6 the model manager) are fed by the test.
"""

from __future__ import annotations

from pathlib import Path

import yaml
from sim_helpers import rover_scenario

from anunnaki.goals import load_binding, parse_goal_model
from anunnaki.sim import RoverSim, UavSim
from anunnaki.tactics import load_tactics
from anunnaki.utu import AutonomicManager

EXAMPLES = Path(__file__).parents[2] / "examples"
OTHER_NODES = {"/utu/oracle/output", "/lm_manager/active"}


def binding_topics(platform: str) -> set[str]:
    data = yaml.safe_load((EXAMPLES / platform / "binding.yaml").read_text())
    return {t["topic"] for agent in data["agents"].values() for t in agent["topics"]}


def manager_for(platform: str, tactics: str, bus, **kw) -> AutonomicManager:  # type: ignore[no-untyped-def]
    binding = load_binding(EXAMPLES / platform / "binding.yaml")
    model = parse_goal_model((EXAMPLES / platform / "goals.yaml").read_text(), binding=binding)
    return AutonomicManager(model, load_tactics(EXAMPLES / platform / tactics), bus=bus, **kw)


def test_rover_goal_model_runs_against_the_rover_sim(bus) -> None:
    manager = manager_for(
        "rover",
        "tactics.xml",
        bus,
        failsafe="fail-safe",
        run_stop_service="/rover/stop",
        warmup=1.0,
    )
    with RoverSim(bus, rover_scenario(), clear_layout=True) as rover:
        for k in range(40):
            rover.step(0.1)
            category = 0 if k < 25 else 2  # the oracle: fine, then compromised
            bus.publish("/utu/oracle/output", {"category": category, "confidence": 0.9})
            manager.step(rover.t)
            if k == 24:
                assert rover.mode == "autonomous"
                verdicts = {v.node: v.status for v in manager.knowledge.verdicts()}
                assert verdicts.get("G1") == "satisfied", verdicts
        published = set(rover.published)
        assert binding_topics("rover") - OTHER_NODES <= published
        assert rover.mode == "manual"  # the paper's fail-safe tactic, through /rover/set_mode
        assert any(c[1] == "set_mode" for c in rover.commands)
        started = [d.tactic for d in manager.knowledge.decisions() if d.kind == "started"]
        assert started == ["fail-safe"]
    manager.close()


def test_uav_goal_model_runs_against_the_uav_sim(bus) -> None:
    manager = manager_for("uav", "tactics.yaml", bus, failsafe="failsafe-f1", warmup=1.0)
    sc = {
        "platform": "uav",
        "camera": {"rate": 10, "width": 32, "height": 32},
        "mission": {"start_altitude": 30, "speed": 4},
    }
    with UavSim(bus, sc) as uav:
        for k in range(40):
            uav.step(0.1)
            bad = k >= 25
            bus.publish(
                "/utu/oracle/output",
                {"category": 2 if bad else 0, "confidence": 0.9, "context": "fog" if bad else ""},
            )
            bus.publish("/lm_manager/active", {"model": "default", "domain": "default"})
            manager.step(uav.t)
            if k == 24:
                assert uav.mode == "auto"
                verdicts = {v.node: v.status for v in manager.knowledge.verdicts()}
                assert verdicts.get("G5") == "satisfied", verdicts
        assert binding_topics("uav") - OTHER_NODES <= set(uav.published)
        assert uav.mode == "hover"  # Failsafe F-1, through /uav/set_mode
        started = [d.tactic for d in manager.knowledge.decisions() if d.kind == "started"]
        assert "failsafe-f1" in started
    manager.close()
