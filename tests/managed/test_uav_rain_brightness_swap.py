"""The UAV's rain+brightness swap to the Enki model uav-rain_brightness (issue #23, item 2).

examples/uav's goals, binding and tactics, Utu stepped on simulated time, the LEC node (the
model manager) with the shipped examples/models/uav.yaml, and the real ``enlil`` oracle as
agent A4, reading the camera: frames of a test layout of ``make-dataset uav`` (320x240,
rendered here), clean for the first second, then under a rain+brightness context of
uav-default's Enlil search. The default model's oracle reports the detector degraded under
``rain+brightness``, Utu's swap-to-rain_brightness-model swaps uav-rain_brightness in through
the model manager, and that model's own oracle then finds it nominal. And the oracles of
the domain models (uav-fog, uav-rain_brightness) name both of the UAV's phenomena, so that
the model in use can be swapped for the next condition's (docs/uav.md).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from anunnaki import topics
from anunnaki.bus import open_bus
from anunnaki.enlil import load_oracle
from anunnaki.goals import parse_binding, parse_goal_model
from anunnaki.lec import LecNode, load_registry
from anunnaki.messages import Assessment, Image
from anunnaki.oracles import OracleNode
from anunnaki.phenomena import PHENOMENA
from anunnaki.sim import scene_frames
from anunnaki.tactics import parse_tactics_yaml
from anunnaki.utu import AutonomicManager, Knowledge

ROOT = Path(__file__).parents[2]
UAV = ROOT / "examples" / "uav"
CAMERA = "/uav/camera/image"

#: A context of uav-default's rain+brightness search in scripts/train-domains.sh (evaluation
#: 34, category 1, degraded: F1 0.857, a drop of 0.069): dense short rain streaks, blurred,
#: the rain dimming the scene to 0.81, then gain 1.17 and gamma 1.31 (darker mid-tones).
CONTEXT = {
    "rain.intensity": 0.771, "rain.slant": -0.728, "rain.drop_length": 2.782,
    "rain.drop_width": 3.182, "rain.blur": 14.044, "rain.brightness": 0.806,
    "brightness.gain": 1.168, "brightness.gamma": 1.312,
}  # fmt: skip

#: From this time on the frames are under CONTEXT (simulated seconds, 10 frames a second).
RAIN_AT = 1.0


#: What the UAV publishes of its route (G15's battery forecast at home needs it, and two
#: battery samples: Utu warms up 2 s, as examples/uav/sim.yaml's does).
ROUTE = {"route_m": 400.0, "home_m": 150.0, "cruise_speed": 8.0}


def frames(n: int) -> list[np.ndarray]:
    """*n* frames of test layout 44 (never in any model's or oracle's training)."""
    return [np.asarray(f.image) for f in scene_frames("uav", layout=44, seed=0, n=n,
                                                       width=320, height=240)]  # fmt: skip


def handled(oracle: OracleNode, n: int, timeout: float = 120.0) -> bool:
    """Whether the oracle node has handled (assessed, withheld or failed) ``n`` frames.

    Counted after the assessment went out: by then Utu's queue holds it (the bus's own
    threads deliver here; Utu is stepped by hand, its actions on worker threads).
    """
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        s = oracle.stats()
        if s.assessments + s.withheld + s.errors >= n:
            return True
        time.sleep(0.002)
    return False


@pytest.fixture(scope="module")
def clean() -> list[np.ndarray]:
    return frames(10)


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory, clean: list[np.ndarray]) -> dict[str, Any]:
    tmp = tmp_path_factory.mktemp("uav-rain")
    binding = parse_binding((UAV / "binding.yaml").read_text(), source="binding.yaml")
    goals = parse_goal_model((UAV / "goals.yaml").read_text(), source="goals.yaml", binding=binding)
    tactics = parse_tactics_yaml((UAV / "tactics.yaml").read_text(), source="tactics.yaml")
    registry = load_registry(ROOT / "examples" / "models" / "uav.yaml")
    rain = PHENOMENA.create("rain+brightness")
    seen: list[Assessment] = []
    with (
        open_bus("inproc") as bus,
        LecNode(bus, registry, camera=CAMERA, active_period=None) as node,
        OracleNode(bus, "enlil", camera=CAMERA, models=registry, window=3) as oracle,
        AutonomicManager(
            goals, tactics, bus=bus, knowledge=Knowledge(str(tmp / "k.db")), warmup=2.0
        ) as utu,
    ):
        bus.subscribe(topics.ORACLE_OUTPUT, lambda s: seen.append(s.message), expect=Assessment)
        for k in range(80):  # 8 s of simulated time in steps of 0.1 s
            t = round(k * 0.1, 1)
            if k % 10 == 0:
                bus.publish("/uav/battery", {"level": 90.0})
                bus.publish("/uav/link", {"connected": True})
                node.publish_active()  # the node's 1 Hz announcement, on simulated time
            image = clean[k % len(clean)]
            if t >= RAIN_AT:
                image = rain.apply(image, CONTEXT, seed=k)
            bus.publish(CAMERA, Image.from_array(image, encoding="png", seq=k))
            bus.publish("/uav/camera/info", {"seq": k, "width": 320, "height": 240})
            bus.publish(
                "/uav/status", {"mode": "auto", "altitude": 30.0, "delivered": False, **ROUTE}
            )
            bus.publish("/uav/gps", {"lat": 42.7251, "lon": -84.4791})
            assert handled(oracle, k + 1), f"frame {k} was not assessed"
            utu.step(t)
        decisions = utu.knowledge.decisions(limit=10_000)
        active, swaps = node.active.id, node.stats().swaps
    return {"decisions": decisions, "seen": seen, "active": active, "swaps": swaps}


@pytest.mark.timeout(300)
def test_the_enlil_oracle_reports_rain_brightness_and_utu_swaps_in_its_model(
    run: dict[str, Any],
) -> None:
    decisions, seen = run["decisions"], run["seen"]
    started = [(d.t, d.tactic) for d in decisions if d.kind == "started"]
    assert [tactic for _, tactic in started] == ["swap-to-rain_brightness-model"], started
    assert RAIN_AT <= started[0][0] <= RAIN_AT + 1.0, started
    swap = next(
        d for d in decisions if d.kind == "action" and d.tactic == "swap-to-rain_brightness-model"
    )
    assert swap.data["ok"] is True and swap.data["domain"] == "rain_brightness", swap.data
    assert run["active"] == "uav-rain_brightness" and run["swaps"] == 1
    ok = [d.tactic for d in decisions if d.kind == "postcondition_ok"]
    assert "swap-to-rain_brightness-model" in ok  # G6: the new model's oracle says nominal
    # What started the swap: the default model's own oracle, on the frames it was shown.
    assert {a.assessor for a in seen} == {"enlil"}
    models = [a.model_id for a in seen]
    k = models.index("uav-rain_brightness")
    before = seen[:k]
    assert all(a.category == 0 for a in before if a.frame_seq is not None and a.frame_seq < 10)
    assert any(a.category == 1 and a.context["phenomenon"] == "rain+brightness" for a in before), (
        before
    )
    # From the swap on, the Enki model runs and its own oracle assesses it: nominal.
    assert models[0] == "uav-default" and all(m == "uav-rain_brightness" for m in models[k:])
    after = seen[k + 3 :]  # past the window of 3 frames
    # (Its context is mostly "clear": that oracle, val accuracy 0.73, calls most frames its
    # model copes with clear; docs/robustify.md, "Shipped domain models".)
    assert after and sum(a.category == 0 for a in after) >= 0.8 * len(after), after


#: The share of frames each domain model's oracle must name right, per condition: below
#: what `anunnaki oracle evaluate` measured on the test split (docs/robustify.md, "Shipped
#: domain models": the phenomenon head on random contexts), for ten frames of one context.
NAMED = {"clear": 0.8, "fog": 0.8, "rain+brightness": 0.8}


@pytest.mark.parametrize("model_id", ["uav-fog", "uav-rain_brightness"])
def test_the_domain_models_oracles_name_both_phenomena(
    model_id: str, clean: list[np.ndarray]
) -> None:
    """The shipped oracle of each Enki model on clean frames, the demo's fog (strength 0.7)
    and rain+brightness at strength 0.5: the phenomenon it names. Before these oracles were
    trained on both phenomena, uav-fog's had never seen rain and uav-rain_brightness's had
    never seen fog: the demo could not swap from one domain model to the next. (Under the
    milder CONTEXT above, which its model copes with, uav-rain_brightness's oracle says
    category 0 and mostly ``clear``: G6 holds on the category alone.)"""
    spec = load_registry(ROOT / "examples" / "models" / "uav.yaml").get(model_id)
    assert spec.oracle is not None
    oracle = load_oracle(spec.oracle.file, sha256=spec.oracle.sha256)
    assert set(oracle.card.phenomenon_classes) >= {"fog", "rain+brightness"}
    fog, rain = PHENOMENA.create("fog"), PHENOMENA.create("rain+brightness")
    shown = {
        "clear": clean,
        "fog": [fog.apply(f, fog.strength_params(0.7), seed=k) for k, f in enumerate(clean)],
        "rain+brightness": [
            rain.apply(f, rain.strength_params(0.5), seed=k) for k, f in enumerate(clean)
        ],
    }
    for condition, images in shown.items():
        named = [p.phenomenon for p in oracle.predict(images)]
        share = named.count(condition) / len(named)
        assert share >= NAMED[condition], (model_id, condition, named)
