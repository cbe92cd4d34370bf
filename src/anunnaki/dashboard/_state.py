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

This module is the store itself: the lock, the version counter and listeners, the goals
and the analysis, the timeline and the run's liveliness. What it holds per pane lives
beside it, called with its lock held: the checks every message passes
(:mod:`~anunnaki.dashboard._checks`), the monitor's topics (``_monitor``), the camera's
frames and detections (``_camera``), the decision log and executions (``_decisions``),
and the page's fixed description of the model and tactics (``_structure``).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from typing import Any, Literal

from anunnaki.dashboard._camera import CameraPane, Frame
from anunnaki.dashboard._checks import (
    MAX_ASSESSORS,
    _name,
    _num,
    _plain,
    assessment_row,
    detections_row,
    parse_analysis,
    queue_rows,
)
from anunnaki.dashboard._decisions import FLAG_KINDS, DecisionLog
from anunnaki.dashboard._monitor import monitor_rows, topics_of
from anunnaki.dashboard._structure import describe
from anunnaki.goals import Evaluator, GoalModel
from anunnaki.tactics import TacticSet

__all__ = ["DashboardState", "Frame"]

log = logging.getLogger("anunnaki.dashboard")


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
        self._topics = topics_of(model)
        self._oracle: dict[str, dict[str, Any]] = {}
        self._oracle_when: dict[str, int] = {}
        self._oracle_heard = 0
        self._oracle_v = 0
        self._camera = CameraPane()
        self._camera_v = 0
        self._log = DecisionLog(decisions)
        self._executions_v = 0
        self._timeline: deque[dict[str, Any]] = deque(maxlen=timeline)
        self._timeline_n = 0
        self._latest_t: float | None = None  # the latest time any pane shows
        self.idle = idle
        self._wall = wall
        self._heard_at: float | None = None  # wall time of the last message
        self._utu_nodes: set[str] = set()  # Utu's nodes whose liveliness token is alive
        self._utu_seen = False
        self._ended: str | None = None  # why the run is over, when its launch said so
        # The assurance case: its drawing (rendered in this process, never from the bus) and
        # its live statuses (from /utu/assurance/state: plain strings, drawn as text).
        self._case_svg: str | None = None
        self._case: dict[str, Any] | None = None
        self._case_v = 0
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

    def end(self, reason: str) -> None:
        """The run is over (its launch closed the observer): ``run()`` says so, with ``reason``.

        A launch that serves its own dashboard (``anunnaki run --dashboard``) closes the
        observer before Utu's nodes stop, so their tokens' withdrawal is never heard: this
        is how the page learns that the run has ended, at once and for good.
        """
        with self._lock:
            self._ended = reason
            self._bump()
        self._changed()

    def run(self) -> dict[str, Any]:
        """Whether the run is live: ``{live, state, reason}``.

        ``state`` is ``"waiting"`` before any message, ``"ended"`` once the launch said the
        run is over (:meth:`end`), every Utu node seen has withdrawn its liveliness token or
        no message has arrived for :attr:`idle` seconds (wall clock), else ``"live"``. A run
        that is fed again is live again, unless its launch ended it.
        """
        with self._lock:
            if self._ended is not None:
                return {"live": False, "state": "ended", "reason": self._ended}
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

    def take_analysis(self, body: Mapping[str, Any]) -> None:
        """A ``/utu/analyze/state`` message: utilities, statuses, violations, eligible tactics.

        The message is checked first and applied as a whole: ill-typed fields are ignored,
        nodes the goal model does not have are dropped, and nothing is half-applied.
        """
        if not isinstance(body, Mapping):
            return
        parsed = parse_analysis(body, self._evaluator.index)
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
        rows = queue_rows(queue)
        if rows is not None:
            self.take_flags(queue=rows)

    def take_flags(self, **flags: Any) -> None:
        """Update analysis fields (``paused``, ``run_stopped``, ``queue``) from other topics.

        ``paused`` and ``run_stopped`` must be bools and ``queue`` a list; others are ignored.
        """
        clean: dict[str, Any] = {}
        for key, value in flags.items():
            if key == "queue":
                rows = queue_rows(value)
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

    def take_decisions(self, decisions: Iterable[Mapping[str, Any]]) -> None:
        """New decisions of the decision log (``/utu/knowledge/decisions`` or a query).

        Each decision is checked before its key is remembered, so a malformed one is skipped
        without hiding a later, well-formed copy; the others of the batch are kept.
        """
        changed = False
        with self._lock:
            self._heard_at = self._wall()
            for row, execution_changed in self._log.add(decisions):
                self._saw(row["t"])
                if execution_changed:
                    self._executions_v = self._bump()
                self._decision_flags(row)
                self._bump()
                changed = True
        if changed:
            self._changed()

    def _decision_flags(self, d: dict[str, Any]) -> None:
        flags = FLAG_KINDS.get(d["kind"])
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

    def take_assessment(self, topic: str, body: Mapping[str, Any], t: float | None = None) -> None:
        """A behavior assessment (``Assessment``, or any message with a ``category``).

        The category must be 0, 1 or 2 (the paper's categories); other messages are ignored.
        At most :data:`MAX_ASSESSORS` assessors are kept: a new one replaces the one heard
        from longest ago.
        """
        if not isinstance(body, Mapping):
            return
        row = assessment_row(topic, body, self.clock() if t is None else t)
        if row is None:
            return
        key = row["assessor"]
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
            self._camera.add_frame(frame)
            self._camera_v = self._bump()
        self._changed()

    def take_detections(self, body: Mapping[str, Any]) -> None:
        """An LEC's detections for one frame (``Detections``)."""
        if not isinstance(body, Mapping):
            return
        row = detections_row(body)
        if row is None:
            return
        with self._lock:
            self._heard_at = self._wall()
            self._camera.add_detections(row)
            self._camera_v = self._bump()
        self._changed()

    def take_active_model(self, body: Mapping[str, Any]) -> None:
        """The model manager's announcement ``{lec, model, domain}``."""
        if not isinstance(body, Mapping):
            return
        with self._lock:
            self._heard_at = self._wall()
            self._camera.active_model = {
                "lec": _name(body.get("lec")),
                "model": _name(body.get("model")),
                "domain": _name(body.get("domain")),
                "source": "lm_manager",
            }
            self._camera_v = self._bump()
        self._changed()

    def set_case_drawing(self, svg: str | None) -> None:
        """The assurance case's drawing (``anunnaki.assurance.render_svg``), made here."""
        with self._lock:
            self._case_svg = svg
            self._case_v = self._bump()
        self._changed()

    @property
    def case_drawing(self) -> str | None:
        """The assurance case's SVG, when one was given."""
        return self._case_svg

    def take_assurance(self, body: Mapping[str, Any]) -> None:
        """The live case's statuses (``/utu/assurance/state`` or its query's answer).

        Each node's ``[status, reason]``; anything malformed is dropped (any bus client may
        publish here: it is shown, never trusted as markup).
        """
        if not isinstance(body, Mapping) or not isinstance(body.get("nodes"), Mapping):
            return
        seq = body.get("seq")
        nodes: dict[str, list[str]] = {}
        for nid, pair in body["nodes"].items():
            if isinstance(nid, str) and isinstance(pair, list | tuple) and len(pair) == 2:
                nodes[nid[:64]] = [str(pair[0])[:16], str(pair[1])[:500]]
        claims = body.get("claims")
        with self._lock:
            old = self._case
            if (
                old is not None
                and isinstance(seq, int)
                and isinstance(old.get("seq"), int)
                and seq < old["seq"]
                and body.get("case") == old.get("case")
            ):
                return  # an older state (the query's answer after a newer publication)
            self._heard_at = self._wall()
            self._case = {
                "case": _name(body.get("case")),
                "root": _name(body.get("root")),
                "t": _num(body.get("t")),
                "seq": seq if isinstance(seq, int) else None,
                "active_model": _name(body.get("active_model")),
                "perceived": _name(body.get("perceived")),
                "claims": [c for c in claims if isinstance(c, str)][:64]
                if isinstance(claims, list)
                else [],
                "nodes": nodes,
            }
            self._case_v = self._bump()
        self._changed()

    # -- readers (web server) ---------------------------------------------------------------
    def frame(self, seq: int | None = None) -> Frame | None:
        """The latest camera frame, or the one with sequence number ``seq`` if still kept."""
        with self._lock:
            return self._camera.frame(seq)

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
        return describe(self.name, self.model, self.tactics)

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
                "monitor": monitor_rows(self._topics, now, 0),
                "values": self._values(),
                "oracle": list(self._oracle.values()),
                "camera": self._camera.view(self._camera.latest()),
                "executions": list(self._log.executions),
                "decisions": list(self._log.decisions),
                "timeline": list(self._timeline),
                "utu_t": self._utu_t,
                "latest_t": self._latest_t,
                "run": self.run(),
                "assurance": self._case,
                "assurance_drawing": self._case_svg is not None,
            }

    def frame_rate(self, window: float = 2.0) -> float | None:
        """Frames a second on the frames' own stamps, over the last ``window`` seconds of them.

        ``(n - 1) / (last stamp - first stamp)`` for the ``n`` frames stamped within
        ``window`` of the latest: a burst of late arrivals does not raise it. ``None`` with
        fewer than two frames in the window.
        """
        with self._lock:
            return self._camera.frame_rate(window)

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
            rows = monitor_rows(self._topics, now, since)
            if rows:
                out["monitor"] = rows
                out["values"] = self._values()
            if self._oracle_v > since:
                out["oracle"] = list(self._oracle.values())
            if self._camera_v > since:
                out["camera"] = self._camera.view(self._camera.latest())
            if self._executions_v > since:
                out["executions"] = list(self._log.executions)
            if self._case_v > since:
                out["assurance"] = self._case
                out["assurance_drawing"] = self._case_svg is not None
            new = [d for d in self._log.decisions if d["n"] > decisions_after]
            if new:
                out["decisions"] = new
            points = [p for p in self._timeline if p["n"] > timeline_after]
            if points:
                out["timeline"] = points
            return out
