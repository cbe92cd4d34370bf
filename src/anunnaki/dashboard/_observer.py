"""The dashboard on the bus: a read-only observer, plus the operator's calls of Utu's services.

:class:`BusObserver` subscribes the same topics Utu's nodes use and writes what arrives into
a :class:`~anunnaki.dashboard.DashboardState`:

=============================== ========================================================
``/utu/analyze/state``          utilities and statuses, violations, eligible tactics,
                                the queue and the pause/run-stop flags
``/utu/plan/start``             the queue (per-node runs)
``/utu/execute/status``         pause and run-stop flags (per-node runs)
``/utu/knowledge/decisions``    a doorbell: new decisions, fetched from ``/utu/knowledge/query``
the agents' topics (binding)    the monitor pane and the dashboard's own evaluation
``/utu/oracle/**``              assessments (category, confidence, context)
``/*/camera/image``             camera frames (``Image``)
``/lec/*/detections``           detection boxes (``Detections``)
``/lm_manager/active``          the active model and its domain
``/utu/assurance/state``        the live assurance case's statuses (asked once at start
                                from ``/utu/assurance/query``)
``/clock``                      simulation time, when Utu runs on ``clock: sim``
=============================== ========================================================

Each has its own bounded queue, so a flood of camera frames cannot delay the analysis
(guideline S1). At start it asks ``/utu/knowledge/query`` for the decisions and the state
(the plan's queue included) so far, so a dashboard started after Utu still shows the whole
log and any pending approval.

It never writes to the bus, except for the operator's actions (:meth:`BusObserver.operate`),
which are requests to Utu's services ``/utu/pause``, ``/utu/resume``, ``/utu/approve`` and
``/utu/run_stop`` carrying the caller: Utu records each in its decision log.
"""

from __future__ import annotations

import bisect
import itertools
import logging
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any, Literal

from anunnaki import topics
from anunnaki._closing import Closing
from anunnaki.bus import Bus, BusError, Sample, ServiceError
from anunnaki.dashboard._state import DashboardState, Frame
from anunnaki.errors import AnunnakiError
from anunnaki.messages import Assessment, Clock, Detections, Generic, Image, body_of
from anunnaki.tokens import client_operator_token

__all__ = ["OPERATIONS", "BusObserver", "ObserverConfig", "OperatorError", "SimTime"]

log = logging.getLogger("anunnaki.dashboard")
#: The badge's reason once the observer is closed: its launch's run is over.
RUN_ENDED = "the run has ended"


Operation = Literal["pause", "resume", "approve", "reject", "run_stop"]
#: The operator's actions and the Utu service each calls.
OPERATIONS: dict[str, str] = {
    "pause": topics.PAUSE,
    "resume": topics.RESUME,
    "approve": topics.APPROVE,
    "reject": topics.APPROVE,
    "run_stop": topics.RUN_STOP,
}


class OperatorError(AnunnakiError):
    """An operator action was not accepted (bad request, or Utu did not answer)."""


@dataclass(frozen=True)
class ObserverConfig:
    """Where the observer listens (ROS-style names and patterns).

    Attributes:
        state: Utu's analysis topic.
        plan: The plan node's start topic (its queue).
        status: The execute node's status topic (pause and run-stop flags).
        decisions: Utu's decision topic.
        query: Utu's knowledge query service (asked once at start).
        oracle: Pattern of the assessment topics.
        camera: Pattern of the camera topics (``Image``).
        detections: Pattern of the detection topics (``Detections``).
        active_model: The model manager's announcement topic.
        clock: The simulation clock topic (read when the observer is given a sim clock).
        assurance: The live assurance case's state topic.
        assurance_query: Its query service (asked once at start).
        query_timeout: Seconds to wait for Utu's answer at start.

    """

    state: str = topics.ANALYSIS
    plan: str = topics.PLAN_START
    status: str = topics.EXECUTE_STATUS
    decisions: str = topics.DECISIONS
    query: str = topics.QUERY
    oracle: str = "/utu/oracle/**"
    camera: str = "/*/camera/image"
    detections: str = "/lec/*/detections"
    active_model: str = topics.ACTIVE_MODEL
    clock: str = topics.CLOCK
    assurance: str = topics.ASSURANCE_STATE
    assurance_query: str = topics.ASSURANCE_QUERY
    query_timeout: float = 3.0


