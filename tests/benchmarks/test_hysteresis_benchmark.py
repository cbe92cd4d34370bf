"""benchmarks/hysteresis.py: its variants are the rover demo edited as documented, and its
measures (swaps, flaps, the way back to the default model) count what they say.

The sweep itself (six variants x 10 seeds of the whole rover demo) is a benchmark, not a
test; here each variant's folder is built and loaded as ``anunnaki run`` would load it, and
the measures are taken from a made-up run.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from bench_helpers import script_module

from anunnaki.check import check_files
from anunnaki.launch import load_launch
from anunnaki.sim import load_scenario

hysteresis = script_module("hysteresis.py", "bench_hysteresis")


def _within(launch: Any, goal: str) -> float:
    spec = launch.parts.model.goals[goal].relax
    return float(spec.within)


def test_a_hold_variant_edits_only_g17s_within(tmp_path: Path) -> None:
    launch_file = hysteresis.prepare("hold-1.5", tmp_path)
    launch = load_launch(launch_file)
    assert _within(launch, "G17") == 1.5
    assert launch.managed.options.shadow is None
    shipped = load_launch(hysteresis.ROOT / "examples" / "rover" / "demo.yaml")
    assert _within(shipped, "G17") == 1.0  # the shipped file untouched (its measured 1 s)


def test_the_shadow_variant_reads_the_default_models_oracle(tmp_path: Path) -> None:
    folder = tmp_path / "x"
    folder.mkdir()
    launch = load_launch(hysteresis.prepare("shadow-1", folder))
    assert _within(launch, "G17") == 1.0
    assert launch.managed.options.shadow == {"name": "enlil", "window": 3, "domain": "default"}
    g17 = launch.parts.model.goals["G17"]
    assert "A7" in g17.utility and g17.agents == ["A7"]
    rover = folder / "rover"
    result = check_files(
        rover / "goals-lm.yaml",
        binding=rover / "binding-shadow.yaml",
        tactics=rover / "tactics-lm.yaml",
    )
    assert not result.errors, result.errors
    back = next(t for t in result.tactics.tactics if t.name == "swap-back-to-default")
    assert any("A7.category == 0" in str(p) for p in back.preconditions)


def test_an_unknown_variant_is_refused(tmp_path: Path) -> None:
    with pytest.raises(SystemExit, match="unknown variant"):
        hysteresis.prepare("wait-3", tmp_path)


@dataclass
class _Decision:
    t: float
    data: dict[str, Any]
    kind: str = "action"


@dataclass
class _Result:
    decisions: list[_Decision] = field(default_factory=list)


def _frame(t: float, model: str, tp: int = 1, fp: int = 0, fn: int = 0) -> dict[str, Any]:
    return {"t": t, "model": model, "tp": tp, "fp": fp, "fn": fn}


def test_measures_count_swaps_flaps_and_the_way_back() -> None:
    scenario = load_scenario(hysteresis.ROOT / "examples" / "rover" / "conditions-scenario.yaml")
    # hsl 8-18 s, fog 24-34 s, raindrop from 40 s (with 1-s ramps): frames every 0.1 s
    frames = []
    for k in range(0, 400):
        t = round(k * 0.1, 1)
        model = "rover-default"
        if 8.5 <= t < 19.0:
            model = "rover-hsl"
        if 24.5 <= t < 36.0:
            model = "rover-fog-enki"
        # the hsl model misses on clear frames: 2 of them after the shift
        frames.append(_frame(t, model, tp=0 if t in (18.2, 18.3) else 1, fn=int(t in (18.2, 18.3))))
    decisions = [
        _Decision(8.5, {"type": "swap_model", "domain": "hsl"}),
        _Decision(19.0, {"type": "swap_model", "domain": "default"}),
        _Decision(24.5, {"type": "swap_model", "domain": "fog"}),
        _Decision(36.0, {"type": "swap_model", "domain": "default"}),
        _Decision(37.0, {"type": "swap_model", "domain": "fog"}),  # undone within 2 s: a flap
        _Decision(37.5, {"type": "change_mode", "mode": "manual"}),  # not a swap
    ]
    out = hysteresis.measure({"frames": frames}, scenario, _Result(decisions))
    assert out["swaps"] == 5 and out["flaps"] == 1
    # clear after the first shift: 18.0-23.9 (hsl model until 19.0) and 34.0-39.9
    assert out["clear_frames"] == 60 + 60
    assert out["clear_robust_frames"] == 10 + 20
    assert out["back_s"] == [1.0, 2.0]
    tp = 120 - 2
    assert out["clear_f1"] == round(2 * tp / (2 * tp + 2), 4)
