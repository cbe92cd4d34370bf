"""The case evaluated while a launch runs: its statuses on the bus, its top claims in the log.

:class:`LiveCase` holds what :func:`~anunnaki.assurance.evaluate` needs — the goal model's
states (Utu's analysis, ``/utu/analyze/state``), the active model (``/lm_manager/active``)
and the condition the oracle perceives (``/utu/oracle/output``'s ``context.phenomenon``) —
and evaluates the case again whenever one of them changes. It is a plain object fed by
direct calls: on a simulated run's executor the evaluation happens in the delivery of the
message that changed it, in order, with no thread and no wait, so the same run gives the
same statuses and the same log.

When a top-level claim (the root goal, and the goals its strategy argues over) starts or
stops to hold (supported or degraded), it calls ``record(t, "assurance", None, **data)``: a
decision of kind ``assurance`` in Utu's knowledge base, with the claim, its status now and
before, and the reason (docs/decision-log.md).

:class:`CaseMonitor` puts a :class:`LiveCase` on a bus: it subscribes the three topics,
publishes the statuses on ``/utu/assurance/state`` at each change and answers
``/utu/assurance/query`` with the statuses now (and the SVG when asked, ``{"svg": true}``):
what the dashboard's pane and ``anunnaki assurance status`` read.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from anunnaki import topics
from anunnaki._closing import Closing
from anunnaki.assurance._case import Case
from anunnaki.assurance._live import LiveStatus, evaluate
from anunnaki.bus import Bus, Sample
from anunnaki.goals import NodeState
from anunnaki.messages import body_of

if TYPE_CHECKING:
    from anunnaki.launch import Launch

__all__ = [
    "HOLDING",
    "CaseMonitor",
    "LiveCase",
    "goal_states",
    "load_live_case",
    "perceived_of",
    "top_claims",
]

#: Statuses under which a claim holds.
HOLDING: Final = ("supported", "degraded")

Record = Callable[..., object]

_STATUS: Final = {"satisfied": True, "unsatisfied": False}


def goal_states(nodes: Mapping[str, Any]) -> dict[str, NodeState]:
    """Goal id → its state, from ``[utility, status]`` pairs (an analysis, a knowledge base).

    ``status`` is ``satisfied``, ``unsatisfied`` or ``unknown`` (anything else: unknown).
    """
    out: dict[str, NodeState] = {}
    for gid, pair in nodes.items():
        if isinstance(pair, list | tuple) and len(pair) >= 2:
            utility = pair[0] if isinstance(pair[0], int | float) else None
            status = _STATUS.get(pair[1]) if isinstance(pair[1], str) else None
            out[gid] = NodeState(gid, "goal", utility, status)
    return out


def perceived_of(assessment: Mapping[str, Any]) -> str | None:
    """The condition an assessment perceives: its ``context.phenomenon`` (``clear`` when empty)."""
    context = assessment.get("context")
    if not isinstance(context, Mapping):
        return None
    name = context.get("phenomenon")
    if name is None or name == "":
        return "clear" if not context else None
    return str(name)


def top_claims(case: Case) -> list[str]:
    """The root goal, then the goals the root's strategies argue over (in order)."""
    root = case.nodes[case.root]
    out = [case.root]
    for sid in root.supported_by:
        node = case.nodes.get(sid)
        if node is not None and node.type == "strategy":
            out.extend(g for g in node.supported_by if case.nodes[g].type == "goal")
    return list(dict.fromkeys(out))


