"""Managed systems: what Utu adapts, every kind in one room, each a plugin named by ``kind``.

A launch file names the system with ``managed: {kind: NAME, …options}``; :data:`MANAGED`
(an :class:`~anunnaki.plugins.Registry`, entry-point group ``anunnaki.managed``) maps the
name to a kind:

* ``scripted`` (:class:`ScriptedKind`) — :class:`ScriptedSystem` replays a trace onto the
  bus and obeys mode changes, run-stop and buzzer commands; the stand-in robot of tests
  and examples;
* ``sim`` (:class:`SimKind`) — :class:`SimulatedSystem`: a pybullet rover or UAV with its
  camera chain, one deterministic program on an executor's bus, scored per phase of its
  scenario (needs the ``vision`` extra, imported on first use);
* ``ros1`` and ``ros2`` — a real robot through the ROS 1 bridge process
  (:mod:`anunnaki.ros1`) or over zenoh (:mod:`anunnaki.ros2`); both are a
  :class:`RobotKind` and differ only in how they reach the robot.

All publish the same topics and obey the same services (guideline H1), so one goal model
and binding run against any of them. **The camera chain** — the LEC node, the oracle node
and a live scorer on one camera topic — is :class:`CameraChain`, used by every kind that
has a camera; an oracle that takes something from the detector's model registry says so
with the hook :class:`TakesModels`.

A kind is a class with ``name``, ``Options`` (a pydantic model of its launch-file keys),
``__init__(options, *, base)``, ``speed``, ``check``, ``notes`` and
``start(ctx) -> ManagedRun`` (:class:`ManagedKind`); optional hooks are Protocols
(:class:`WritesReports`, :class:`ServesModels`). A third party adds one with a module and an
entry point::

    [project.entry-points."anunnaki.managed"]
    my_robot = "my_package.robot:MyRobotKind"

``examples/managed/echo.py`` is a whole kind in 60 lines (docs/architecture.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from anunnaki.managed._camera import CameraChain, TakesModels, check_camera_chain
from anunnaki.managed._kinds import ScriptedKind, SimKind
from anunnaki.managed._robot import Link, RobotConfig, RobotKind
from anunnaki.managed._scripted import ScriptedSystem
from anunnaki.managed._slot import (
    MANAGED,
    DecisionLike,
    DrawsScenarios,
    ManagedContext,
    ManagedKind,
    ManagedRun,
    ServesModels,
    UtuSettings,
    WritesReports,
)

if TYPE_CHECKING:
    from anunnaki.managed._sim import (
        PhaseScore,
        SimulatedSystem,
        format_phases,
        format_scoring,
        phase_spans,
        scenario_phases,
        score_phases,
    )

__all__ = [
    "MANAGED",
    "CameraChain",
    "DecisionLike",
    "DrawsScenarios",
    "Link",
    "ManagedContext",
    "ManagedKind",
    "ManagedRun",
    "PhaseScore",
    "RobotConfig",
    "RobotKind",
    "ScriptedKind",
    "ScriptedSystem",
    "ServesModels",
    "SimKind",
    "SimulatedSystem",
    "TakesModels",
    "UtuSettings",
    "WritesReports",
    "check_camera_chain",
    "format_phases",
    "format_scoring",
    "phase_spans",
    "scenario_phases",
    "score_phases",
]

_LAZY = {
    "PhaseScore",
    "SimulatedSystem",
    "format_phases",
    "format_scoring",
    "phase_spans",
    "scenario_phases",
    "score_phases",
}


def __getattr__(name: str) -> Any:
    """The simulated system's names, imported on first use (they need the vision extra)."""
    if name in _LAZY:
        from anunnaki.managed import _sim

        return getattr(_sim, name)
    raise AttributeError(f"module 'anunnaki.managed' has no attribute {name!r}")
