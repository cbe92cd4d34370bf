"""Failsafe F-1 when no model is trusted: the rover's tactics with the model manager.

examples/rover/tactics-lm.yaml, goals-lm.yaml and binding-enlil.yaml (``make demo``) under
Utu, stepped at the rover's 10 Hz with a scripted rover, model manager and oracle. A raindrop
lands on the lens at 3 s and degrades the default model; ``swap-to-raindrop-model`` swaps in
the raindrop model at once. When that model's own oracle finds it degraded too, no model is
left to try: ``fail-safe-robust-model-degraded`` hands the rover to a human once the alarm
has outlasted G19's tolerance (0.5 s), instead of the fail-safe waiting out the swap's 6 s
deadline; the swap's failure at its deadline then escalates to nothing (the fail-safe's goal
G3 already holds), so the rover is handed over, and the operator e-mailed, once. A raindrop
model its oracle finds nominal keeps the rover autonomous, and a verdict still about the
model the swap replaced does not count against the new one.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from anunnaki.goals import load_goal_model
from anunnaki.tactics import load_tactics
from anunnaki.utu import AutonomicManager, Knowledge, RecordingActuator

ROVER = Path(__file__).resolve().parents[2] / "examples" / "rover"
RATE = 10  # Hz: the rover's camera, sensors and oracle
ONSET = 3.0  # s: the raindrop lands
DEADLINE = 6.0  # s: the swaps' postcondition deadline (tactics-lm.yaml)


@dataclass
class World:
    """The rover, its model manager and the oracle, obeying what Utu asked for."""

    #: Category the oracle gives each model in the raindrop.
    in_rain: dict[str, int]
    #: After a swap, the oracle keeps assessing the replaced model this long (a slow oracle).
    lag: float = 0.0
    mode: str = "autonomous"
    model: str = "rover-default"
    swapped_at: float | None = None
    previous: str = "rover-default"
    decisions: list[tuple[float, str, str | None]] = field(default_factory=list)

    def run(self, until: float) -> tuple[AutonomicManager, RecordingActuator]:
        actuator = RecordingActuator()
        manager = AutonomicManager(
            load_goal_model(ROVER / "goals-lm.yaml", ROVER / "binding-enlil.yaml"),
            load_tactics(ROVER / "tactics-lm.yaml"),
            knowledge=Knowledge(),
            actuator=actuator,
            warmup=1.0,  # as demo.yaml: the sonar's rate and G20 need a few samples
            failsafe="fail-safe",
            run_stop_service="/rover/stop",
            publish_state=False,
        )
        seen = 0
        with manager:
            for i in range(round(until * RATE) + 1):
                t = i / RATE
                for kind, name, payload in actuator.calls[seen:]:
                    if kind == "request" and name == "/rover/set_mode":
                        self.mode = str(payload["mode"])
                    elif kind == "request" and name == "/lm_manager/swap":
                        self.previous, self.swapped_at = self.model, t
                        self.model = f"rover-{payload['domain']}"
                seen = len(actuator.calls)
                self.feed(manager, t, i)
                manager.step(t)
            self.decisions = [(d.t, d.kind, d.tactic) for d in manager.knowledge.decisions()]
        return manager, actuator

    def feed(self, manager: AutonomicManager, t: float, seq: int) -> None:
        status = {"mode": self.mode, "buzzer": False, "bumper": False, "lights": False}
        manager.feed("/rover/status", status, t=t)
        manager.feed("/rover/camera/info", {"seq": seq, "width": 128, "height": 128}, t=t)
        manager.feed("/rover/ultrasonic", {"range": 3.0}, t=t)
        domain = self.model.removeprefix("rover-")
        manager.feed("/lm_manager/active", {"model": self.model, "domain": domain}, t=t)
        assessed = self.model
        if self.swapped_at is not None and t < self.swapped_at + self.lag:
            assessed = self.previous
        raining = t >= ONSET
        verdict = {
            "category": self.in_rain[assessed] if raining else 0,
            "confidence": 0.9,
            "context": {"phenomenon": "raindrop" if raining else "clear"},
            "model_id": assessed,
        }
        manager.feed("/utu/oracle/output", verdict, t=t)

    def started(self, tactic: str) -> list[float]:
        return [t for t, kind, name in self.decisions if kind == "started" and name == tactic]

    def kinds(self, tactic: str) -> list[str]:
        return [kind for _, kind, name in self.decisions if name == tactic]


def mode_requests(actuator: RecordingActuator) -> list[str]:
    return [str(p["mode"]) for k, n, p in actuator.calls if n == "/rover/set_mode"]


def test_a_robust_model_degraded_in_its_own_condition_hands_over_at_once() -> None:
    world = World(in_rain={"rover-default": 2, "rover-raindrop": 2})
    _, actuator = world.run(until=ONSET + DEADLINE + 1.0)
    (swap,) = world.started("swap-to-raindrop-model")
    assert ONSET <= swap < ONSET + 0.2, world.decisions
    (hand_over,) = world.started("fail-safe-robust-model-degraded")
    # G19 tolerates the alarm 0.5 s past G20's 0.25 s window: the hand-over comes then,
    # not at the swap's deadline (6 s after the swap)
    assert swap + 0.5 <= hand_over <= ONSET + 1.0, world.decisions
    assert world.mode == "manual" and mode_requests(actuator) == ["manual"]
    assert "postcondition_ok" in world.kinds("fail-safe-robust-model-degraded")
    # the swap still fails at its deadline (its model never sufficed) ...
    assert "postcondition_failed" in world.kinds("swap-to-raindrop-model")
    # ... and nothing runs the fail-safe again: the rover is handed over, the operator
    # e-mailed, once
    assert world.started("fail-safe") == [], world.decisions
    exhausted = [d for d in world.decisions if d[1] == "escalation_exhausted"]
    assert exhausted == [(swap + DEADLINE, "escalation_exhausted", "swap-to-raindrop-model")]
    mails = [p for k, channel, p in actuator.calls if k == "notify" and channel == "email"]
    assert len(mails) == 1, actuator.calls


def test_a_robust_model_its_oracle_finds_nominal_keeps_the_rover_autonomous() -> None:
    world = World(in_rain={"rover-default": 2, "rover-raindrop": 0})
    _, actuator = world.run(until=ONSET + DEADLINE + 1.0)
    assert len(world.started("swap-to-raindrop-model")) == 1
    assert "postcondition_ok" in world.kinds("swap-to-raindrop-model")
    assert world.started("fail-safe-robust-model-degraded") == []
    assert world.started("fail-safe") == []
    assert world.mode == "autonomous" and mode_requests(actuator) == []


def test_a_verdict_about_the_replaced_model_does_not_hand_over() -> None:
    """An oracle that takes 1.5 s to assess the new model (the ground truth's window does)
    keeps reporting the default model degraded: that is no verdict on the raindrop model."""
    world = World(in_rain={"rover-default": 2, "rover-raindrop": 0}, lag=1.5)
    _, actuator = world.run(until=ONSET + DEADLINE + 1.0)
    assert "postcondition_ok" in world.kinds("swap-to-raindrop-model")
    assert world.started("fail-safe-robust-model-degraded") == []
    assert world.started("fail-safe") == []  # it waits while the swap is in flight
    assert world.mode == "autonomous" and mode_requests(actuator) == []


def test_a_failed_swap_still_escalates_to_the_fail_safe_when_g3_fails() -> None:
    """The robust model degraded, but its oracle never reports on it (lag past the deadline):
    the hand-over is the swap's escalation to the fail-safe at the deadline, as before."""
    world = World(in_rain={"rover-default": 2, "rover-raindrop": 2}, lag=DEADLINE + 1.0)
    _, actuator = world.run(until=ONSET + DEADLINE + 1.0)
    (swap,) = world.started("swap-to-raindrop-model")
    assert world.started("fail-safe-robust-model-degraded") == []
    assert world.started("fail-safe") == [swap + DEADLINE], world.decisions
    assert (swap + DEADLINE, "escalated", "swap-to-raindrop-model") in world.decisions
    assert mode_requests(actuator) == ["manual"]
