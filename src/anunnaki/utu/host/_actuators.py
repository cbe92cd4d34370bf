"""How tactic actions reach the managed system: over the bus, or recorded (tests, replay)."""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future
from typing import Any

from anunnaki import topics
from anunnaki.errors import AnunnakiError
from anunnaki.messages import RunStop, body_of
from anunnaki.tactics import Notice
from anunnaki.utu._config import UtuConfig
from anunnaki.utu.cycle._actions import ActionOutcome

__all__ = ["BusActuator", "RecordingActuator", "bus_actuator", "stop_platform"]

log = logging.getLogger("anunnaki.utu")


class RecordingActuator:
    """An actuator that performs nothing and records what it was asked (tests, replay).

    Args:
        replies: The reply of each service (default ``{}``).
        outcomes: Whether each action succeeds, in the order they are asked for, as
            ``(ok, detail)`` (a replay gives the recorded ones, so a run whose action failed
            escalates again); past the end, every action succeeds.

    """

    def __init__(
        self,
        replies: Mapping[str, Mapping[str, Any]] | None = None,
        *,
        outcomes: Sequence[tuple[bool, str]] = (),
    ) -> None:
        self.calls: list[tuple[str, str, dict[str, Any]]] = []
        self.replies = dict(replies or {})
        self._outcomes = deque(outcomes)

    def _outcome(self, detail: str, reply: dict[str, Any] | None = None) -> ActionOutcome:
        if self._outcomes:
            ok, recorded = self._outcomes.popleft()
            return ActionOutcome(ok, recorded, reply if ok else None)
        return ActionOutcome(True, detail, reply)

    def publish(self, topic: str, payload: Mapping[str, Any]) -> ActionOutcome:
        """Record a publication."""
        self.calls.append(("publish", topic, dict(payload)))
        return self._outcome("published")

    def request(self, service: str, payload: Mapping[str, Any], timeout: float) -> ActionOutcome:
        """Record a request; reply with the configured reply or ``{}``."""
        self.calls.append(("request", service, dict(payload)))
        return self._outcome("replied", dict(self.replies.get(service, {})))

    def notify(self, action: Notice, tactic: str, now: float) -> ActionOutcome:
        """Record a notification."""
        self.calls.append(("notify", action.channel, {"to": action.to, "subject": action.subject}))
        return self._outcome("recorded")


class BusActuator:
    """Actions over the bus: publish on topics, request services, notify through a Notifier.

    ``blocking``: a request waits for the managed system, so a loop runs requests through
    an :class:`~anunnaki.utu.host.ThreadRunner` (off its path).
    """

    blocking = True

    def __init__(
        self,
        bus: Any,
        notifier: Any | None = None,
        *,
        on_notified: Callable[[str, Any], None] | None = None,
    ) -> None:
        self.bus = bus
        self.notifier = notifier
        self.on_notified = on_notified

    def publish(self, topic: str, payload: Mapping[str, Any]) -> ActionOutcome:
        """Publish ``payload`` as a Generic message on ``topic``."""
        self.bus.publish(topic, dict(payload))
        return ActionOutcome(True, f"published on {topic}")

    def request(self, service: str, payload: Mapping[str, Any], timeout: float) -> ActionOutcome:
        """Request ``service``; a timeout or an error reply is a failed action."""
        try:
            reply = self.bus.request(
                service, dict(payload), timeout=timeout, wait_for_service=False
            )
        except AnunnakiError as exc:
            return ActionOutcome(False, f"{type(exc).__name__}: {exc}")
        return _outcome_of(service, reply)

    def request_start(
        self, service: str, payload: Mapping[str, Any], timeout: float
    ) -> Future[ActionOutcome]:
        """:meth:`request` without waiting: the reply completes the returned future.

        The bus's :meth:`~anunnaki.bus.Bus.request_start`: no thread waits for the reply.
        """
        outcome: Future[ActionOutcome] = Future()
        try:
            pending = self.bus.request_start(service, dict(payload), timeout=timeout)
        except AnunnakiError as exc:
            outcome.set_result(ActionOutcome(False, f"{type(exc).__name__}: {exc}"))
            return outcome

        def replied(done: Future[Any]) -> None:
            try:
                result = _outcome_of(service, done.result())
            except Exception as exc:  # a timeout, an error reply: a failed action
                result = ActionOutcome(False, f"{type(exc).__name__}: {exc}")
            outcome.set_result(result)

        pending.add_done_callback(replied)
        return outcome

    def notify(self, action: Notice, tactic: str, now: float) -> ActionOutcome:
        """Send through the notifier in the background (the loop never waits on SMTP)."""
        if self.notifier is None:
            log.info(
                "notify (%s to %s): %s — %s",
                action.channel,
                action.to,
                action.subject,
                action.message,
            )
            return ActionOutcome(True, "logged (no notifier configured)")
        from anunnaki.utu.host._notify import Notification

        note = Notification(
            channel=action.channel,
            to=action.to or "",
            subject=action.subject,
            message=action.message,
            tactic=tactic,
            t=now,
            details={},
        )
        callback = self.on_notified

        def done(result: Any) -> None:
            if callback is not None:
                callback(tactic, result)

        self.notifier.send_in_background(note, done)
        return ActionOutcome(True, f"{action.channel} notification queued")


def stop_platform(
    bus: Any, config: UtuConfig, *, reason: str, caller: str
) -> tuple[bool | None, str]:
    """Run-stop the platform from outside the loop (a watchdog, a launch whose node died).

    Asks the configured run-stop service once (a service that is not up fails at once) and
    publishes a :class:`~anunnaki.messages.RunStop` on ``/utu/run_stop`` for every other part of
    Utu (the monitor records it) and any dashboard.

    Returns:
        ``(ok, error)``: ``ok`` is ``None`` when no run-stop service is configured.

    """
    service = config.run_stop.service
    ok: bool | None = None
    error = ""
    if service is not None:
        try:
            bus.request(service, dict(config.run_stop.payload), timeout=1.0, wait_for_service=False)
            ok = True
        except AnunnakiError as exc:
            ok, error = False, str(exc)
            log.error("utu: the run-stop request to %s failed: %s", service, exc)
    try:
        bus.publish(topics.RUN_STOP, RunStop(reason=reason, caller=caller))
    except AnunnakiError as exc:
        log.error("utu: could not announce the run-stop: %s", exc)
    return ok, error


def bus_actuator(
    bus: Any, config: UtuConfig, *, on_notified: Callable[[str, Any], None] | None = None
) -> BusActuator:
    """The actuator of a host on ``bus``, with the configuration's notifier (if any)."""
    notifier = None
    if config.notify:
        from anunnaki.utu.host._notify import Notifier, NotifyConfig

        notifier = Notifier(NotifyConfig.model_validate(config.notify))
    return BusActuator(bus, notifier, on_notified=on_notified)


def _outcome_of(service: str, reply: Any) -> ActionOutcome:
    """A request's reply as an action's outcome: refused (``ok: false``) or replied."""
    body = body_of(reply)  # a Generic's object, or a ServiceReply's {ok, error, body}
    if body.get("ok") is False:
        return ActionOutcome(False, str(body.get("error") or "refused"), body)
    inner = body.get("body")
    if isinstance(inner, dict) and "ok" in body:
        body = inner
    return ActionOutcome(True, f"{service} replied", body)
