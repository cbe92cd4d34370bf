"""The UAV's fog swap with the shipped Enki model uav-fog (issue #23, item 2).

examples/uav's goals, binding and tactics, Utu stepped on simulated time, and the LEC node
(the model manager) with the shipped examples/models/uav.yaml: the fog swap the UAV's tactic
asks for, which failed while the registry had no fog model, succeeds.
"""

from __future__ import annotations

from pathlib import Path

from anunnaki import topics
from anunnaki.bus import open_bus
from anunnaki.goals import parse_binding, parse_goal_model
from anunnaki.lec import LecNode, load_registry
from anunnaki.messages import Assessment
from anunnaki.tactics import parse_tactics_yaml
from anunnaki.utu import AutonomicManager, Knowledge

ROOT = Path(__file__).parents[2]
UAV = ROOT / "examples" / "uav"


#: What the UAV publishes of its route (G15's battery forecast at home needs it, and two
#: battery samples: Utu warms up 2 s, as examples/uav/sim.yaml's does).
ROUTE = {"route_m": 400.0, "home_m": 150.0, "cruise_speed": 8.0}


def uav_oracle(t: float, domain: str) -> tuple[int, str]:
    """The oracle's (category, context) at t: fog from 5 s, the fog model copes with it."""
    if t < 5.0:
        return 0, "clear"
    return (0 if domain == "fog" else 1), "fog"


def test_a_uav_fog_swap_succeeds(tmp_path: Path) -> None:
    """examples/uav's goals, binding and tactics, Utu stepped on simulated time, the LEC node
    with the shipped examples/models/uav.yaml (real model files, sha256 checked). The
    assessments are published on the oracle's topic by the test (no UAV simulator renders
    the 320x240 frames the UAV's oracle reads): degraded in fog from t = 5 s while the
    default model runs. Utu's swap-to-robust-model swaps the Enki model uav-fog in.
    """
    binding = parse_binding((UAV / "binding.yaml").read_text(), source="binding.yaml")
    goals = parse_goal_model((UAV / "goals.yaml").read_text(), source="goals.yaml", binding=binding)
    tactics = parse_tactics_yaml((UAV / "tactics.yaml").read_text(), source="tactics.yaml")
    registry = load_registry(ROOT / "examples" / "models" / "uav.yaml")
    with (
        open_bus("inproc") as bus,
        LecNode(bus, registry, camera="/uav/camera/image", active_period=None) as node,
        AutonomicManager(
            goals, tactics, bus=bus, knowledge=Knowledge(str(tmp_path / "k.db")), warmup=2.0
        ) as utu,
    ):
        for k in range(150):  # 15 s of simulated time in steps of 0.1 s
            t = round(k * 0.1, 1)
            bus.publish("/uav/camera/info", {"seq": k, "width": 320, "height": 240})
            bus.publish(
                "/uav/status", {"mode": "auto", "altitude": 30.0, "delivered": False, **ROUTE}
            )
            bus.publish("/uav/gps", {"lat": 42.7251, "lon": -84.4791})
            if k % 10 == 0:
                bus.publish("/uav/battery", {"level": 90.0})
                bus.publish("/uav/link", {"connected": True})
                node.publish_active()  # the node's 1 Hz announcement, on simulated time
            if k % 5 == 0:  # the oracle at 2 Hz
                category, context = uav_oracle(t, node.active.domain)
                bus.publish(
                    topics.ORACLE_OUTPUT,
                    Assessment(category=category, confidence=1.0, model_id=node.active.id,
                               context={"phenomenon": context, "params": {}},
                               assessor="script"),
                )  # fmt: skip
            utu.step(t)
        decisions = utu.knowledge.decisions(limit=10_000)
    started = [(d.t, d.tactic) for d in decisions if d.kind == "started"]
    assert [tactic for _, tactic in started] == ["swap-to-robust-model"], started
    assert 5.0 <= started[0][0] <= 5.2
    swap = next(d for d in decisions if d.kind == "action" and d.tactic == "swap-to-robust-model")
    assert swap.data["ok"] is True and swap.data["domain"] == "fog", swap.data
    assert node.active.id == "uav-fog" and node.stats().swaps == 1
    assert "swap-to-robust-model" in [d.tactic for d in decisions if d.kind == "postcondition_ok"]
