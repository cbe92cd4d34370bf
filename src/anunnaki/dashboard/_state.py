"""What the dashboard knows: one thread-safe, versioned store that every pane is drawn from.

Bus callbacks write into :class:`DashboardState` (``take_*`` methods, any thread); the web
server reads it. Every write bumps a version counter and stamps what it changed with that
version, so a client that has seen version ``v`` asks :meth:`DashboardState.delta` for what
changed since and gets only that: the goals whose utility or status moved, the decisions
and timeline points after its cursor, a camera frame's metadata (never its pixels, which are
fetched separately by sequence number). That is how 300 goals at 10 Hz stay cheap: the
server coalesces whatever happened between two sends into one patch.

The store never calls into Utu. It holds what Utu published (``/utu/analyze/state``,
``/utu/knowledge/decisions``, the plan's queue) and what the managed system published (the
agents' topics, assessments, camera frames, detections), plus its own evaluator of the
goal model fed with the same agent topics, which answers *why* a node has its status
(:meth:`DashboardState.explain`) without touching the manager.
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

from anunnaki.goals import Evaluator, GoalModel, TopicFreshness
from anunnaki.tactics import TacticSet

__all__ = ["DashboardState", "Frame"]

log = logging.getLogger("anunnaki.dashboard")

#: Decision kinds drawn as markers on the timeline.
TIMELINE_KINDS = frozenset(
    {
        "started",
        "postcondition_ok",
        "postcondition_failed",
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
_RESULT_KINDS = frozenset({"postcondition_ok", "postcondition_failed", "completed"})
#: Decisions that change Utu's pause and run-stop flags: the header follows the decision log
#: as well as the analysis, so it shows an operator's call from whichever arrives first (and
#: from a knowledge base recorded by an Utu that published its analysis on goal changes only).
_FLAG_KINDS: dict[str, dict[str, bool]] = {
    "paused": {"paused": True},
    "resumed_adaptation": {"paused": False, "run_stopped": False},
    "run_stop": {"paused": True, "run_stopped": True},
}
_STATUSES = ("satisfied", "unsatisfied", "unknown")
#: Bounds on what a message can make the dashboard keep (whatever arrives on the bus).
MAX_ASSESSORS = 32
MAX_NAME = 200
MAX_LIST = 500
MAX_ACTIONS = 100
_SAFE_INT = 2**53


@dataclass(frozen=True)
class Frame:
    """One camera frame as the dashboard keeps it (the encoded bytes, never decoded).

    Attributes:
        topic: The camera topic.
        seq: The camera's frame counter.
        encoding: ``"jpeg"`` or ``"png"``.
        width: Width in pixels.
        height: Height in pixels.
        data: The encoded image file.
        t: Its stamp on the dashboard's clock (seconds): the sender's publication time on
            the wall clock, its simulated instant on ``clock: sim``. The frame rate is
            measured on these stamps, never on arrivals (which come in bursts).

    """

    topic: str
    seq: int
    encoding: str
    width: int
    height: int
    data: bytes
    t: float

    @property
    def media_type(self) -> str:
        """The HTTP content type of :attr:`data`."""
        return "image/png" if self.encoding == "png" else "image/jpeg"


class _Topic(TopicFreshness):
    """A monitored topic as the monitor pane shows it: last message and freshness.

    Freshness (last arrival, count, rate, staleness) is :class:`anunnaki.goals.TopicFreshness`,
    the definition the goal model's ``rate(A)`` and Utu's Monitor use.
    """

    def __init__(self, agents: list[str], staleness: float, window: int) -> None:
        super().__init__(staleness, window=window)
        self.agents = agents
        self.last_msg: Any = None
        self.version = 0


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


def _queue_rows(value: Any) -> list[dict[str, Any]] | None:
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


class DashboardState:
    """The dashboard's picture of a run, fed from the bus and read by the web server.

    Args:
        model: The goal model (with its binding): the tree, the agents and their topics.
        tactics: The tactics, for the plan and execute panes.
        name: The run's name, shown in the page title.
        clock: The dashboard's time in seconds (arrival stamps, staleness, rates): a
            simulation's time when Utu runs on ``clock: sim``, wall time otherwise.
        clock_kind: ``"sim"`` or ``"wall"``; on the wall clock the page shows times relative
            to the dashboard's start.
        operator: Whether operator actions are offered (the server was given a token).
        decisions: How many decisions to keep in memory (the knowledge base has them all).
        timeline: How many root-utility changes to keep for the timeline.
        idle: Seconds (wall clock) without any message after which the run counts as
            ended (the page's *live* badge goes off); see :meth:`run`.
        wall: The monotonic clock :attr:`idle` is measured on (``time.monotonic``).

    """

    def __init__(
        self,
        model: GoalModel,
        tactics: TacticSet,
        *,
        name: str | None = None,
        clock: Callable[[], float] | None = None,
        clock_kind: Literal["sim", "wall"] = "wall",
        operator: bool = False,
        decisions: int = 2000,
        timeline: int = 5000,
        idle: float = 5.0,
        wall: Callable[[], float] = time.monotonic,
    ) -> None:
        if not idle > 0:
            raise ValueError(f"idle must be > 0 seconds, got {idle!r}")
        self.model = model
        self.tactics = tactics
        self.name = name or model.name
        self.clock: Callable[[], float] = clock or time.time
        self.clock_kind = clock_kind
        self.operator = operator
        self.t0 = 0.0 if clock_kind == "sim" else time.time()
        self._lock = threading.RLock()
        self._version = 0
        self._listeners: list[Callable[[], None]] = []
        self._evaluator = Evaluator(model)
        self._ids = list(self._evaluator.ids)
        # Goals: what Utu published (or, until it does, the dashboard's own evaluation).
        self._goals: dict[str, tuple[float | None, str, int]] = {}
        self._goal_source: Literal["utu", "dashboard"] = "dashboard"
        self._analysis: dict[str, Any] = {
            "t": None,
            "violated": [],
            "eligible": [],
            "postconditions": {},
            "queue": [],
            "paused": False,
            "run_stopped": False,
            "warming_up": False,
        }
        self._analysis_v = 0
        self._utu_t: float | None = None
        self._flags_t: float | None = None  # Utu's time of the last pause/resume/run-stop
        staleness = model.spec.staleness
        self._topics: dict[str, _Topic] = {}
        for agent in model.agents.values():
            for tb in agent.topics:
                entry = self._topics.get(tb.topic)
                if entry is None:
                    entry = self._topics[tb.topic] = _Topic(
                        [], agent.staleness or staleness, model.spec.rate_window
                    )
                entry.agents.append(agent.id)
                entry.staleness = min(entry.staleness, agent.staleness or staleness)
        self._oracle: dict[str, dict[str, Any]] = {}
        self._oracle_when: dict[str, int] = {}
        self._oracle_heard = 0
        self._oracle_v = 0
        self._frames: deque[Frame] = deque(maxlen=8)
        self._detections: dict[int, dict[str, Any]] = {}
        self._active_model: dict[str, Any] | None = None
        self._camera_v = 0
        self._camera_count = 0
        self._decisions: deque[dict[str, Any]] = deque(maxlen=decisions)
        self._decision_keys: set[str] = set()
        self._decision_n = 0
        self._executions: deque[dict[str, Any]] = deque(maxlen=200)
        self._executions_v = 0
        self._timeline: deque[dict[str, Any]] = deque(maxlen=timeline)
        self._timeline_n = 0
        self._frame_stamps: deque[float] = deque(maxlen=64)
        self._latest_t: float | None = None  # the latest time any pane shows
        self.idle = idle
        self._wall = wall
        self._heard_at: float | None = None  # wall time of the last message
        self._utu_nodes: set[str] = set()  # Utu's nodes whose liveliness token is alive
        self._utu_seen = False
        self._evaluate_own(self.clock())

    # -- the run's liveliness and time ---------------------------------------------------------
    def _saw(self, t: float | None) -> None:
        """A message arrived (call with the lock held); ``t`` is the time a pane shows."""
        self._heard_at = self._wall()
        if t is not None and math.isfinite(t):
            self._latest_t = t if self._latest_t is None else max(self._latest_t, t)

    def heard(self) -> None:
        """A message that changes no pane arrived (``/clock``): the run is being fed."""
        with self._lock:
            self._heard_at = self._wall()

    def utu_node(self, node: str, alive: bool) -> None:
        """Utu's node ``node`` appeared or vanished (its liveliness token)."""
        with self._lock:
            if alive:
                self._utu_seen = True
                self._utu_nodes.add(node)
            else:
                self._utu_nodes.discard(node)
            self._bump()
        self._changed()

    def run(self) -> dict[str, Any]:
        """Whether the run is live: ``{live, state, reason}``.

        ``state`` is ``"waiting"`` before any message, ``"ended"`` once every Utu node seen
        has withdrawn its liveliness token or no message has arrived for :attr:`idle`
        seconds (wall clock), else ``"live"``. A run that is fed again is live again.
        """
        with self._lock:
            if self._utu_seen and not self._utu_nodes:
                return {"live": False, "state": "ended", "reason": "Utu's nodes are gone"}
            if self._heard_at is None:
                return {"live": False, "state": "waiting", "reason": "no message yet"}
            silent = self._wall() - self._heard_at
            if silent > self.idle:
                reason = f"no message for {silent:.0f} s"
                return {"live": False, "state": "ended", "reason": reason}
            return {"live": True, "state": "live", "reason": None}

    @property
    def latest_t(self) -> float | None:
        """The latest time any pane shows (what the header shows), ``None`` before any."""
        return self._latest_t

    # -- change notification --------------------------------------------------------------
    def _bump(self) -> int:
        self._version += 1
        return self._version

    def _changed(self) -> None:
        for listener in list(self._listeners):
            listener()

    def add_listener(self, callback: Callable[[], None]) -> Callable[[], None]:
        """Call ``callback()`` after every change (from the writing thread; keep it short).

        Returns:
            A function that removes the listener.

        """
        with self._lock:
            self._listeners.append(callback)

        def remove() -> None:
            with self._lock:
                if callback in self._listeners:
                    self._listeners.remove(callback)

        return remove

    @property
    def has_analysis(self) -> bool:
        """Whether an analysis from Utu has arrived."""
        return self._analysis["t"] is not None

    @property
    def version(self) -> int:
        """The number of changes so far."""
        return self._version

    # -- writers (bus threads) -------------------------------------------------------------
    def take_input(self, topic: str, message: Mapping[str, Any], t: float | None = None) -> None:
        """An agent's message: the monitor pane's row and the dashboard's own evaluation."""
        if not isinstance(message, Mapping):
            return
        now = self.clock() if t is None else t
        with self._lock:
            entry = self._topics.get(topic)
            if entry is None:
                self._heard_at = self._wall()
                return
            self._saw(now)
            entry.last_msg = _plain(message)
            entry.arrive(now)
            entry.version = self._bump()
            try:
                self._evaluator.observe(topic, message, now)
                self._evaluate_own(now)
            except Exception:  # one odd message must not stop the monitor pane
                log.warning("dashboard: could not evaluate a message of %s", topic, exc_info=True)
        self._changed()

    def tick(self) -> None:
        """Let time pass for the dashboard's own evaluation (staleness, rates)."""
        with self._lock:
            if self._evaluator.tick(self.clock()):
                self._evaluate_own(self.clock())
                self._bump()
            else:
                return
        self._changed()

    def _evaluate_own(self, now: float) -> None:
        if self._goal_source != "dashboard":
            return
        ev = self._evaluator
        ev.tick(now)
        for nid in self._ids:
            st = ev.state(nid)
            self._set_goal(nid, st.utility, st.status_name)

    def _set_goal(self, nid: str, utility: float | None, status: str) -> None:
        old = self._goals.get(nid)
        if old is not None and old[0] == utility and old[1] == status:
            return
        self._goals[nid] = (utility, status, self._bump())

    def _parse_analysis(self, body: Mapping[str, Any]) -> dict[str, Any]:
        """What an analysis message says, checked field by field; no side effects.

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
                if nid not in self._evaluator.index:
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
        queue = _queue_rows(body.get("queue"))
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

    def take_analysis(self, body: Mapping[str, Any]) -> None:
        """A ``/utu/analyze/state`` message: utilities, statuses, violations, eligible tactics.

        The message is checked first and applied as a whole: ill-typed fields are ignored,
        nodes the goal model does not have are dropped, and nothing is half-applied.
        """
        if not isinstance(body, Mapping):
            return
        parsed = self._parse_analysis(body)
        nodes: dict[str, tuple[float | None, str]] | None = parsed["nodes"]
        t: float | None = parsed["t"]
        fields: dict[str, Any] = parsed["fields"]
        with self._lock:
            if t is not None and self._flags_t is not None and t < self._flags_t:
                # Older than the operator's last call the decision log showed: not its flags.
                fields = {k: v for k, v in fields.items() if k not in ("paused", "run_stopped")}
            if nodes:
                if self._goal_source != "utu":
                    self._goal_source = "utu"
                    for nid in self._ids:  # what Utu does not say is unknown, not the guess
                        if nid not in nodes:
                            self._set_goal(nid, None, "unknown")
                for nid, (utility, status) in nodes.items():
                    self._set_goal(nid, utility, status)
            a = {**self._analysis, **fields}
            self._saw(t)
            if t is not None:
                a["t"] = t
                self._utu_t = t if self._utu_t is None else max(self._utu_t, t)
            if a != self._analysis:
                self._analysis = a
                self._analysis_v = self._bump()
            root = self._goals.get(self.model.root)
            if root is not None and t is not None:
                last = self._timeline[-1] if self._timeline else None
                if last is None or (last["u"], last["s"]) != (root[0], root[1]):
                    self._timeline_n += 1
                    point = {"n": self._timeline_n, "t": t, "u": root[0], "s": root[1]}
                    self._timeline.append(point)
                    self._bump()
        self._changed()

    def take_queue(self, queue: Any) -> None:
        """The plan's priority-sorted queue (``/utu/plan/start`` in per-node runs)."""
        rows = _queue_rows(queue)
        if rows is not None:
            self.take_flags(queue=rows)

    def take_flags(self, **flags: Any) -> None:
        """Update analysis fields (``paused``, ``run_stopped``, ``queue``) from other topics.

        ``paused`` and ``run_stopped`` must be bools and ``queue`` a list; others are ignored.
        """
        clean: dict[str, Any] = {}
        for key, value in flags.items():
            if key == "queue":
                rows = _queue_rows(value)
                if rows is not None:
                    clean[key] = rows
            elif key in ("paused", "run_stopped", "warming_up") and isinstance(value, bool):
                clean[key] = value
        with self._lock:
            self._heard_at = self._wall()
            a = {**self._analysis, **clean}
            if a == self._analysis:
                return
            self._analysis = a
            self._analysis_v = self._bump()
        self._changed()

    @staticmethod
    def _decision_row(d: Any) -> tuple[str, dict[str, Any]] | None:
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

    def take_decisions(self, decisions: Iterable[Mapping[str, Any]]) -> None:
        """New decisions of the decision log (``/utu/knowledge/decisions`` or a query).

        Each decision is checked before its key is remembered, so a malformed one is skipped
        without hiding a later, well-formed copy; the others of the batch are kept.
        """
        changed = False
        with self._lock:
            self._heard_at = self._wall()
            for d in decisions:
                try:
                    parsed = self._decision_row(d)
                except (TypeError, ValueError, RecursionError):  # data JSON cannot hold
                    parsed = None
                if parsed is None:
                    continue
                key, row = parsed
                if key in self._decision_keys:
                    continue
                if len(self._decision_keys) >= 4 * (self._decisions.maxlen or 1000):
                    kept = (self._decision_row(x) for x in self._decisions)
                    self._decision_keys = {k[0] for k in kept if k is not None}
                self._decision_keys.add(key)
                self._decision_n += 1
                row["n"] = self._decision_n
                self._decisions.append(row)
                self._saw(row["t"])
                self._execution(row)
                self._decision_flags(row)
                self._bump()
                changed = True
        if changed:
            self._changed()

    def _decision_flags(self, d: dict[str, Any]) -> None:
        flags = _FLAG_KINDS.get(d["kind"])
        if flags is None:
            return
        analysed = self._analysis.get("t")
        if d["t"] is not None and analysed is not None and d["t"] < analysed:
            return  # the analysis since then says what holds
        if d["t"] is not None:
            self._flags_t = d["t"] if self._flags_t is None else max(self._flags_t, d["t"])
        a = {**self._analysis, **flags}
        if a != self._analysis:
            self._analysis = a
            self._analysis_v = self._bump()

    def _execution(self, d: dict[str, Any]) -> None:
        kind, tactic = d["kind"], d["tactic"]
        if tactic is None:
            return
        data = d["data"]
        if kind == "started":
            self._executions.append(
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
            self._executions_v = self._bump()
            return
        run = next((e for e in reversed(self._executions) if e["tactic"] == tactic), None)
        if run is None:
            return
        if kind == "action":
            if len(run["actions"]) >= MAX_ACTIONS:
                return
            run["actions"].append(
                {
                    "type": data.get("type"),
                    "ok": data.get("ok"),
                    "detail": data.get("detail"),
                }
            )
        elif kind in _RESULT_KINDS and run["result"] == "awaiting":
            run["result"] = kind
            run["result_t"] = d["t"]
            run["note"] = data.get("note")
        else:
            return
        self._executions_v = self._bump()

    def take_assessment(self, topic: str, body: Mapping[str, Any], t: float | None = None) -> None:
        """A behavior assessment (``Assessment``, or any message with a ``category``).

        The category must be 0, 1 or 2 (the paper's categories); other messages are ignored.
        At most :data:`MAX_ASSESSORS` assessors are kept: a new one replaces the one heard
        from longest ago.
        """
        if not isinstance(body, Mapping):
            return
        category = body.get("category")
        if isinstance(category, bool) or not isinstance(category, int) or not 0 <= category <= 2:
            return
        key = _name(body.get("assessor")) or topic
        context = body.get("context")
        seq = body.get("frame_seq")
        row = {
            "assessor": key,
            "topic": topic,
            "category": category,
            "confidence": _num(body.get("confidence")),
            "context": _plain(context, 50) if isinstance(context, Mapping) else {},
            "model_id": _name(body.get("model_id")),
            "frame_seq": _number(seq) if isinstance(seq, int) else None,
            "t": self.clock() if t is None else t,
        }
        with self._lock:
            self._saw(_num(row["t"]))
            self._oracle_heard += 1
            self._oracle[key] = row
            self._oracle_when[key] = self._oracle_heard
            while len(self._oracle) > MAX_ASSESSORS:
                oldest = min(self._oracle_when, key=self._oracle_when.__getitem__)
                del self._oracle[oldest], self._oracle_when[oldest]
            self._oracle_v = self._bump()
        self._changed()

    def take_frame(self, frame: Frame) -> None:
        """A camera frame."""
        with self._lock:
            self._saw(frame.t)
            if self._frame_stamps and frame.t < self._frame_stamps[-1]:
                self._frame_stamps.clear()  # the clock went back (a new run): start over
            self._frame_stamps.append(frame.t)
            self._frames.append(frame)
            self._camera_count += 1
            self._camera_v = self._bump()
        self._changed()

    def take_detections(self, body: Mapping[str, Any]) -> None:
        """An LEC's detections for one frame (``Detections``)."""
        if not isinstance(body, Mapping):
            return
        seq = body.get("frame_seq")
        if isinstance(seq, bool) or not isinstance(seq, int) or not 0 <= seq < _SAFE_INT:
            return
        boxes = body.get("boxes")
        labels = body.get("labels")
        scores = body.get("scores")
        row = {
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
        with self._lock:
            self._heard_at = self._wall()
            self._detections[seq] = row
            while len(self._detections) > 32:
                del self._detections[min(self._detections)]
            if self._active_model is None or self._active_model.get("source") == "detections":
                self._active_model = {
                    "model": row["model_id"],
                    "domain": row["domain"],
                    "source": "detections",
                }
            self._camera_v = self._bump()
        self._changed()

    def take_active_model(self, body: Mapping[str, Any]) -> None:
        """The model manager's announcement ``{lec, model, domain}``."""
        if not isinstance(body, Mapping):
            return
        with self._lock:
            self._heard_at = self._wall()
            self._active_model = {
                "lec": _name(body.get("lec")),
                "model": _name(body.get("model")),
                "domain": _name(body.get("domain")),
                "source": "lm_manager",
            }
            self._camera_v = self._bump()
        self._changed()

    # -- readers (web server) ---------------------------------------------------------------
    def frame(self, seq: int | None = None) -> Frame | None:
        """The latest camera frame, or the one with sequence number ``seq`` if still kept."""
        with self._lock:
            if not self._frames:
                return None
            if seq is None:
                return self._frames[-1]
            return next((f for f in reversed(self._frames) if f.seq == seq), None)

    def explain(self, node: str) -> dict[str, Any] | None:
        """Why ``node`` has its status: Utu's verdict and the evaluator's explanation.

        Returns:
            ``None`` for an unknown node; else ``{node, utu: {utility, status}, explanation,
            text}`` where ``explanation`` is the tree of
            :meth:`anunnaki.goals.Explanation.to_dict` and ``text`` its rendering.

        """
        with self._lock:
            if node not in self._evaluator.index:
                return None
            self._evaluator.tick(self.clock())
            ex = self._evaluator.explain(node)
            verdict = self._goals.get(node)
            return {
                "node": node,
                "source": self._goal_source,
                "utu": None if verdict is None else {"utility": verdict[0], "status": verdict[1]},
                "explanation": ex.to_dict(),
                "text": ex.render(),
            }

    def structure(self) -> dict[str, Any]:
        """The goal model and tactics as the page draws them (does not change during a run)."""
        m = self.model
        goals = [
            {
                "id": g.id,
                "description": g.description,
                "refinement": g.refinement,
                "children": list(g.children),
                "utility": g.utility,
                "relax": None if g.relax is None else g.relax.operator,
                "agents": list(g.agents),
                "objective": g.objective,
            }
            for g in m.goals.values()
        ]
        obstacles = [
            {
                "id": o.id,
                "description": o.description,
                "obstructs": list(o.obstructs),
                "condition": o.condition,
                "resolutions": list(o.resolutions),
            }
            for o in m.obstacles.values()
        ]
        agents = [
            {
                "id": a.id,
                "description": a.description,
                "topics": [
                    {"topic": tb.topic, "attributes": list(tb.attributes)} for tb in a.topics
                ],
                "goals": [g.id for g in m.goals.values() if a.id in g.agents],
            }
            for a in m.agents.values()
        ]
        tactics = [
            {
                "name": t.name,
                "description": t.description,
                "priority": t.priority,
                "requires_approval": t.requires_approval,
                "deadline": t.deadline,
                "preconditions": [_describe_condition(c) for c in t.preconditions],
                "postconditions": [_describe_condition(c) for c in t.postconditions],
            }
            for t in self.tactics.tactics
        ]
        return {
            "name": self.name,
            "root": m.root,
            "goals": goals,
            "obstacles": obstacles,
            "agents": agents,
            "tactics": tactics,
        }

    def _monitor_rows(self, now: float, since: int) -> list[dict[str, Any]]:
        rows = []
        for topic, e in self._topics.items():
            if e.version <= since and since > 0:
                continue
            rows.append(
                {
                    "topic": topic,
                    "agents": e.agents,
                    "last": e.last_msg,
                    "last_t": e.last,
                    "count": e.count,
                    "rate": e.rate(now),
                    "staleness": e.staleness,
                    "stale": e.stale(now),
                }
            )
        return rows

    def _values(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for key, value in self._evaluator.values().items():
            if isinstance(value, str | int | float | bool) or value is None:
                out[key] = value
            else:
                out[key] = str(value)
        return out

    def snapshot(self) -> dict[str, Any]:
        """Everything a page needs to draw itself from scratch, with the version it shows."""
        with self._lock:
            now = self.clock()
            frame = self._frames[-1] if self._frames else None
            return {
                "version": self._version,
                "now": now,
                "clock": self.clock_kind,
                "t0": self.t0,
                "operator": self.operator,
                "structure": self.structure(),
                "goal_source": self._goal_source,
                "goals": {k: [u, s] for k, (u, s, _v) in self._goals.items()},
                "analysis": dict(self._analysis),
                "monitor": self._monitor_rows(now, 0),
                "values": self._values(),
                "oracle": list(self._oracle.values()),
                "camera": self._camera(frame),
                "executions": list(self._executions),
                "decisions": list(self._decisions),
                "timeline": list(self._timeline),
                "utu_t": self._utu_t,
                "latest_t": self._latest_t,
                "run": self.run(),
            }

    def frame_rate(self, window: float = 2.0) -> float | None:
        """Frames a second on the frames' own stamps, over the last ``window`` seconds of them.

        ``(n - 1) / (last stamp - first stamp)`` for the ``n`` frames stamped within
        ``window`` of the latest: a burst of late arrivals does not raise it. ``None`` with
        fewer than two frames in the window.
        """
        with self._lock:
            stamps = self._frame_stamps
            if len(stamps) < 2:
                return None
            last = stamps[-1]
            inside = [t for t in stamps if t >= last - window]
            span = last - inside[0]
            if len(inside) < 2 or span <= 0:
                return None
            return (len(inside) - 1) / span

    def _camera(self, frame: Frame | None) -> dict[str, Any]:
        out: dict[str, Any] = {
            "active": self._active_model,
            "frames": self._camera_count,
            "fps": self.frame_rate(),
        }
        if frame is not None:
            out["frame"] = {
                "topic": frame.topic,
                "seq": frame.seq,
                "width": frame.width,
                "height": frame.height,
                "t": frame.t,
            }
            out["detections"] = self._detections.get(frame.seq) or (
                self._detections[max(self._detections)] if self._detections else None
            )
        elif self._detections:
            out["detections"] = self._detections[max(self._detections)]
        return out

    def delta(self, since: int, *, decisions_after: int, timeline_after: int) -> dict[str, Any]:
        """What changed after version ``since``, for a page that has seen it.

        Args:
            since: The version the page shows.
            decisions_after: The ``n`` of the last decision the page has.
            timeline_after: The ``n`` of the last timeline point the page has.

        Returns:
            ``{version, now, ...}`` with only the sections that changed (goals: only the
            changed nodes; decisions and timeline: only the new rows).

        """
        with self._lock:
            now = self.clock()
            out: dict[str, Any] = {
                "version": self._version,
                "now": now,
                "utu_t": self._utu_t,
                "latest_t": self._latest_t,
                "run": self.run(),
            }
            if self._version <= since:
                return out
            goals = {k: [u, s] for k, (u, s, v) in self._goals.items() if v > since}
            if goals:
                out["goals"] = goals
                out["goal_source"] = self._goal_source
            if self._analysis_v > since:
                out["analysis"] = dict(self._analysis)
            rows = self._monitor_rows(now, since)
            if rows:
                out["monitor"] = rows
                out["values"] = self._values()
            if self._oracle_v > since:
                out["oracle"] = list(self._oracle.values())
            if self._camera_v > since:
                out["camera"] = self._camera(self._frames[-1] if self._frames else None)
            if self._executions_v > since:
                out["executions"] = list(self._executions)
            new = [d for d in self._decisions if d["n"] > decisions_after]
            if new:
                out["decisions"] = new
            points = [p for p in self._timeline if p["n"] > timeline_after]
            if points:
                out["timeline"] = points
            return out


def _describe_condition(cond: Any) -> str:
    goal = getattr(cond, "goal", None)
    if goal is not None:
        return f"{goal} {getattr(cond, 'state', '')}".strip()
    expression = getattr(cond, "expression", None)
    return str(expression) if expression is not None else str(cond)
