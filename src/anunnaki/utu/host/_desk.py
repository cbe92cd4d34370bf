"""Where the outside world enters the cycle, written once for every host.

An operator's call (``/utu/run_stop``, ``/utu/pause``, ``/utu/resume``, ``/utu/approve``,
``/utu/reload``), a run-stop heard on the ``/utu/run_stop`` topic and an agent node that
vanished (liveliness) all become *operator entries*: queued here, taken by the next cycle
at a defined point (the monitor stage's batch), recorded in the decision log with their
caller, repeated by a replay. The inline manager and the monitor node hold one
:class:`OperatorDesk` each; nothing of it is written twice.

Run-stop, written once too: every host listens on ``/utu/run_stop`` through
:func:`listen_run_stop`, and the execute stage of every host announces the run-stops it
performs (:func:`execute_stage`, :func:`announce_run_stop`). A stuck loop is the one thing
that cannot wait for the next cycle: the watchdog of a host's loop (:func:`loop_watchdog`)
tells the platform from its own thread (:func:`watchdog_run_stop`), the same way in every
host. :class:`DecisionFeed` publishes new decisions at a rate, for every host.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from anunnaki import topics
from anunnaki.bus import Bus, Sample, Subscriber
from anunnaki.errors import AnunnakiError
from anunnaki.messages import RunStop, body_of
from anunnaki.utu._config import UtuConfig
from anunnaki.utu.cycle._actions import ActionRunner
from anunnaki.utu.cycle._execute import ExecuteStage
from anunnaki.utu.cycle._knowledge import Knowledge
from anunnaki.utu.cycle._knowledge_stage import DecisionTail, decision_dict
from anunnaki.utu.cycle._mape import Actuator, Planner
from anunnaki.utu.cycle._monitor import MonitorStage
from anunnaki.utu.cycle._parts import UtuParts
from anunnaki.utu.host._actuators import stop_platform

__all__ = [
    "DecisionFeed",
    "OperatorDesk",
    "Watchdog",
    "announce_run_stop",
    "execute_stage",
    "listen_run_stop",
    "loop_watchdog",
    "watchdog_run_stop",
]

log = logging.getLogger("anunnaki.utu")


class OperatorDesk:
    """The queue of operator entries of one host, and the services that fill it.

    Args:
        stage: The host's monitor stage: it checks a request (the operator token, a reload's
            files) and turns it into an entry.
        wake: Called after an entry is queued (the host's loop takes it at once).
        watch: Called with the monitored topics after a request was taken (a reload may
            watch new topics); ``None`` when the host watches nothing itself.

    """

    def __init__(
        self,
        stage: MonitorStage,
        *,
        wake: Callable[[], None],
        watch: Callable[[list[str]], None] | None = None,
    ) -> None:
        self.stage = stage
        self._wake = wake
        self._watch = watch
        self._ops: list[dict[str, Any]] = []
        self._lock = threading.Lock()
        #: A run-stop was asked (and not resumed since): readiness says so at once, before
        #: the cycle that applies it.
        self.run_stop_asked = False

    def enqueue(self, entry: dict[str, Any]) -> None:
        """Queue one entry for the next cycle (safe from any thread)."""
        with self._lock:
            self._ops.append(entry)
        self._wake()

    def take(self) -> list[dict[str, Any]]:
        """Every entry queued so far, in order; the queue is empty afterwards."""
        with self._lock:
            ops, self._ops = self._ops, []
        return ops

    def __len__(self) -> int:
        return len(self._ops)

    @property
    def pending(self) -> bool:
        """Whether an entry waits for the next cycle."""
        return bool(self._ops)

    def stopping(self, in_force: bool) -> bool:
        """Whether readiness says ``run_stopped``: ``in_force`` (applied), or asked since."""
        return in_force or self.run_stop_asked

    def call(self, op: str, message: Any) -> dict[str, Any]:
        """An operator request (a service handler): checked now, queued, answered.

        A refused request (no operator token, a malformed one) is answered and not queued;
        a reload is checked at once (a broken file is refused with its error in the reply,
        and still queued, marked ``refused``, so the decision log says it).
        """
        entry, reply = self.stage.request(op, message)
        if entry is None:
            return reply
        if self._watch is not None:
            self._watch(self.stage.topics)
        if op == "run_stop" and reply["ok"]:
            self.run_stop_asked = True
        elif op == "resume":
            self.run_stop_asked = False
        self.enqueue(entry)
        return reply

    def heard_run_stop(self, caller: str, reason: str) -> None:
        """A run-stop heard on ``/utu/run_stop`` enters the cycle as an operator call."""
        self.run_stop_asked = True
        self.enqueue({"op": "run_stop", "caller": caller, "reason": reason})

    def node_changed(self, node: str, alive: bool) -> None:
        """A liveliness change: a vanished agent node enters the cycle (``node_lost``)."""
        if not alive:
            self.enqueue({"op": "node_lost", "node": node, "caller": "liveliness"})

    def declare(self, bus: Bus) -> list[Any]:
        """Offer the operator services on ``bus`` and watch the agents' nodes.

        The operator token is resolved here, by the one host that offers the services
        (:meth:`~anunnaki.utu.UtuConfig.operator_token`: the user's token file is written
        first if none is given), never by a host without a bus. Returns what was declared
        (the host closes it).
        """
        self.stage.operator_token = self.stage.parts.config.operator_token()
        declared: list[Any] = [
            bus.service(service, self._handler(op))
            for op, service in topics.OPERATOR_SERVICES.items()
        ]
        if any(a.node for a in self.stage.parts.model.agents.values()):
            declared.append(bus.watch_liveliness(self.node_changed))
        return declared

    def _handler(self, op: str) -> Callable[[Any], dict[str, Any]]:
        return lambda message: self.call(op, message)


def listen_run_stop(
    bus: Bus, utu: str, who: str, on_heard: Callable[[str, str], None]
) -> Subscriber:
    """Subscribe ``/utu/run_stop``, calling ``on_heard(caller, reason)`` for each run-stop.

    Every run-stop counts but the announcements of Utu ``utu`` itself (``caller``
    ``utu:<utu>``), which it already performs. ``who`` names the host in the log. Returns
    the subscription (the host closes it).
    """

    def heard(sample: Sample) -> None:
        body = body_of(sample.message)
        caller = str(body.get("caller") or sample.sender)
        if caller.startswith(f"utu:{utu}"):
            return
        reason = str(body.get("reason", "run-stop topic"))
        log.warning("%s: run-stop from %s: %s", who, caller, reason)
        on_heard(caller, reason)

    return bus.subscribe(topics.RUN_STOP, heard, queue=16)


def watchdog_run_stop(
    bus: Bus, config: UtuConfig, *, what: str, caller: str, stalled: float
) -> None:
    """The watchdog's run-stop, from its own thread while the loop of ``what`` is stuck.

    The platform is asked at once through the configured run-stop service on the bus (not
    through the loop's actuator, which may be what hangs), and ``/utu/run_stop`` tells every
    other part of Utu: a monitor (the inline manager's or the monitor node's) records it as
    an operator's run-stop by ``caller``, so the decision log and a replay have it.
    """
    reason = f"watchdog: {what} has not finished a round for {stalled:.1f} s"
    log.error("utu: %s; run-stop", reason)
    stop_platform(bus, config, reason=reason, caller=caller)


def loop_watchdog(
    bus: Bus | None, config: UtuConfig, *, what: str, caller: str, floor: float
) -> Watchdog | None:
    """The watchdog of one host's loop, or ``None`` (no ``watchdog`` configured, no bus).

    It fires after ``max(watchdog, floor)`` seconds without a beat (``floor``: what an idle
    round of the loop may wait) and run-stops the platform (:func:`watchdog_run_stop`).
    """
    limit = config.watchdog
    if limit is None or bus is None:  # it stops the platform over the bus
        return None

    def fire(stalled: float) -> None:
        watchdog_run_stop(bus, config, what=what, caller=caller, stalled=stalled)

    return Watchdog(fire, max(limit, floor))


def announce_run_stop(bus: Bus, utu: str, caller: str, reason: str) -> None:
    """Tell every part of Utu ``utu`` and any dashboard that it performs a run-stop.

    Published on ``/utu/run_stop`` with caller ``utu:<utu>``, which Utu's own listeners
    ignore (:func:`listen_run_stop`): they already perform it.
    """
    try:
        bus.publish(
            topics.RUN_STOP, RunStop(reason=f"{reason} (asked by {caller})", caller=f"utu:{utu}")
        )
    except AnunnakiError as exc:  # a closed bus at shutdown
        log.warning("could not announce run-stop: %s", exc)


def execute_stage(
    parts: UtuParts,
    knowledge: Knowledge,
    actuator: Actuator,
    *,
    bus: Bus | None,
    runner: ActionRunner | None,
    planner: Planner | None = None,
) -> ExecuteStage:
    """The execute stage as every host runs it: a run-stop it performs is announced.

    The announcement goes on ``/utu/run_stop`` of ``bus`` (:func:`announce_run_stop`;
    nothing without a bus); ``runner`` runs blocking requests off the loop; ``planner``:
    the tactic runtimes to take up (default: a new store).
    """
    utu = parts.config.name

    def announce(caller: str, reason: str) -> None:
        if bus is not None:
            announce_run_stop(bus, utu, caller, reason)

    return ExecuteStage(
        parts, knowledge, actuator, on_run_stop=announce, runner=runner, planner=planner
    )


class DecisionFeed:
    """New decisions of a knowledge base on ``/utu/knowledge/decisions``, for dashboards and logs.

    ``{decisions: [{id, t, kind, tactic, data}]}``, each decision once, from those written
    after the feed was made (by any writer of the knowledge base).

    Args:
        bus: Where to publish.
        knowledge: The knowledge base to follow.
        rate: At most this many publications a second of wall time (:meth:`due`).

    """

    def __init__(self, bus: Bus, knowledge: Knowledge, rate: float) -> None:
        self.bus = bus
        self.tail = DecisionTail(knowledge)
        self.period = 1.0 / rate
        self._next = 0.0

    def publish(self) -> bool:
        """Publish the decisions written since the last call; returns whether there were any."""
        rows = self.tail.read()
        if rows:
            self.bus.publish(topics.DECISIONS, {"decisions": [decision_dict(d) for d in rows]})
        return bool(rows)

    def due(self) -> bool:
        """Whether a publication is due now; if so, the next is one period from now."""
        now = time.monotonic()
        if now < self._next:
            return False
        self._next = now + self.period
        return True

    def wait(self) -> float:
        """Seconds until the next publication is due."""
        return max(0.0, self._next - time.monotonic())


class Watchdog:
    """Calls ``on_fire(stalled)`` once when a loop has not beaten for ``limit`` seconds.

    The loop calls :meth:`beat` before each step (or round); the watchdog's own thread
    checks four times per ``limit`` (at least every 0.25 s). It fires again only after
    the loop has beaten once more.
    """

    def __init__(self, on_fire: Callable[[float], None], limit: float) -> None:
        self.on_fire = on_fire
        self.limit = limit
        self._last = time.monotonic()
        self._fired = False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, name="utu-watchdog", daemon=True)
        self._thread.start()

    def beat(self) -> None:
        """The loop is about to step: it is alive."""
        self._last = time.monotonic()
        self._fired = False

    def _watch(self) -> None:
        while not self._stop.wait(min(self.limit / 4, 0.25)):
            stalled = time.monotonic() - self._last
            if stalled > self.limit and not self._fired:
                self._fired = True
                try:
                    self.on_fire(stalled)
                except Exception:  # the watchdog must outlive what it calls
                    log.exception("utu: the watchdog's run-stop raised")

    def close(self) -> None:
        """Stop watching."""
        self._stop.set()
        self._thread.join(timeout=2.0)