def load_live_case(
    launch: str | Path | None,
    case_dir: str | Path | None = None,
    *,
    warn: Callable[[str], None] | None = None,
    loaded: Launch | None = None,
) -> Case | None:
    """The case a running launch evaluates: ``case_dir``'s, or built from the launch now.

    Built only when a criteria file (``assurance.yaml``) lies beside the launch file and
    develops its goal model (a case without any evidence argues nothing: ``None``); a few
    tenths of a second. A case that cannot be built is said through ``warn`` and ``None``
    returned (the run goes on without one); a ``case_dir`` that cannot be read raises.
    ``loaded``: the launch file as the caller has loaded it (not read again).
    """
    from anunnaki.assurance._build import CRITERIA_FILE, build_case
    from anunnaki.assurance._case import read_case
    from anunnaki.errors import AnunnakiError

    if case_dir is not None:
        return read_case(case_dir)
    if launch is None or not (Path(launch).parent / CRITERIA_FILE).is_file():
        return None
    try:
        case = build_case(launch, loaded=loaded)
    except AnunnakiError as exc:
        if warn is not None:
            warn(f"assurance: no live case ({exc})")
        return None
    return case if case.solutions() else None


class LiveCase:
    """A case and the system's state now; evaluated again at each change.

    Args:
        case: The case (``build_case`` or ``read_case``).
        record: ``record(t, kind, tactic, **data)`` (``Knowledge.record_decision``): called
            when a top-level claim's support changes; ``None`` records nothing.
        claims: The claims whose support is recorded (default :func:`top_claims`).

    Not thread-safe by itself (:class:`CaseMonitor` locks it).

    """

    def __init__(
        self, case: Case, *, record: Record | None = None, claims: Iterable[str] | None = None
    ) -> None:
        self.case = case
        self.record = record
        self.claims = list(claims) if claims is not None else top_claims(case)
        self.goals: dict[str, NodeState] = {}
        self.active_model: str | None = None
        self.perceived: str | None = None
        self.t: float | None = None
        self.seq = 0
        self.statuses: dict[str, LiveStatus] = evaluate(case, {})
        self._held: dict[str, bool] | None = None  # each top claim held, as last recorded
        self._was: dict[str, str] = {}  # each top claim's status, as last recorded

    # -- what changes it --------------------------------------------------------------------
    def take_analysis(self, body: Mapping[str, Any]) -> dict[str, LiveStatus]:
        """Utu's analysis (``/utu/analyze/state``): evaluate; returns the nodes that changed.

        When its time is past the last analysis's, the instant before has ended: a top claim
        whose support at its end differs from what was last recorded is recorded then,
        stamped with that instant (a claim lost and regained within one instant is not).
        """
        t = body.get("t")
        if isinstance(t, int | float) and not isinstance(t, bool):
            if self.t is not None and float(t) != self.t:
                self.flush()
            self.t = float(t)
        nodes = body.get("nodes")
        if isinstance(nodes, Mapping):
            self.goals = goal_states(nodes)
        return self.update()

    def take_active_model(self, body: Mapping[str, Any]) -> bool:
        """The model manager's announcement (``/lm_manager/active``: ``model``).

        Taken into the next evaluation (Utu's next analysis, or :meth:`update`); returns
        whether it changed.
        """
        model = body.get("model")
        model = model if isinstance(model, str) and model else None
        changed = model != self.active_model
        self.active_model = model
        return changed

    def take_assessment(self, body: Mapping[str, Any]) -> bool:
        """An oracle's assessment (``/utu/oracle/output``: ``context.phenomenon``), as above."""
        perceived = perceived_of(body)
        if perceived is None or perceived == self.perceived:
            return False
        self.perceived = perceived
        return True

    def update(self) -> dict[str, LiveStatus]:
        """Evaluate the case now; returns the nodes whose status changed."""
        before = self.statuses
        now = evaluate(self.case, self.goals, self.active_model, self.perceived)
        changed = {k: v for k, v in now.items() if before.get(k) != v}
        self.statuses = now
        if changed:
            self.seq += 1
        return changed

    def flush(self) -> None:
        """Record each top claim whose support changed since it was last recorded.

        The first call (after Utu's first analysis) records every top claim's status
        (``support: initial``); later ones a claim that stopped (``lost``) or started
        (``regained``) to hold. Called when an instant ends and when the run ends.
        """
        if self.t is None or self.record is None:
            return
        now = {c: self.statuses[c] for c in self.claims if c in self.statuses}
        first = self._held is None
        last = self._held or {}
        for claim, s in now.items():
            holds = s.status in HOLDING
            if first:
                self._record(claim, "initial", s, None)
            elif holds != last.get(claim):
                self._record(claim, "regained" if holds else "lost", s, self._was.get(claim))
        self._held = {c: s.status in HOLDING for c, s in now.items()}
        self._was = {c: s.status for c, s in now.items()}

    def _record(self, claim: str, change: str, s: LiveStatus, was: str | None) -> None:
        assert self.record is not None and self.t is not None
        self.record(
            self.t,
            "assurance",
            None,
            claim=claim,
            support=change,
            status=s.status,
            was=was,
            reason=s.reason or None,
            active_model=self.active_model,
            perceived=self.perceived,
        )

    # -- what it shows ------------------------------------------------------------------------
    def snapshot(self, *, svg: str | None = None) -> dict[str, Any]:
        """The statuses now, as the state topic and the query service carry them."""
        out: dict[str, Any] = {
            "case": self.case.name,
            "root": self.case.root,
            "t": self.t,
            "seq": self.seq,
            "active_model": self.active_model,
            "perceived": self.perceived,
            "claims": list(self.claims),
            "nodes": {
                n.id: [self.statuses[n.id].status, self.statuses[n.id].reason]
                for n in self.case
                if n.id in self.statuses
            },
        }
        if svg is not None:
            out["svg"] = svg
        return out


