"""A scripted managed system: replays a trace onto the bus and obeys commands.

It stands in for a robot in tests and examples. It publishes each record of a trace at its
time and exposes the same topics and services as the simulated platforms (guideline H1):

* ``<prefix>/set_mode`` (service, ``{mode}``) — from then on the ``mode`` field of every
  status message is the requested mode, whatever the trace says;
* ``<prefix>/stop`` (service, ``{reason}``) — run-stop: status messages report
  ``stopped: true`` and mode ``stopped``;
* ``<prefix>/buzzer`` (topic, ``{on}``) — the status's ``buzzer`` field follows;
* ``<prefix>/teleop`` (topic) — accepted and counted in manual mode;
* ``/clock`` — the simulation time, when ``publish_clock`` is set.

Time is the trace's: ``step(until)`` publishes every record up to ``until`` (deterministic
tests), ``run(clock)`` publishes live at ``speed`` × real time.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from anunnaki import topics
from anunnaki._closing import Closing
from anunnaki.bus import LivelinessGuard
from anunnaki.messages import Clock, body_of
from anunnaki.trace import Record, read_trace

__all__ = ["ScriptedSystem"]

log = logging.getLogger("anunnaki.managed")


class ScriptedSystem(Closing):
    """Replays a trace on a bus and obeys mode, stop and buzzer commands.

    Args:
        bus: The bus to publish on and offer services on.
        trace: A trace file or its records.
        prefix: The platform's name prefix (``/rover`` or ``/uav``).
        status_topic: The topic whose messages carry ``mode``/``buzzer`` (default
            ``<prefix>/status``).
        modes: The modes ``set_mode`` accepts.
        publish_clock: Publish the trace time on ``/clock`` before each instant (at high
            priority, so that it reaches a node before the instant's messages).
        stop_without_utu: Seconds a Utu node it has seen may be gone before the system
            stops by itself (``None``: never), as a real platform should
            (docs/running.md#failure-behaviour).

    """

    def __init__(
        self,
        bus: Any,
        trace: str | Path | list[Record],
        *,
        prefix: str = "/rover",
        status_topic: str | None = None,
        modes: tuple[str, ...] = ("autonomous", "manual"),
        publish_clock: bool = False,
        stop_without_utu: float | None = 0.2,
    ) -> None:
        self.bus = bus
        self.records: list[Record] = (
            read_trace(trace).records if isinstance(trace, str | Path) else list(trace)
        )
        self.prefix = prefix
        self.status_topic = status_topic or f"{prefix}/status"
        self.modes = modes
        self.publish_clock = publish_clock
        # At high priority: assessments travel high and, across processes, could overtake
        # it; the time of an instant must reach a node before the instant's messages.
        self._clock = bus.publisher(topics.CLOCK, priority="high") if publish_clock else None
        self.overrides: dict[str, Any] = {}
        self.commands: list[tuple[float, str, dict[str, Any]]] = []
        self.teleop = 0
        self.t = float("-inf")
        self._next = 0
        self._lock = threading.Lock()
        self._intake = threading.Lock()  # buzzer commands are applied one caller at a time
        # Buzzer commands are applied where they arrive (in-process: in the publisher's
        # thread, before its publish returns), not on a subscriber thread of their own: one
        # that ran late let the next instants' status miss a command Utu had sent, and the
        # postcondition failed under load.
        self._buzzers: Any = None
        self._declared = [
            bus.service(f"{prefix}/set_mode", self._set_mode),
            bus.service(f"{prefix}/stop", self._stop),
            bus.subscribe(f"{prefix}/teleop", self._teleop, queue=64),
        ]
        self._buzzers = bus.subscribe(f"{prefix}/buzzer", queue=16, on_ready=self._take_buzzers)
        self._declared.append(self._buzzers)
        if stop_without_utu is not None:
            self._declared.append(
                LivelinessGuard(
                    bus,
                    lambda why: self._stop({"reason": f"Utu lost: {why}"}),
                    timeout=stop_without_utu,
                )
            )

    # -- commands ---------------------------------------------------------------------------
    def _set_mode(self, message: Any) -> dict[str, Any]:
        body = body_of(message)
        mode = body.get("mode")
        if mode not in self.modes:
            return {"ok": False, "error": f"unknown mode {mode!r}; modes: {list(self.modes)}"}
        with self._lock:
            if self.overrides.get("stopped"):
                return {"ok": False, "error": "the system is stopped (run-stop)"}
            self.overrides["mode"] = mode
            self.commands.append((self.t, "set_mode", body))
        log.info("scripted system: mode -> %s", mode)
        return {"ok": True, "mode": mode}

    def _stop(self, message: Any) -> dict[str, Any]:
        body = body_of(message)
        with self._lock:
            self.overrides["stopped"] = True
            self.overrides["mode"] = "stopped"
            self.commands.append((self.t, "stop", body))
        log.info("scripted system: run-stop (%s)", body.get("reason"))
        return {"ok": True, "stopped": True}

    def _buzzer(self, sample: Any) -> None:
        body = body_of(sample.message)
        with self._lock:
            self.overrides["buzzer"] = bool(body.get("on", False))
            self.commands.append((self.t, "buzzer", body))

    def _take_buzzers(self) -> None:
        """Apply the buzzer commands queued so far, in their order."""
        with self._intake:
            sub = self._buzzers
            while sub is not None and (sample := sub.try_recv()) is not None:
                self._buzzer(sample)

    def _teleop(self, sample: Any) -> None:
        with self._lock:
            if self.overrides.get("mode") == "manual":
                self.teleop += 1

    # -- publishing -------------------------------------------------------------------------
    def message(self, record: Record) -> dict[str, Any]:
        """The message actually published for ``record`` (with commands applied)."""
        msg = dict(record.msg)
        if record.topic == self.status_topic:
            with self._lock:
                msg.update(self.overrides)
        return msg

    def step(self, until: float) -> int:
        """Publish every record with ``t <= until``; returns how many."""
        self._take_buzzers()
        n = 0
        while self._next < len(self.records) and self.records[self._next].t <= until:
            rec = self.records[self._next]
            if rec.t != self.t:
                self.t = rec.t
                if self._clock is not None:
                    self._clock.put(Clock(time=max(rec.t, 0.0)))
            self.bus.publish(rec.topic, self.message(rec))
            self._next += 1
            n += 1
        self.t = max(self.t, until)
        return n

    @property
    def done(self) -> bool:
        """Whether every record has been published."""
        return self._next >= len(self.records)

    @property
    def end(self) -> float:
        """The time of the last record."""
        return self.records[-1].t if self.records else 0.0

    def instants(self) -> list[float]:
        """The distinct record times, in order."""
        out: list[float] = []
        for r in self.records:
            if not out or r.t != out[-1]:
                out.append(r.t)
        return out

    def run(
        self,
        stop: threading.Event | None = None,
        *,
        speed: float = 1.0,
        start: float | None = None,
    ) -> None:
        """Publish live: record times are scaled by ``1/speed`` from the wall clock."""
        stop = stop or threading.Event()
        t0 = self.records[0].t if self.records else 0.0
        wall0 = time.monotonic() if start is None else start
        for instant in self.instants():
            due = wall0 + (instant - t0) / speed
            delay = due - time.monotonic()
            if delay > 0 and stop.wait(delay):
                return
            self.step(instant)

    def state(self) -> Mapping[str, Any]:
        """The commanded state (mode, stopped, buzzer)."""
        with self._lock:
            return dict(self.overrides)

    def close(self) -> None:
        """Withdraw the services and subscriptions."""
        for d in self._declared:
            d.close()
        self._declared.clear()
