"""Managed systems: what Utu adapts.

* :class:`ScriptedSystem` — replays a trace onto the bus and obeys mode changes, run-stop
  and buzzer commands; the stand-in robot of tests and examples.

The simulated rover and UAV (pybullet) will live here too, with the same topics and
services (guideline H1).
"""

from anunnaki.managed.scripted import ScriptedSystem

__all__ = ["ScriptedSystem"]
