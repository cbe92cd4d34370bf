"""The messages every node may speak: any JSON object, the clock, service replies, modes.

``Generic`` is what a robot's sensor topics publish; ``Clock`` is simulation time;
``ServiceReply`` the generic answer of a service (and the form of every service error);
``ModeRequest``/``ModeReply`` and ``RunStop`` are what Utu asks of a managed system.
"""

from __future__ import annotations

from typing import Any, Self

from pydantic import Field, JsonValue, model_validator

from anunnaki.messages._base import MESSAGES, Message

__all__ = ["Clock", "Generic", "ModeReply", "ModeRequest", "RunStop", "ServiceReply"]


@MESSAGES.register
class Generic(Message):
    """Any JSON object: what a robot's sensor topics publish.

    The body on the wire *is* the object, e.g. ``{"mode": "autonomous", "buzzer": false}``;
    read it as ``msg.data["mode"]`` or ``msg["mode"]``.
    """

    data: dict[str, JsonValue] = Field(default_factory=dict)

    def to_body(self) -> dict[str, Any]:
        """Return the object itself."""
        return dict(self.data)

    @classmethod
    def from_body(cls, body: dict[str, Any], binary: bytes | None = None) -> Self:
        """Wrap the object."""
        return cls.model_validate({"data": body})

    def __getitem__(self, key: str) -> JsonValue:
        return self.data[key]


@MESSAGES.register
class Clock(Message):
    """Simulation time (the ROS ``/clock`` topic).

    Attributes:
        time: Simulated time in seconds since the start of the simulation (>= 0).

    """

    time: float = Field(ge=0.0)


@MESSAGES.register
class ModeRequest(Message):
    """Ask a managed system to change its operating mode (e.g. the fail-safe tactic).

    Attributes:
        mode: The mode wanted, e.g. ``"manual"`` or ``"autonomous"``.
        reason: Why, for logs and the dashboard.
        caller: Who asks (node name).

    """

    mode: str = Field(min_length=1)
    reason: str = ""
    caller: str = ""


@MESSAGES.register
class ModeReply(Message):
    """The answer to a :class:`ModeRequest`.

    Attributes:
        mode: The mode in force after the request.
        accepted: Whether the requested mode was taken.
        reason: Why not, when refused.

    """

    mode: str
    accepted: bool
    reason: str = ""


@MESSAGES.register
class ServiceReply(Message):
    """A generic service reply, and the form every service error takes on the wire.

    ``ok=False`` carries ``error`` (a requester sees :class:`~anunnaki.bus.ServiceError`);
    ``ok=True`` may carry a JSON ``body``.
    """

    ok: bool
    error: str | None = None
    body: dict[str, JsonValue] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _error_iff_not_ok(self) -> Self:
        if self.ok and self.error is not None:
            raise ValueError("an ok reply carries no error")
        if not self.ok and not self.error:
            raise ValueError("a failed reply must say what the error is")
        return self


@MESSAGES.register
class RunStop(Message):
    """Stop the whole system now (guideline S4). Sent on ``/utu/run_stop`` at top priority.

    Attributes:
        reason: Why the system is stopped.
        caller: Who stopped it.

    """

    reason: str = Field(min_length=1)
    caller: str = Field(min_length=1)
