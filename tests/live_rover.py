"""What a live run of the rover example guarantees, for the tests that run one.

A live run is Utu on threads of its own or in other processes (separate nodes, a zenoh bus,
``--processes``): the scripted replay plays on its clock as ``rosbag play`` does and waits
for no one, and Utu takes what has arrived at each cycle. It stamps each input with the
simulated instant its sender published it in (the last ``/clock`` that sender published
before it), kept within the cycle that takes it and the one before. The same decisions
come in the same order, but a cycle can still come late, under load, and then decide late.

On threads in one process an input is never stamped late (the bus delivers in publication
order), so no decision comes before the deterministic run's. Across processes one can: the
replay's ``/clock`` travels at high priority and may overtake a sensor's message of an
earlier instant, and the monitor's cycle at the later time then comes first; from t=10 the
ultrasonic's 4.8 Hz leaves the rover's G6 20 ms of slack per 10 samples, so an input stamped
one instant late reads as a violation and the fail-safe may come before the light dims at
t=25. Under load a goal can also go unknown for a moment, and the planner chooses a tactic
again in its cooldown and defers it, which changes nothing.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

#: A live run replays at this speed: a simulated second is then a tenth of a wall second,
#: enough for five processes on a loaded 2-CPU machine (at 50× they fall behind).
LIVE_SPEED = 10.0
#: How long, in simulated seconds, a live Utu may take longer than the deterministic run to
#: decide: the fail-safe's own deadline.
LIVE_LAG = 5.0


def live_decisions(decisions: Sequence[Any]) -> list[Any]:
    """A live run's decisions, less a tactic chosen again in its cooldown (and deferred)."""
    out: list[Any] = []
    for d in decisions:
        again = bool(out) and (out[-1].kind, out[-1].tactic) == ("selected", d.tactic)
        if d.kind == "deferred" and again and str(d.data.get("reason")).startswith("cooldown"):
            out.pop()
        else:
            out.append(d)
    return out
