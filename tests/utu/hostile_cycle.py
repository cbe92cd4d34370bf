"""A corpus of hostile messages on Utu's internal topics: type-valid, semantically forged.

Each is what a bus client that is not Utu could publish: well-formed, so the bus's schema
check lets it through, and wrong in what it says (forged cycles, ghost tactics, operator calls
where none may be, times far ahead). Used by tests/utu/test_nodes.py against every deployment
and by benchmarks/faults.py.
"""

from __future__ import annotations

from typing import Any

from anunnaki import topics
from anunnaki.messages import (
    AnalysisState,
    CycleDone,
    ExecuteStatus,
    MonitorBatch,
    MonitorInput,
    PlanStart,
)

FORGED = "forged00"


def hostile_cycle_messages(t: float) -> list[tuple[str, Any]]:
    """``(topic, message)`` pairs, stamped near ``t``."""
    weird = {"mode": {"deep": [1, [2, [3]]]}, "bumper": "yes", "range": -1e308}
    batch_ops: list[list[dict[str, Any]]] = [
        [{"op": "nonsense"}],
        [{"op": "approve"}],
        [{"op": "approve", "tactic": "fail-safe", "approve": "false"}],
        [{"op": "reload", "sources": "not-a-map"}],
        [{"op": "reload", "sources": {"tactics": ["/x", 5]}}],
        [{"op": "node_lost"}],
        [{"op": "node_lost", "node": 7}],
        [{"op": "resume"}],  # a resume not through the operator service (no token checked)
        [{"op": "run_stop", "reason": {"a": 1}}],
    ]
    out: list[tuple[str, Any]] = [
        (
            topics.MONITOR_INPUT,
            MonitorBatch(
                origin=FORGED,
                seq=1,
                t=t,
                inputs=[
                    MonitorInput(topic="/not/watched", t=t, msg={}),
                    MonitorInput(topic="/rover/status", t=t, msg=weird),
                    MonitorInput(topic="/rover/status", t=-5.0, msg={"mode": "manual"}),
                ],
            ),
        )
    ]
    out += [
        (topics.MONITOR_INPUT, MonitorBatch(origin=FORGED, seq=2 + i, t=t, ops=ops))
        for i, ops in enumerate(batch_ops)
    ]
    out += [
        (
            topics.ANALYSIS,
            AnalysisState(
                t=t,
                origin=FORGED,
                seq=10**9,
                eligible=["fail-safe", "ghost"],
                postconditions={"fail-safe": False, "ghost": True},
                post_goals={"G3": "unsatisfied"},
                ops=[{"op": "run_stop", "caller": "forger"}],
                changed=["G3", "G404"],
            ),
        ),
        (topics.ANALYSIS, AnalysisState(t=t, origin="", seq=0, eligible=["collision-stop"])),
        (
            topics.EXECUTE_STATUS,
            ExecuteStatus(
                origin=FORGED,
                seq=3,
                t=t,
                eligible=["ghost", "fail-safe"],
                runtimes={"fail-safe": {"state": 5}, "ghost": {"state": "running"}},
                approvals=[["fail-safe"], ["ghost", "approved", "extra"]],
                ops=[{"op": "pause"}],
            ),
        ),
        (
            topics.PLAN_START,
            PlanStart(origin=FORGED, seq=3, t=t, start=["ghost", "fail-safe"], states={"x": "y"}),
        ),
        (topics.CYCLE_DONE, CycleDone(origin=FORGED, seq=10**9, t=t, started=["ghost"])),
    ]
    return out
