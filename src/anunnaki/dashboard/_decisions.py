"""The decision log as the dashboard keeps it, and the executions it implies.

Decisions arrive from Utu's knowledge base (live, or re-sent by a query) and may come twice;
this log keeps the newest ones in order, each once, numbered for the pages' cursors, and
folds ``started``/``action``/result decisions into the execute pane's rows. Apart from
:class:`~anunnaki.dashboard.DashboardState` because de-duplication and the execution rows
are rules of their own; the store calls it with its lock held.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator
from typing import Any

from anunnaki.dashboard._checks import MAX_ACTIONS, _number, decision_row

__all__ = ["FLAG_KINDS", "TIMELINE_KINDS", "DecisionLog"]

#: Decision kinds drawn as markers on the timeline.
TIMELINE_KINDS = frozenset(
    {
        "started",
        "postcondition_ok",
        "postcondition_failed",
        "action_failed",
        "completed",
        "escalated",
        "run_stop",
        "paused",
        "resumed_adaptation",
        "approved",
        "rejected",
        "pending_approval",
    }
)
_RESULT_KINDS = frozenset(
    {"postcondition_ok", "postcondition_failed", "action_failed", "completed"}
)
#: Decisions that change Utu's pause and run-stop flags: the header follows the decision log
#: as well as the analysis, so it shows an operator's call from whichever arrives first (and
#: from a knowledge base recorded by an Utu that published its analysis on goal changes only).
FLAG_KINDS: dict[str, dict[str, bool]] = {
    "paused": {"paused": True},
    "resumed_adaptation": {"paused": False, "run_stopped": False},
    "run_stop": {"paused": True, "run_stopped": True},
}


class DecisionLog:
    """The newest decisions, each once, and the executions they describe (not locked).

    Args:
        maxlen: How many decisions to keep.

    """

    def __init__(self, maxlen: int) -> None:
        self.decisions: deque[dict[str, Any]] = deque(maxlen=maxlen)
        self.executions: deque[dict[str, Any]] = deque(maxlen=200)
        self._keys: set[str] = set()
        self._n = 0

    def add(self, decisions: Any) -> Iterator[tuple[dict[str, Any], bool]]:
        """Keep the new, well-formed decisions of a batch; yield each kept row.

        Each decision is checked before its key is remembered, so a malformed one is skipped
        without hiding a later, well-formed copy. Yields ``(row, execution_changed)``.
        """
        for d in decisions:
            try:
                parsed = decision_row(d)
            except (TypeError, ValueError, RecursionError):  # data JSON cannot hold
                parsed = None
            if parsed is None:
                continue
            key, row = parsed
            if key in self._keys:
                continue
            if len(self._keys) >= 4 * (self.decisions.maxlen or 1000):
                kept = (decision_row(x) for x in self.decisions)
                self._keys = {k[0] for k in kept if k is not None}
            self._keys.add(key)
            self._n += 1
            row["n"] = self._n
            self.decisions.append(row)
            yield row, self._execution(row)

    def _execution(self, d: dict[str, Any]) -> bool:
        """Fold a decision into the execution rows; whether a row changed."""
        kind, tactic = d["kind"], d["tactic"]
        if tactic is None:
            return False
        data = d["data"]
        if kind == "started":
            self.executions.append(
                {
                    "tactic": tactic,
                    "started": d["t"],
                    "reason": data.get("reason"),
                    "deadline": _number(data.get("deadline")),
                    "actions": [],
                    "result": "awaiting",
                    "result_t": None,
                    "note": None,
                }
            )
            return True
        run = next((e for e in reversed(self.executions) if e["tactic"] == tactic), None)
        if run is None:
            return False
        if kind == "action":
            if len(run["actions"]) >= MAX_ACTIONS:
                return False
            run["actions"].append(
                {
                    "type": data.get("type"),
                    "ok": data.get("ok"),
                    "detail": data.get("detail"),
                }
            )
            return True
        if kind in _RESULT_KINDS and run["result"] == "awaiting":
            run["result"] = kind
            run["result_t"] = d["t"]
            run["note"] = data.get("note")
            return True
        return False
