"""What a bus message may make the dashboard keep: bounds and field-by-field checks.

Everything the dashboard shows arrives from the bus, from any sender. These functions turn
a message's fields into the plain values a pane keeps (finite numbers, short names, bounded
lists, JSON-safe mappings) or ``None`` when a field is ill-typed, so one odd message never
breaks a pane or grows the store without bound. They are pure and hold no state; the
store (:class:`~anunnaki.dashboard.DashboardState`) decides what to do with the result.
"""

from __future__ import annotations

import json
import math
from collections.abc import Collection, Mapping
from typing import Any

__all__ = [
    "MAX_ACTIONS",
    "MAX_ASSESSORS",
    "MAX_LIST",
    "MAX_NAME",
    "assessment_row",
    "decision_row",
    "detections_row",
    "parse_analysis",
    "queue_rows",
]

#: Bounds on what a message can make the dashboard keep (whatever arrives on the bus).
MAX_ASSESSORS = 32
MAX_NAME = 200
MAX_LIST = 500
MAX_ACTIONS = 100
_SAFE_INT = 2**53
_STATUSES = ("satisfied", "unsatisfied", "unknown")


def _num(value: Any) -> float | None:
    """A finite number as a float, else ``None`` (bools, strings, NaN, ints beyond float)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    try:
        f = float(value)
    except OverflowError:  # an int too large for a float, e.g. 10**400
        return None
    return f if math.isfinite(f) else None


def _number(value: Any) -> int | float | None:
    """Like :func:`_num`, but an int that a page can hold exactly stays an int."""
    if isinstance(value, int) and not isinstance(value, bool) and -_SAFE_INT < value < _SAFE_INT:
        return value
    return _num(value)


def _name(value: Any) -> str | None:
    """A non-empty string of at most :data:`MAX_NAME` characters, else ``None``."""
    return value if isinstance(value, str) and 0 < len(value) <= MAX_NAME else None


def _names(value: Any) -> list[str] | None:
    """A list of names (others dropped, at most :data:`MAX_LIST`); ``None`` if not a list."""
    if not isinstance(value, list | tuple):
        return None
    return [v for v in (_name(x) for x in value[:MAX_LIST]) if v is not None]


def _flag(value: Any) -> bool | None:
    return value if isinstance(value, bool) else None


def _plain(value: Mapping[Any, Any], limit: int = MAX_LIST) -> dict[str, Any]:
    """A mapping with string keys (at most ``limit`` of them), as JSON can carry it."""
    return {str(k): v for k, v in list(value.items())[:limit]}


def queue_rows(value: Any) -> list[dict[str, Any]] | None:
    """The plan's queue, each row ``{tactic, priority, state, deadline}``; ``None`` if no list."""
    if not isinstance(value, list | tuple):
        return None
    rows = []
    for row in value[:MAX_LIST]:
        if not isinstance(row, Mapping):
            continue
        tactic = _name(row.get("tactic"))
        if tactic is None:
            continue
        state = _name(row.get("state"))
        rows.append(
            {
                "tactic": tactic,
                "priority": _number(row.get("priority")),
                "state": state or "unknown",
                "deadline": _number(row.get("deadline")),
            }
        )
    return rows


def parse_analysis(body: Mapping[str, Any], known: Collection[str]) -> dict[str, Any]:
    """What an analysis message says, checked field by field; no side effects.

    Args:
        body: The ``/utu/analyze/state`` message.
        known: The goal model's node ids; other nodes are never kept.

    Returns:
        ``{"nodes": {id: (utility, status)} | None, "t": float | None, "fields": {...}}``
        with only the goal model's nodes, and only the fields that are well typed; an
        ill-typed field is left out, so the pane keeps showing its previous value.

    """
    nodes: dict[str, tuple[float | None, str]] | None = None
    raw = body.get("nodes")
    if isinstance(raw, Mapping):
        nodes = {}
        for nid, value in raw.items():
            if nid not in known:
                continue  # a node this goal model does not have: never kept
            if not isinstance(value, list | tuple) or len(value) != 2:
                continue
            status = value[1] if value[1] in _STATUSES else "unknown"
            nodes[str(nid)] = (_num(value[0]), status)
    fields: dict[str, Any] = {}
    violated = _names(body.get("violated"))
    if violated is not None:
        fields["violated"] = violated
    eligible = _names(body["eligible"] if "eligible" in body else body.get("tactics"))
    if eligible is not None:
        fields["eligible"] = eligible
    queue = queue_rows(body.get("queue"))
    if queue is not None:
        fields["queue"] = queue
    post = body.get("postconditions")
    if isinstance(post, Mapping):
        fields["postconditions"] = _plain(post)
    for key in ("paused", "run_stopped", "warming_up"):
        flag = _flag(body.get(key))
        if flag is not None:
            fields[key] = flag
    return {"nodes": nodes, "t": _num(body.get("t")), "fields": fields}


def decision_row(d: Any) -> tuple[str, dict[str, Any]] | None:
    """A decision's de-duplication key and its row (without ``n``), or ``None`` if bad."""
    if not isinstance(d, Mapping):
        return None
    kind = _name(d.get("kind"))
    if kind is None:
        return None
    raw = d.get("data")
    data = _plain(raw) if isinstance(raw, Mapping) else {}
    row = {"t": _num(d.get("t")), "kind": kind, "tactic": _name(d.get("tactic")), "data": data}
    key = json.dumps(
        [row["t"], kind, row["tactic"], data], sort_keys=True, default=str, allow_nan=True
    )
    return key, row


def assessment_row(topic: str, body: Mapping[str, Any], t: float) -> dict[str, Any] | None:
    """The oracle pane's row of a behavior assessment, or ``None`` if it is not one.

    The category must be 0, 1 or 2 (the paper's categories); the row is keyed by its
    ``assessor`` (the topic when it names none).
    """
    category = body.get("category")
    if isinstance(category, bool) or not isinstance(category, int) or not 0 <= category <= 2:
        return None
    context = body.get("context")
    seq = body.get("frame_seq")
    return {
        "assessor": _name(body.get("assessor")) or topic,
        "topic": topic,
        "category": category,
        "confidence": _num(body.get("confidence")),
        "context": _plain(context, 50) if isinstance(context, Mapping) else {},
        "model_id": _name(body.get("model_id")),
        "frame_seq": _number(seq) if isinstance(seq, int) else None,
        "t": t,
    }


def detections_row(body: Mapping[str, Any]) -> dict[str, Any] | None:
    """The camera pane's row of an LEC's detections, or ``None`` without a valid frame_seq."""
    seq = body.get("frame_seq")
    if isinstance(seq, bool) or not isinstance(seq, int) or not 0 <= seq < _SAFE_INT:
        return None
    boxes = body.get("boxes")
    labels = body.get("labels")
    scores = body.get("scores")
    return {
        "frame_seq": seq,
        "model_id": _name(body.get("model_id")),
        "domain": _name(body.get("domain")),
        "width": _number(body.get("width")),
        "height": _number(body.get("height")),
        "boxes": [
            [_num(v) or 0.0 for v in b]
            for b in (boxes[:MAX_LIST] if isinstance(boxes, list) else [])
            if isinstance(b, list | tuple) and len(b) == 4
        ],
        "labels": [str(x)[:MAX_NAME] for x in labels[:MAX_LIST]]
        if isinstance(labels, list)
        else [],
        "scores": [_num(x) for x in scores[:MAX_LIST]] if isinstance(scores, list) else [],
    }
