"""Tactics name logical endpoints; the manager sends to what the binding maps them to."""

from __future__ import annotations

from pathlib import Path

import pytest

from anunnaki.goals import load_binding, parse_goal_model
from anunnaki.tactics import load_tactics
from anunnaki.utu import AutonomicManager, RecordingActuator

ROVER = Path(__file__).parents[2] / "examples" / "rover"


def ros_feed(m: AutonomicManager, t: float, *, category: int, near: bool) -> None:
    """One tick of the Fig. 13 rover's topics, named and shaped as binding-ros.yaml says."""
    m.feed(
        "/rover/controller/state",
        {"control_mode": "autonomous", "buzzer_on": False, "bumper_pressed": False},
    )
    m.feed("/camera/image_info", {"header": {"seq": round(t * 10)}, "width": 320, "height": 240})
    m.feed("/ultrasonic/range", {"range": 0.5 if near else 3.0})
    m.feed("/utu/oracle/output", {"category": category, "confidence": 0.9})


@pytest.mark.parametrize("tactics", ["tactics.xml", "tactics.yaml"])
def test_the_rover_tactics_act_on_the_ros_rovers_own_endpoints(tactics: str) -> None:
    binding = load_binding(ROVER / "binding-ros.yaml")
    model = parse_goal_model((ROVER / "goals.yaml").read_text(), binding=binding)
    act = RecordingActuator()
    m = AutonomicManager(model, load_tactics(ROVER / tactics), actuator=act, warmup=0.5)
    try:
        for i in range(30):
            t = round(i * 0.1, 6)
            ros_feed(m, t, category=1 if t >= 2.0 else 0, near=1.0 <= t < 1.5)
            m.step(t)
        assert ("publish", "/rover/controller/buzzer", {"on": True}) in act.calls
        assert ("request", "/rover/controller/set_mode", {"mode": "manual"}) in act.calls
        assert all(
            not name.startswith("/rover/") or "/controller/" in name for _, name, _ in act.calls
        )
        sent = [d.data for d in m.knowledge.decisions() if d.kind == "action"]
        assert {"service": "/rover/controller/set_mode", "mode": "manual"}.items() <= next(
            d for d in sent if "mode" in d
        ).items()
    finally:
        m.close()
