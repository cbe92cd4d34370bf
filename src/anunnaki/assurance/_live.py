"""The case against a running system: each node's status for the goal model's state now.

A pure function of the case, the goal model's node states (what
:class:`anunnaki.goals.Evaluator` reports), the active model and the perceived condition, so
a live pane, the decision log and a replay get the same answer for the same input:

* **evidence is valid only where it was measured**: a figure about one model supports its
  claim only while that model is active, and a figure measured in some conditions (clean
  frames, fog) only while the oracle perceives one of them. A claim whose every evidence is
  out of its domain loses its support and says why (``undeveloped``, with the reason);
* **the goal model's state comes first**: a goal the evaluator finds unsatisfied is
  ``violated``; a RELAX-ed goal satisfied below full utility (within its tolerance) is
  ``degraded`` where its evidence supports it;
* otherwise the evidence decides, as at build time (supported, failed, stale, unverified,
  undeveloped), and strategies combine their sub-goals (AND: the worst, OR: the best).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

from anunnaki.assurance._case import Case, Node, _post_order

__all__ = ["LIVE_STATUSES", "LiveStatus", "evaluate"]

#: Live statuses, best first.
LIVE_STATUSES: Final = (
    "supported",
    "degraded",
    "undeveloped",
    "unverified",
    "stale",
    "failed",
    "violated",
)
_RANK: Final = {s: i for i, s in enumerate(LIVE_STATUSES)}
_OUT: Final = "out of domain"


@dataclass(frozen=True)
class LiveStatus:
    """One node's status now, and why when it is not supported."""

    status: str
    reason: str = ""


def _applies(node: Node, active_model: str | None, perceived: str | None) -> str | None:
    """``None`` when the solution's evidence holds now; otherwise why not."""
    ev = node.evidence
    assert ev is not None
    if ev.model is not None and active_model is not None and ev.model != active_model:
        return f"{ev.model} is not the active model ({active_model})"
    if ev.conditions and perceived is not None and perceived not in ev.conditions:
        return f"measured in {', '.join(ev.conditions)}, not in {perceived}"
    return None


def _model_goal(node: Node) -> bool:
    """A goal of the goal model (not a hazard's derived goal, ``G-O1-detected``)."""
    return (
        node.type == "goal"
        and node.source is not None
        and not node.id.startswith(f"G-{node.source}-")
    )


def _state(goal_states: Mapping[str, Any], gid: str) -> tuple[bool | None, float | None] | None:
    state = goal_states.get(gid)
    if state is None:
        return None
    if isinstance(state, bool):
        return state, None
    return getattr(state, "status", None), getattr(state, "utility", None)


def evaluate(
    case: Case,
    goal_states: Mapping[str, Any],
    active_model: str | None = None,
    perceived: str | None = None,
    *,
    relaxed: frozenset[str] | set[str] = frozenset(),
) -> dict[str, LiveStatus]:
    """Every GSN node's live status.

    Args:
        case: The case (``build_case`` or ``read_case``).
        goal_states: Goal id → its state now: an :class:`anunnaki.goals.NodeState` (status
            and utility) or a bare ``True``/``False``/``None``. Goals not named keep their
            evidence's status.
        active_model: The detector's active model (agent A6's ``model``), if known.
        perceived: The condition the oracle perceives (A4's ``context``: ``clear``,
            ``fog`` …), if known.
        relaxed: Goal ids whose satisfaction below full utility is ``degraded`` (default:
            every goal whose case node states a RELAX acceptance criterion).

    """
    relaxed = relaxed or {
        n.source for n in case if n.type == "context" and n.id.endswith("-accept") and n.source
    }
    out: dict[str, LiveStatus] = {}
    for nid in _post_order(case):
        node = case.nodes[nid]
        if node.type in ("context", "assumption", "justification"):
            continue
        if node.evidence is not None:
            why = _applies(node, active_model, perceived)
            out[nid] = LiveStatus(_OUT, why) if why else LiveStatus(node.evidence.status)
            continue
        out[nid] = _inner(node, out, goal_states, relaxed)
    return out


def _inner(
    node: Node, out: dict[str, LiveStatus], goal_states: Mapping[str, Any], relaxed: Any
) -> LiveStatus:
    below = [out[c] for c in node.supported_by if c in out]
    held = [s for s in below if s.status != _OUT]
    if not below:
        status = LiveStatus("undeveloped")
    elif not held:
        reasons = "; ".join(dict.fromkeys(s.reason for s in below if s.reason))
        status = LiveStatus("undeveloped", f"no evidence holds now: {reasons}")
    elif node.type == "strategy" and node.refinement == "or":
        status = min(held, key=lambda s: _RANK[s.status])
    else:
        status = max(held, key=lambda s: _RANK[s.status])
    if not _model_goal(node):
        return status
    state = _state(goal_states, node.source or "")
    if state is None:
        return status
    satisfied, utility = state
    if satisfied is False:
        return LiveStatus("violated", "the goal model finds it unsatisfied")
    if (
        satisfied
        and node.source in relaxed
        and utility is not None
        and utility < 1.0
        and status.status == "supported"
    ):
        why = f"satisfied within its RELAX tolerance (utility {utility:.2f})"
        return LiveStatus("degraded", why)
    return status
