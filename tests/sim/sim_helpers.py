"""Helpers for the simulation tests: small cameras keep the suite fast."""

from __future__ import annotations

from typing import Any

SMALL_CAMERA = {"rate": 10, "width": 64, "height": 48}


def rover_scenario(**overrides: Any) -> dict[str, Any]:
    """A short, clear route with a small camera."""
    base: dict[str, Any] = {
        "platform": "rover",
        "camera": dict(SMALL_CAMERA),
        "route": [[0, 0], [40, 0]],
    }
    base.update(overrides)
    return base
