"""The knowledge stage: queries, and the decisions written since the last publication."""

from __future__ import annotations

from typing import Any

from anunnaki.messages import body_of
from anunnaki.utu.cycle._knowledge import Decision, Knowledge
from anunnaki.utu.cycle._parts import UtuParts

__all__ = [
    "DecisionTail",
    "KnowledgeStage",
    "decision_dict",
]


# -- knowledge -----------------------------------------------------------------------------------
def decision_dict(d: Decision) -> dict[str, Any]:
    """A decision as published on ``/utu/knowledge/decisions``."""
    return {"id": d.id, "t": d.t, "kind": d.kind, "tactic": d.tactic, "data": d.data}


class DecisionTail:
    """The decisions written to a knowledge base since the last read, by any writer.

    Args:
        knowledge: The knowledge base (another process may be writing it).
        from_start: Read the decisions already there too (default: only new ones).

    """

    def __init__(self, knowledge: Knowledge, *, from_start: bool = False) -> None:
        self.knowledge = knowledge
        last = [] if from_start else knowledge.decisions(limit=1)
        self.last_id = last[-1].id if last else 0

    def read(self) -> list[Decision]:
        """Return the decisions written since the last call, in order."""
        rows = self.knowledge.decisions(after_id=self.last_id)
        if rows:
            self.last_id = rows[-1].id
        return rows


class KnowledgeStage:
    """Answers ``/utu/knowledge/query`` from the knowledge base and the latest cycle.

    ``{what: decisions|queue|state, limit, after}``: the decisions (the newest ``limit``,
    with ids above ``after`` if given), the priority-sorted queue, or the analysis with the
    queue and the operator flags.
    """

    def __init__(self, parts: UtuParts, knowledge: Knowledge) -> None:
        self.parts = parts
        self.knowledge = knowledge
        self.state: dict[str, Any] = {}
        self.queue: list[Any] = []
        self.flags = {"paused": False, "run_stopped": False}

    def query(self, message: Any) -> dict[str, Any]:
        """Answer one query (a bus message or a mapping)."""
        body = body_of(message)
        what = body.get("what", "state")
        limit = body.get("limit", 100)
        if not isinstance(limit, int) or isinstance(limit, bool) or limit < 1:
            limit = 100
        if what == "decisions":
            after = body.get("after")
            after_id = after if isinstance(after, int) and not isinstance(after, bool) else None
            rows = self.knowledge.decisions(limit=min(limit, 10_000), after_id=after_id)
            return {
                "ok": True,
                "decisions": [
                    {"id": d.id, "t": d.t, "kind": d.kind, "tactic": d.tactic, "data": d.data}
                    for d in rows
                ],
            }
        if what == "queue":
            return {"ok": True, "queue": list(self.queue)}
        if what == "state":
            state = self.state or {
                "t": None,
                "root": self.parts.model.root,
                "nodes": {},
                "violated": [],
                "tactics": [],
            }
            return {"ok": True, **state, "queue": list(self.queue), **self.flags}
        return {"ok": False, "error": f"unknown query {what!r}; ask decisions, queue or state"}
