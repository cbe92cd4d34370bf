"""The monitor stage: takes what arrived and stamps the cycle (see :mod:`anunnaki.utu.cycle`)."""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from typing import Any, cast

from anunnaki.errors import AnunnakiError
from anunnaki.messages import MonitorBatch, MonitorInput, body_of
from anunnaki.tokens import OPERATOR_TOKEN_ENV, default_token_file, token_matches
from anunnaki.utu.cycle._entries import (
    build_message,
    operator_entry,
    reloaded_parts,
)
from anunnaki.utu.cycle._parts import UtuParts

__all__ = [
    "MonitorStage",
]

log = logging.getLogger("anunnaki.utu")


# -- monitor -------------------------------------------------------------------------------------
class MonitorStage:
    """Takes what arrived and stamps the cycle.

    Each input keeps its own arrival time (the sender's stamp on wall time, else the
    cycle's), clamped into ``(previous cycle, this cycle]``: a burst taken by one cycle
    keeps its spacing, so ``rate(A)`` and temporal goals see what really happened.

    Attributes:
        operator_token: The token pause, resume, approve and reload requests must carry;
            ``None`` (as built) until a host offers the operator services on a bus and sets
            it (:meth:`~anunnaki.utu.host.OperatorDesk.declare`): a manager without a bus
            (a replay, a test) takes calls only from its own process, and never reads or
            writes the user's token file.

    """

    def __init__(self, parts: UtuParts, *, origin: str = "") -> None:
        self.origin = origin
        self.seq = 0
        self.last_t = 0.0  # inputs are never stamped before the start of time
        self.operator_token: str | None = None
        self.unauthorised = 0  # operator requests refused for want of the token
        self.set_parts(parts)

    def set_parts(self, parts: UtuParts) -> None:
        """Watch the topics of ``parts``' goal model."""
        self.parts = parts
        topics: list[str] = []
        for agent in parts.model.agents.values():
            for tb in agent.topics:
                if tb.topic not in topics:
                    topics.append(tb.topic)
        self.topics = topics

    def request(self, op: str, message: Any) -> tuple[dict[str, Any] | None, dict[str, Any]]:
        """An operator service request: ``(op entry to queue or None, the reply)``.

        A reload is checked now, so the caller hears of a broken file at once: refused, it
        still enters the cycle (marked ``refused``) so the decision log says it and a replay
        repeats it; accepted, it carries the files' texts and this monitor watches the new
        model's topics from now on.
        """
        refused = self._unauthorised(op, message)
        if refused is not None:
            return None, {"ok": False, "status": "unauthorised", "error": refused}
        entry = operator_entry(op, message)
        if "error" in entry:
            return None, {"ok": False, "error": entry["error"]}
        reply: dict[str, Any] = {"ok": True, "queued": op, "caller": entry["caller"]}
        if op == "reload":
            try:
                parts = reloaded_parts(self.parts, entry)
            except (AnunnakiError, OSError) as exc:
                return {**entry, "refused": str(exc)}, {
                    "ok": False,
                    "status": "refused",
                    "error": str(exc),
                }
            entry["sources"] = {k: [p, text] for k, (p, text) in parts.sources.items()}
            self.set_parts(parts)
            reply["status"] = "accepted"
        return entry, reply

    def _unauthorised(self, op: str, message: Any) -> str | None:
        """Why an operator request may not act (``None``: it may); a run-stop always may."""
        token = self.operator_token
        if token is None or op == "run_stop" or token_matches(body_of(message).get("token"), token):
            return None
        self.unauthorised += 1
        if self.unauthorised == 1:
            log.warning(
                "utu: refused an operator %s without the operator token; further refusals "
                "are counted, not logged",
                op,
            )
        return (
            f"unauthorised: {op} needs the operator token ('token' in the request; clients "
            f"read it from ${OPERATOR_TOKEN_ENV}, else from the user's {default_token_file()}); "
            "anyone may request a run-stop"
        )

    def batch(
        self,
        t: float,
        inputs: Sequence[tuple[str, Mapping[str, Any], float | None]],
        ops: Sequence[Mapping[str, Any]],
    ) -> MonitorBatch:
        """One batch at time ``t`` (never earlier than the last) of ``(topic, msg, t_in)``."""
        t = max(float(t), self.last_t)
        previous, self.last_t = self.last_t, t
        self.seq += 1
        taken = [
            build_message(
                MonitorInput,
                topic=topic,
                t=t if t_in is None else min(max(float(t_in), previous), t),
                msg=dict(msg),
            )
            for topic, msg, t_in in inputs
        ]
        return cast(
            MonitorBatch,
            build_message(
                MonitorBatch,
                origin=self.origin,
                seq=self.seq,
                t=t,
                inputs=taken,
                ops=[dict(op) for op in ops],
            ),
        )