class SimTime:
    """Simulation time for the dashboard, and the simulation time of each input.

    Utu on ``clock: sim`` takes each input at the simulated instant it was published in.
    The dashboard's subscribers run on separate threads, so "the latest ``/clock`` when the
    input is handled" can be an instant off, enough to misjudge a 4.8 Hz sensor. Instead an
    input is stamped with the simulated time of the last ``/clock`` its *sender* published
    before it (both envelopes carry the sender's wall clock), which is exactly its instant.
    An input waits (briefly) until that is known: a later clock from the same sender has
    arrived, or ``patience`` seconds have passed. Senders that publish no clock (a node in
    another process) get the latest simulation time.

    :meth:`now` is a watermark: it never runs ahead of an input still waiting, so the
    dashboard's evaluation never judges staleness or rates before the inputs are in.
    """

    #: Most senders of ``/clock`` remembered at once.
    MAX_SENDERS = 64

    def __init__(self, *, patience: float = 0.2, history: int = 512) -> None:
        self.patience = patience
        self._lock = threading.Lock()
        self._latest = 0.0
        self._mark = 0.0
        self._clocks: dict[str, deque[tuple[float, float]]] = {}
        self._history = history
        self._pending: list[tuple[float, int, float, str, str, dict[str, Any]]] = []
        self._order = itertools.count()

    def now(self) -> float:
        """The time up to which every input has been handled (seconds)."""
        return self._mark

    def instant(self, sender: str, sent_at: float) -> float:
        """The simulated instant of a message published at ``sent_at`` (no waiting).

        The simulated time of the last ``/clock`` its sender published before it, or the
        latest simulation time for a sender that publishes no clock. For camera frames,
        whose rate is measured on these instants, not on their arrivals.
        """
        with self._lock:
            hist = self._clocks.get(sender)
            if hist is None:
                return self._latest
            i = bisect.bisect_right(hist, (sent_at, float("inf"))) - 1
            return max(hist[i][1] if i >= 0 else hist[0][1], 0.0)

    def clock(self, sender: str, sent_at: float, t: float) -> None:
        """A ``/clock`` message: ``t`` simulated seconds, published at ``sent_at`` (wall)."""
        with self._lock:
            if sender not in self._clocks and len(self._clocks) >= self.MAX_SENDERS:
                # Bounded: forget the sender whose clock was heard from longest ago.
                del self._clocks[min(self._clocks, key=lambda k: self._clocks[k][-1][0])]
            hist = self._clocks.setdefault(sender, deque(maxlen=self._history))
            if not hist or sent_at >= hist[-1][0]:
                hist.append((sent_at, t))
            self._latest = max(self._latest, t)

    def add(self, sender: str, sent_at: float, topic: str, body: dict[str, Any]) -> None:
        """An input to stamp; collect it with :meth:`ready`."""
        with self._lock:
            self._pending.append(
                (sent_at, next(self._order), time.monotonic(), sender, topic, body)
            )

    def ready(self) -> list[tuple[float, str, dict[str, Any]]]:
        """The inputs whose time is known, in publication order: ``(t, topic, body)``."""
        out: list[tuple[float, int, float, str, dict[str, Any]]] = []
        with self._lock:
            keep = []
            now = time.monotonic()
            for item in self._pending:
                sent_at, order, arrived, sender, topic, body = item
                hist = self._clocks.get(sender)
                if hist is None:
                    out.append((sent_at, order, self._latest, topic, body))
                    continue
                if hist[-1][0] < sent_at and now - arrived < self.patience:
                    keep.append(item)
                    continue
                i = bisect.bisect_right(hist, (sent_at, float("inf"))) - 1
                t = hist[i][1] if i >= 0 else hist[0][1]
                out.append((sent_at, order, t, topic, body))
            self._pending = keep
            out.sort(key=lambda x: (x[0], x[1]))
            self._mark = max([self._mark, *(x[2] for x in out)])
            if not keep:
                self._mark = max(self._mark, self._latest)
        return [(max(t, 0.0), topic, body) for _s, _o, t, topic, body in out]


