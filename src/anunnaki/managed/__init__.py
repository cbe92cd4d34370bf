"""Managed systems: what Utu adapts, each a plugin a launch file names by ``kind``.

* :class:`ScriptedSystem` — replays a trace onto the bus and obeys mode changes, run-stop
  and buzzer commands; the stand-in robot of tests and examples (``kind: scripted``).
* :class:`SimulatedSystem` — a pybullet rover or UAV with its detector (the LEC node) and
  its oracle, in lockstep, scored per phase of its scenario (``kind: sim``; needs the
  ``vision`` extra, imported on first use).

Both publish the same topics and obey the same services (guideline H1), so one goal model
and binding run against either. A launch file picks one with ``managed: {kind: …}``; third
parties add kinds through the ``anunnaki.managed`` entry-point group (see
:mod:`anunnaki.launch`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from anunnaki.managed._scripted import ScriptedSystem

if TYPE_CHECKING:
    from anunnaki.managed._sim import (
        PhaseScore,
        SimulatedSystem,
        format_phases,
        format_scoring,
        scenario_phases,
    )

__all__ = [
    "PhaseScore",
    "ScriptedSystem",
    "SimulatedSystem",
    "format_phases",
    "format_scoring",
    "scenario_phases",
]

_LAZY = {
    "PhaseScore",
    "SimulatedSystem",
    "format_phases",
    "format_scoring",
    "scenario_phases",
}


def __getattr__(name: str) -> Any:
    """The simulated system's names, imported on first use (they need the vision extra)."""
    if name in _LAZY:
        from anunnaki.managed import _sim

        return getattr(_sim, name)
    raise AttributeError(f"module 'anunnaki.managed' has no attribute {name!r}")
