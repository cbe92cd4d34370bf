"""Enki's domain models swapped in by the examples' tactics (issue #23, item 2).

Rover: the loop of test_sim_enlil.py (the pybullet rover, the LEC node, the real ``enlil``
oracle reading the camera, Utu with examples/rover/tactics-lm.yaml) with the shipped
registry examples/models/rover.yaml, under a shift of hue and saturation from t = 3 s: the
default model's oracle reports the detector degraded under ``hsl``, Utu swaps in the Enki
model rover-hsl through the model manager, and rover-hsl's own oracle assesses from then on.
"""

from __future__ import annotations

from typing import Any

import pytest
from test_sim_enlil import SCENARIO, run_enlil

from anunnaki.messages import Assessment

#: test_sim_enlil.py's 10 s scene, its hue turned 150 degrees and its colours saturated
#: from t = 3 s (the default model's F1 falls; rover-hsl was fine-tuned for this shift).
HSL_SCENARIO: dict[str, Any] = {
    **SCENARIO,
    "name": "enlil-hsl",
    "phenomena": [
        {"at": 3, "phenomenon": "hsl", "params": {"hue": 150, "saturation": 0.5, "lightness": 0}}
    ],
}


@pytest.fixture(scope="module")
def hsl_run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    return run_enlil(tmp_path_factory.mktemp("enki-hsl"), HSL_SCENARIO)


@pytest.mark.timeout(300)  # as test_sim_enlil.py's run: about 20 s quiet, 100 s shared
def test_the_enlil_oracle_reports_hsl_and_utu_swaps_in_rover_hsl(hsl_run: dict[str, Any]) -> None:
    result, log = hsl_run["result"], hsl_run["log"]
    assert result.exit_code == 0, log
    started = [(d.t, d.tactic) for d in result.decisions if d.kind == "started"]
    swaps = [t for t, tactic in started if tactic == "swap-to-hsl-model"]
    assert len(swaps) == 1 and 3.0 <= swaps[0] < 10.0, started
    swap = next(
        d for d in result.decisions if d.kind == "action" and d.tactic == "swap-to-hsl-model"
    )
    assert swap.data["ok"] is True and swap.data["domain"] == "hsl", swap.data
    ok = [d.tactic for d in result.decisions if d.kind == "postcondition_ok"]
    assert "swap-to-hsl-model" in ok, log  # G9: rover-hsl's oracle says it copes with hsl
    assert ("started", "fail-safe") not in [(d.kind, d.tactic) for d in result.decisions]
    seen: list[Assessment] = hsl_run["assessments"]
    assert {a.assessor for a in seen} == {"enlil"}
    models = [a.model_id for a in seen]
    # What started the swap: the default model's oracle, degraded under hsl, after t = 3 s.
    k = models.index("rover-hsl")
    before = [a for a in seen[:k] if a.frame_seq is not None and a.frame_seq >= 30]
    assert any(a.category >= 1 and a.context["phenomenon"] == "hsl" for a in before), before
    # From the swap on, the Enki model runs and its own oracle assesses it.
    assert models[0] == "rover-default" and all(m == "rover-hsl" for m in models[k:])
    after = seen[k + 3 :]  # past the window of 3 frames
    assert after and sum(a.category == 0 for a in after) >= 0.8 * len(after)
    assert sum(a.context["phenomenon"] == "hsl" for a in after) >= 0.8 * len(after)
