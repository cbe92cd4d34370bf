"""The per-phase table of a simulated run, built from synthetic runs (no simulator).

Issue 34: a phase without a ground-truth object has no F1 (its counts are shown instead of
0.00); a UAV's phases end at its touch-down (the time on the ground is a row of its own);
each phase gives the oracle's agreement with its live scorer.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest

from anunnaki.managed import PhaseScore, format_phases, phase_spans, score_phases
from anunnaki.sim import GROUND, load_scenario

ROOT = Path(__file__).parents[2]
UAV_SCENARIO = ROOT / "examples" / "uav" / "demo-scenario.yaml"
ROVER_SCENARIO = ROOT / "examples" / "rover" / "conditions-scenario.yaml"


def rows(table: str) -> list[list[str]]:
    """The table's cells, split at runs of two or more spaces (header first, rule dropped)."""
    import re

    lines = table.splitlines()
    return [re.split(r"\s{2,}", line.strip()) for line in [lines[0], *lines[2:]]]


def test_a_phase_without_ground_truth_has_no_f1_but_its_counts() -> None:
    """The rover's last 2 s: clear, nothing in view, one false positive (issue 34, item 5)."""
    spans = [(0.0, 18.0, "hsl"), (18.0, 20.0, "clear")]
    frames = [(0.1 * k, 2, 0, 1, "rover-hsl") for k in range(180)]
    frames += [(18.0 + 0.1 * k, 0, int(k == 5), 0, "rover-hsl") for k in range(20)]
    hsl, clear = score_phases(spans, frames=frames)
    assert (clear.tp, clear.fp, clear.fn) == (0, 1, 0)
    assert clear.f1 is None  # nothing to find: no F1, and surely not 0
    assert hsl.f1 == pytest.approx(2 * 360 / (2 * 360 + 180))
    assert clear.as_dict() | {"f1": None, "tp": 0, "fp": 1, "fn": 0} == clear.as_dict()
    table = rows(format_phases([hsl, clear]))
    header = table[0]
    cells = dict(zip(header, table[2], strict=True))
    assert cells["F1"] == "–" and cells["TP/FP/FN"] == "0/1/0"
    assert dict(zip(header, table[1], strict=True))["F1"] == "0.80"
    # two objects missed is an F1 of 0, defined
    assert PhaseScore(0, 1, "fog", frames=1, fn=2).f1 == 0.0


def test_a_uav_s_phases_end_at_touch_down() -> None:
    """The UAV demo landed at 49.5 s of a 75-s scenario: its last flying phase ends there."""
    sc = load_scenario(UAV_SCENARIO)
    spans = phase_spans(sc, 75.0, landed=49.5)
    assert spans[-2:] == [(20.0, 49.5, "fog"), (49.5, 75.0, GROUND)]
    assert [label for *_, label in spans[:3]] == ["clear", "rain+brightness", "rain+brightness"]
    assert phase_spans(sc, 75.0)[-1] == (20.0, 75.0, "fog")  # still airborne: no ground row
    assert phase_spans(sc, 30.0, landed=49.5)[-1] == (20.0, 30.0, "fog")  # ran to 30 s only
    rover = load_scenario(ROVER_SCENARIO)
    assert phase_spans(rover, 20.0)[-1] == (18.0, 20.0, "clear")


def test_each_phase_gives_the_oracle_s_agreement_with_the_scorer() -> None:
    spans = [(0.0, 10.0, "clear"), (10.0, 20.0, "fog"), (20.0, 30.0, GROUND)]
    compared = [(0.1 * k, 0, 0) for k in range(100)]  # clear: all agree
    compared += [(10.0 + 0.1 * k, 1, 0 if k % 4 else 1) for k in range(100)]  # fog: 25 %
    decisions = [
        SimpleNamespace(t=10.5, kind="started", tactic="swap-to-fog-model"),
        SimpleNamespace(t=10.5, kind="postcondition_ok", tactic="swap-to-fog-model"),
    ]
    clear, fog, ground = score_phases(
        spans,
        frames=[(0.1 * k, 1, 0, 0, "m") for k in range(300)],
        assessments=[(12.0, 1), (12.1, 1), (13.0, 0)],
        collisions=[15.0],
        decisions=decisions,
        compared=compared,
    )
    assert (clear.agreement, clear.compared) == (1.0, 100)
    assert (fog.agreement, fog.compared) == (0.25, 100)
    assert ground.agreement is None and ground.compared == 0
    assert fog.as_dict()["agreement"] == 0.25 and fog.as_dict()["agreement_frames"] == 100
    assert ground.as_dict()["agreement"] is None
    assert fog.categories == {1: 2, 0: 1} and fog.collisions == 1
    assert fog.tactics == ["swap-to-fog-model (ok)"]
    table = rows(format_phases([clear, fog, ground]))
    agree = [dict(zip(table[0], r, strict=True))["agree"] for r in table[1:]]
    assert agree == ["100% of 100", "25% of 100", "-"]
    # without a scorer the column is left out
    assert "agree" not in format_phases(score_phases(spans, frames=[(1.0, 1, 0, 0, "m")]))


def test_a_phase_under_drops_gives_f1_on_the_visible_boxes() -> None:
    """Issue 33: under a raindrop the table also counts hidden boxes as ignore boxes."""
    spans = [(0.0, 10.0, "clear"), (10.0, 20.0, "raindrop")]
    frames = [(0.1 * k, 2, 0, 0, "m") for k in range(100)]
    frames += [(10.0 + 0.1 * k, 1, 0, 1, "m") for k in range(100)]  # one of two boxes missed
    visible = [(10.0 + 0.1 * k, 1, 0, 0, 1) for k in range(100)]  # ... the hidden one
    clear, drops = score_phases(spans, frames=frames, visible=visible)
    assert clear.f1_visible is None and clear.as_dict()["visible"] is None
    assert drops.f1 == pytest.approx(2 / 3) and drops.f1_visible == 1.0
    assert drops.as_dict()["visible"] == {"frames": 100, "tp": 100, "fp": 0, "fn": 0, "hidden": 100}
    table = rows(format_phases([clear, drops]))
    cells = dict(zip(table[0], table[2], strict=True))
    assert cells["F1"] == "0.67" and cells["F1 visible"] == "1.00"
    assert dict(zip(table[0], table[1], strict=True))["F1 visible"] == "–"
    # no phenomenon with a mask: no column
    assert "F1 visible" not in format_phases(score_phases(spans, frames=frames))


def test_hidden_boxes_move_to_the_ignore_boxes_of_the_frame() -> None:
    import numpy as np

    from anunnaki.managed._sim import _visible_truth

    boxes = np.array([[0, 0, 10, 10], [20, 20, 30, 30]], float)
    t, kept, labels, ignore = _visible_truth(
        (1.0, boxes, ["pedestrian", "deer"], np.zeros((0, 4))), np.array([True, False])
    )
    assert t == 1.0 and labels == ["deer"] and kept.tolist() == [[20, 20, 30, 30]]
    assert ignore.tolist() == [[0, 0, 10, 10]]