class BusObserver(Closing):
    """Subscribes a bus for a :class:`DashboardState`; closes what it declared.

    Args:
        bus: The bus (shared with Utu in one process, or a session of its own).
        state: Where to write.
        config: Topic names and patterns.
        sim: On ``clock: sim``: the simulation time the state reads (its ``now``), moved on
            by the ``/clock`` topic; inputs are stamped with their instant. ``None``: wall
            clock, inputs stamped with their sender's time as Utu does.
        seed: Ask Utu's knowledge service for the state and decisions so far (in the
            background; nothing waits for it).

    """

    def __init__(
        self,
        bus: Bus,
        state: DashboardState,
        config: ObserverConfig | None = None,
        *,
        sim: SimTime | None = None,
        seed: bool = True,
    ) -> None:
        self.bus = bus
        self.state = state
        self.config = config or ObserverConfig()
        self.sim = sim
        self._declared: list[Any] = []
        self._closed = threading.Event()
        self._seeded = threading.Event()
        self._inputs_lock = threading.Lock()
        self._doorbell = threading.Event()  # Utu wrote decisions: fetch them from its service
        self._last_id = 0
        self._fetch_failed = False
        self._fetch_lock = threading.Lock()
        c = self.config
        try:
            if sim is not None:
                self._sub(c.clock, self._on_clock, 8, Clock)
            self._sub(c.state, self._on_state, 8)
            self._sub(c.plan, self._on_plan, 8)
            self._sub(c.status, self._on_status, 8)
            self._sub(c.decisions, self._on_decisions, 1024)
            for topic in state.model.topic_routes():
                self._sub(topic, self._on_input, 256)
            self._sub(c.oracle, self._on_assessment, 64)
            self._sub(c.camera, self._on_frame, 4, Image)
            self._sub(c.detections, self._on_detections, 16, Detections)
            self._sub(c.active_model, self._on_active, 8)
            self._sub(c.assurance, self._on_assurance, 8)
            self._declared.append(bus.watch_liveliness(self._on_liveliness))
        except BaseException:
            self.close()
            raise
        self._ticker = threading.Thread(
            target=self._tick, name="anunnaki-dashboard-tick", daemon=True
        )
        self._ticker.start()
        if seed:
            threading.Thread(target=self._seed, name="anunnaki-dashboard-seed", daemon=True).start()
        else:
            self._seeded.set()
        threading.Thread(
            target=self._fetch_decisions, name="anunnaki-dashboard-decisions", daemon=True
        ).start()

    def _sub(self, pattern: str, callback: Any, queue: int, expect: Any = None) -> None:
        self._declared.append(self.bus.subscribe(pattern, callback, queue=queue, expect=expect))

    def now(self) -> float:
        """The observer's time: the simulation's on a sim clock, else the wall clock."""
        return self.state.clock()

    # -- callbacks (one thread per subscriber) ---------------------------------------------
    def _on_liveliness(self, node: str, alive: bool) -> None:
        if node.startswith(topics.UTU_NODE_PREFIX):
            self.state.utu_node(node, alive)

    def _on_clock(self, sample: Sample) -> None:
        self.state.heard()
        t = getattr(sample.message, "time", None)
        if self.sim is not None and isinstance(t, float | int):
            self.sim.clock(sample.sender, sample.sent_at, float(t))
            self._take_ready()

    def _on_state(self, sample: Sample) -> None:
        self.state.take_analysis(body_of(sample.message))

    def _on_plan(self, sample: Sample) -> None:
        self.state.take_queue(body_of(sample.message).get("queue"))

    def _on_status(self, sample: Sample) -> None:
        body = body_of(sample.message)  # flags that are not bools are ignored
        self.state.take_flags(paused=body.get("paused"), run_stopped=body.get("run_stopped"))

    def _on_decisions(self, sample: Sample) -> None:
        # A doorbell, never the content: any bus client can publish on this topic, so the
        # rows are fetched from the attached Utu's knowledge service (issue #12).
        self._doorbell.set()

    def _fetch_decisions(self) -> None:
        """Fetch the decisions written since the last one shown: on each ring, and every 2 s."""
        self._seeded.wait()
        while not self._closed.is_set():
            self._doorbell.wait(2.0)
            if self._closed.is_set():
                return
            self._doorbell.clear()
            self._fetch()

    def _fetch(self, *, wait_for_service: bool = True) -> None:
        """Ask Utu's knowledge service for the decisions after the last one shown.

        One fetch at a time (the fetcher's, or :meth:`close`'s last). A bus that has closed,
        or an observer closing, ends the run for this observer: no warning then.
        """
        c = self.config
        with self._fetch_lock:
            try:
                while True:
                    reply = body_of(
                        self.bus.request(
                            c.query,
                            {"what": "decisions", "after": self._last_id, "limit": 2000},
                            timeout=c.query_timeout,
                            wait_for_service=wait_for_service,
                        )
                    )
                    rows = reply.get("decisions")
                    if not isinstance(rows, list) or not rows:
                        break
                    self._take_decisions(rows)
                    if len(rows) < 2000:
                        break
            except (BusError, AnunnakiError) as exc:
                if self._closed.is_set() or self.bus.closed:
                    log.debug("dashboard: %s at the end of the run: %s", c.query, exc)
                elif not self._fetch_failed:
                    self._fetch_failed = True
                    log.warning(
                        "dashboard: %s does not answer (%s): decisions are shown only from "
                        "the Utu this dashboard is attached to",
                        c.query,
                        exc,
                    )

    def _take_decisions(self, rows: list[Any]) -> None:
        ids = [r["id"] for r in rows if isinstance(r, dict) and type(r.get("id")) is int]
        if ids:
            self._last_id = max(self._last_id, *ids)
        self.state.take_decisions(rows)

    def _on_input(self, sample: Sample) -> None:
        if self.sim is None:
            # On the wall clock Utu takes an input at its sender's stamp: so does this.
            self.state.take_input(sample.topic, body_of(sample.message), sample.sent_at)
            return
        self.sim.add(sample.sender, sample.sent_at, sample.topic, body_of(sample.message))
        self._take_ready()

    def _take_ready(self) -> None:
        assert self.sim is not None
        with self._inputs_lock:  # one writer at a time keeps publication order
            for t, topic, body in self.sim.ready():
                self.state.take_input(topic, body, t)

    def _on_assessment(self, sample: Sample) -> None:
        message = sample.message
        if isinstance(message, Assessment | Generic):
            self.state.take_assessment(sample.topic, body_of(message), self.now())

    def _on_frame(self, sample: Sample) -> None:
        m = sample.message
        assert isinstance(m, Image)
        # Stamped with its publication (its simulated instant on a sim clock), not its
        # arrival: frames arrive in bursts, and the frame rate is measured on the stamps.
        if self.sim is None:
            stamp = sample.sent_at
        else:
            stamp = self.sim.instant(sample.sender, sample.sent_at)
        self.state.take_frame(
            Frame(sample.topic, m.seq, m.encoding, m.width, m.height, m.data, stamp)
        )

    def _on_detections(self, sample: Sample) -> None:
        self.state.take_detections(body_of(sample.message))

    def _on_active(self, sample: Sample) -> None:
        self.state.take_active_model(body_of(sample.message))

    def _on_assurance(self, sample: Sample) -> None:
        self.state.take_assurance(body_of(sample.message))

    def _tick(self) -> None:
        while not self._closed.wait(0.1):
            try:
                if self.sim is not None:
                    self._take_ready()
                self.state.tick()
            except Exception:  # the ticker never dies of one bad evaluation
                log.exception("dashboard: evaluation tick failed")

    def _seed(self) -> None:
        c = self.config
        try:
            reply = body_of(
                self.bus.request(
                    c.query, {"what": "decisions", "limit": 2000}, timeout=c.query_timeout
                )
            )
            rows = reply.get("decisions")
            if isinstance(rows, list):
                self._take_decisions(rows)
            state = body_of(self.bus.request(c.query, {"what": "state"}, timeout=c.query_timeout))
            # The state answer carries the plan's queue: a late dashboard sees pending approvals.
            if state.get("ok") is not False and state.get("nodes") and not self.state.has_analysis:
                self.state.take_analysis(state)  # (a live analysis, when there is one, is newer)
        except (BusError, AnunnakiError) as exc:
            if not self._closed.is_set():
                log.info("dashboard: no answer from %s (%s); showing live data only", c.query, exc)
        finally:
            self._seed_case()
            self._seeded.set()

    def _seed_case(self) -> None:
        """The live case's statuses so far, when the dashboard draws a case."""
        if self.state.case_drawing is None:
            return
        c = self.config
        try:
            reply = self.bus.request(
                c.assurance_query, {}, timeout=c.query_timeout, wait_for_service=False
            )
            self.state.take_assurance(body_of(reply))
        except (BusError, AnunnakiError) as exc:  # not up yet: its topic will say
            log.info("dashboard: no answer from %s (%s)", c.assurance_query, exc)

    def wait_seeded(self, timeout: float | None = None) -> bool:
        """Wait until the start-up query is answered (or given up); returns whether it ended."""
        return self._seeded.wait(timeout)

    # -- the operator ------------------------------------------------------------------------
    def operate(
        self,
        op: str,
        *,
        caller: str,
        tactic: str | None = None,
        reason: str | None = None,
        timeout: float = 3.0,
    ) -> dict[str, Any]:
        """Call Utu's service for an operator action; Utu records it with ``caller``.

        Args:
            op: ``pause``, ``resume``, ``approve``, ``reject`` or ``run_stop``.
            caller: Who acts (recorded in the decision log).
            tactic: The pending tactic, for ``approve``/``reject``.
            reason: Why, for ``run_stop``.
            timeout: Seconds to wait for Utu's answer.

        Returns:
            Utu's reply (``{ok, queued, caller}``).

        Raises:
            OperatorError: An unknown action, a missing tactic, or no (or a refusing) answer.

        """
        service = OPERATIONS.get(op)
        if service is None:
            raise OperatorError(f"unknown action {op!r}; the actions are {', '.join(OPERATIONS)}")
        payload: dict[str, Any] = {"caller": caller}
        try:
            token = client_operator_token()  # Utu's operator token, not the dashboard's own
        except AnunnakiError as exc:  # the user's token file is unreadable or open to others
            raise OperatorError(str(exc)) from None
        if token is not None:
            payload["token"] = token
        if op in ("approve", "reject"):
            if not tactic:
                raise OperatorError(f"{op} needs the name of a pending tactic")
            payload.update(tactic=tactic, approve=op == "approve")
        if op == "run_stop":
            payload["reason"] = reason or "operator run-stop from the dashboard"
        try:
            reply = body_of(self.bus.request(service, payload, timeout=timeout))
        except ServiceError as exc:
            raise OperatorError(f"{service} refused: {exc}") from None
        except BusError as exc:
            raise OperatorError(f"{service} did not answer: {exc}") from None
        if reply.get("ok") is False:
            raise OperatorError(f"{service} refused: {reply.get('error') or 'no reason given'}")
        return reply

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called (the page keeps what it was shown)."""
        return self._closed.is_set()

    def close(self) -> None:
        """Fetch the last decisions, withdraw the subscriptions, stop the ticker. Idempotent.

        The page then says the run has ended (:data:`RUN_ENDED`).
        The last fetch asks Utu once more, while it may still answer (``anunnaki run
        --dashboard`` closes the observer after the run, before Utu's nodes stop and the bus
        closes): the page then shows the run's decisions to the end. A Utu that is not up
        fails it at once; a bus already closed skips it.
        """
        first = not self._closed.is_set()
        self._closed.set()
        self._doorbell.set()  # wakes the decision fetcher, which then ends
        if first and self._seeded.is_set() and not self.bus.closed:
            self._fetch(wait_for_service=False)
        if first:
            self.state.end(RUN_ENDED)
        for obj in reversed(self._declared):
            try:
                obj.close()
            except Exception as exc:  # best effort: the bus may be closing too
                log.debug("closing %r: %r", obj, exc)
        self._declared.clear()
