"""Helpers of the managed-system tests: the short fog scene the whole-loop tests run."""

from __future__ import annotations

from typing import Any


def fog_scene(name: str, *, duration: float, fog_at: float) -> dict[str, Any]:
    """A rover scenario: no background clutter, a pedestrian crossing 4-5 m ahead and a deer in
    view, and from ``fog_at`` a fog dense enough that the default model's F1 falls to about 0.
    """
    return {
        "anunnaki": "scenario/1",
        "platform": "rover",
        "name": name,
        "layout": 3,
        "background": False,
        "seed": 0,
        "duration": duration,
        "camera": {"rate": 10, "width": 128, "height": 128},
        "route": [[0, 0], [30, 0]],
        "cruise_speed": 0.3,
        "objects": [
            {"kind": "pedestrian", "x": 5.0, "y": -1.5, "walk_to": [5.0, 1.5], "speed": 0.3},
            {"kind": "deer", "x": 7.0, "y": 2.2, "yaw": 1.57},
        ],
        "phenomena": [
            {"at": fog_at, "phenomenon": "fog", "params": {"density": 8, "intensity": 0.3}}
        ],
    }