class CaseMonitor(Closing):
    """A :class:`LiveCase` on a bus: fed by Utu's topics, its statuses published and served.

    Args:
        live: The live case.
        bus: The launch's bus (on a simulated run's executor, every callback runs there).
        svg: The case's drawing (:func:`~anunnaki.assurance.render_svg`), sent to a query
            that asks for it.
        state_topic, query_service: Where it publishes and answers.

    """

    def __init__(
        self,
        live: LiveCase,
        bus: Bus,
        *,
        svg: str | None = None,
        state_topic: str = topics.ASSURANCE_STATE,
        query_service: str = topics.ASSURANCE_QUERY,
    ) -> None:
        self.live = live
        self.bus = bus
        self.svg = svg
        self.state_topic = state_topic
        self._lock = threading.Lock()
        self._sent = False
        self._declared: list[Any] = []
        try:
            self._declared.append(bus.subscribe(topics.ANALYSIS, self._on_analysis, queue=64))
            self._declared.append(bus.subscribe(topics.ACTIVE_MODEL, self._on_active, queue=8))
            self._declared.append(
                bus.subscribe(topics.ORACLE_OUTPUT, self._on_assessment, queue=64)
            )
            self._declared.append(bus.service(query_service, self._on_query))
        except BaseException:
            self.close()
            raise

    def _on_analysis(self, sample: Sample) -> None:
        self._take(self.live.take_analysis, sample)

    def _on_active(self, sample: Sample) -> None:
        with self._lock:
            self.live.take_active_model(body_of(sample.message))

    def _on_assessment(self, sample: Sample) -> None:
        with self._lock:
            self.live.take_assessment(body_of(sample.message))

    def _take(
        self, how: Callable[[Mapping[str, Any]], dict[str, LiveStatus]], sample: Sample
    ) -> None:
        with self._lock:
            changed = how(body_of(sample.message))
            if not changed and self._sent:
                return
            body = self.live.snapshot()
            self._sent = True
        self.bus.publish(self.state_topic, body)

    def _on_query(self, message: Any) -> dict[str, Any]:
        want_svg = bool(body_of(message).get("svg"))
        with self._lock:
            body = self.live.snapshot(svg=self.svg if want_svg else None)
        body["kinds"] = {n.id: n.type for n in self.live.case}
        return body

    def close(self) -> None:
        """Record the last instant's changes; undeclare its subscribers and service (idempotent)."""
        declared, self._declared = self._declared, []
        if declared:
            with self._lock:
                self.live.flush()
        for d in reversed(declared):
            d.close()
