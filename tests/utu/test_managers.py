"""The baseline managers (``anunnaki run --manager none|random``) in place of the planner's choice.

Driven by ``step(now)`` as in test_manager.py: the rover's goal model, three tactics, the
oracle's category turning 1 at t = 1.1 s (the planner then starts ``beep`` and ``hand-over``).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from anunnaki.goals import load_binding, parse_goal_model
from anunnaki.tactics import parse_tactics_yaml
from anunnaki.utu import AutonomicManager, RecordingActuator
from anunnaki.utu.cycle import MANAGERS, baseline

ROVER = Path(__file__).parents[2] / "examples" / "rover"

TACTICS = """\
anunnaki: tactics/1
tactics:
  - name: hand-over
    priority: 10
    preconditions: [{goal: G3, state: unsatisfied}]
    actions: [{type: change_mode, service: /rover/set_mode, mode: manual}]
    postconditions: [{goal: G3, state: satisfied}]
    deadline: 2
  - name: beep
    priority: 50
    preconditions: [{expression: "A4.category >= 1"}]
    actions: [{type: publish, topic: /rover/buzzer, payload: {"on": true}}]
  - name: lights
    priority: 30
    preconditions: [{expression: "A3.range < 0.5"}]
    actions: [{type: publish, topic: /rover/lights, payload: {"on": true}}]
"""


def make(manager: str, seed: int = 0) -> tuple[AutonomicManager, RecordingActuator]:
    binding = load_binding(ROVER / "binding.yaml")
    model = parse_goal_model((ROVER / "goals.yaml").read_text(), binding=binding)
    act = RecordingActuator()
    m = AutonomicManager(model, parse_tactics_yaml(TACTICS), actuator=act, warmup=0.5)
    m.plan_stage.planner.select = baseline(manager, seed)
    return m, act


def drive(m: AutonomicManager, a: float, b: float, category: int) -> None:
    for i in range(round((b - a) / 0.1) + 1):
        t = round(a + i * 0.1, 6)
        m.feed("/rover/status", {"mode": "autonomous", "buzzer": False, "bumper": False})
        m.feed("/rover/camera/info", {"seq": int(t * 10)})
        m.feed("/rover/ultrasonic", {"range": 3.0})
        m.feed("/utu/oracle/output", {"category": category, "confidence": 0.9})
        m.step(t)


def started(m: AutonomicManager) -> list[tuple[float, str | None]]:
    return [(d.t, d.tactic) for d in m.knowledge.decisions() if d.kind == "started"]


def test_utu_is_the_planner_itself() -> None:
    assert baseline("utu") is None
    m, _ = make("utu")
    drive(m, 0, 1.0, 0)
    drive(m, 1.1, 1.5, 1)
    assert [tac for _, tac in started(m)][:2] == ["beep", "hand-over"]


def test_none_starts_nothing_whatever_the_goals_say() -> None:
    m, act = make("none")
    drive(m, 0, 1.0, 0)
    drive(m, 1.1, 3.0, 1)
    assert started(m) == []
    assert act.calls == []
    # the planner's own choices are not the baseline's: none of them is recorded (issue 34)
    assert planners_words(m) == []
    # ... though the planner kept its queue: the goal model was evaluated as with Utu
    queued = {q["tactic"] for q in m.plan_stage.planner.queue() if q["state"] == "queued"}
    assert queued == {"beep", "hand-over"}


def planners_words(m: AutonomicManager) -> list[tuple[str, str | None]]:
    """The planner's own decisions: what it selected, deferred, asked an operator about."""
    own = {"selected", "deferred", "pending_approval", "withdrawn"}
    return [(d.kind, d.tactic) for d in m.knowledge.decisions() if d.kind in own]


def test_a_baseline_asks_no_operator_to_approve() -> None:
    """A tactic that needs approval: Utu asks for it; a baseline, which would not start it, not."""
    text = TACTICS.replace("    priority: 50\n", "    priority: 50\n    requires_approval: true\n")
    for manager, expected in (("utu", [("pending_approval", "beep")]), ("none", [])):
        binding = load_binding(ROVER / "binding.yaml")
        model = parse_goal_model((ROVER / "goals.yaml").read_text(), binding=binding)
        m = AutonomicManager(
            model, parse_tactics_yaml(text), actuator=RecordingActuator(), warmup=0.5
        )
        m.plan_stage.planner.select = baseline(manager)
        drive(m, 0, 1.0, 0)
        drive(m, 1.1, 2.0, 1)
        assert [w for w in planners_words(m) if w[0] == "pending_approval"] == expected, manager
        pending = [q["tactic"] for q in m.plan_stage.planner.queue() if q["state"] == "pending"]
        assert pending == [tactic for _, tactic in expected], manager


def test_random_starts_one_draw_when_the_planner_would_start() -> None:
    m, _ = make("random", seed=1)
    drive(m, 0, 1.0, 0)
    assert started(m) == []  # nothing to decide: no draw either
    drive(m, 1.1, 1.1, 1)
    draws = [d for d in m.knowledge.decisions() if d.kind == "random_draw"]
    assert len(draws) == 1 and draws[0].t == pytest.approx(1.1)
    assert draws[0].data["candidates"] == 3  # any startable tactic, preconditions or not
    assert [tac for _, tac in started(m)] == [draws[0].tactic]
    # the planner's choices it displaced are consumed, not retried at the next step
    assert set(draws[0].data["displaced"]) == {"beep", "hand-over"} - {draws[0].tactic}
    assert planners_words(m) == []  # the draw is the decision; the planner's are not logged


def test_random_is_seeded() -> None:
    def picks(seed: int) -> list[str | None]:
        m, _ = make("random", seed)
        drive(m, 0, 1.0, 0)
        for k in range(6):  # six episodes of the alarm: six decisions
            drive(m, 1.1 + 4 * k, 2.9 + 4 * k, 1)
            drive(m, 3.0 + 4 * k, 5.0 + 4 * k, 0)
        return [d.tactic for d in m.knowledge.decisions() if d.kind == "random_draw"]

    assert picks(3) == picks(3)
    assert any(picks(s) != picks(3) for s in range(4, 10))


def test_an_unknown_manager_is_refused() -> None:
    assert MANAGERS == ("utu", "none", "random")
    with pytest.raises(ValueError, match="unknown manager 'greedy'; managers: utu, none, random"):
        baseline("greedy")
