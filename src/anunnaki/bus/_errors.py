"""Errors raised by the bus.

All of them derive from :class:`BusError` (itself an :class:`~anunnaki.errors.AnunnakiError`);
the ones a caller typically catches also derive from the matching builtin
(``TimeoutError``, ``ValueError``) so generic code keeps working.
"""

from __future__ import annotations

from anunnaki.errors import AnunnakiError

__all__ = [
    "BusClosedError",
    "BusConfigError",
    "BusConnectError",
    "BusError",
    "BusTimeout",
    "MalformedMessage",
    "ServiceError",
    "TopicNameError",
]


class BusError(AnunnakiError):
    """Base class of every error the bus raises."""


class BusTimeout(BusError, TimeoutError):
    """A request got no reply, or a pull subscriber got no message, within the deadline."""


class BusClosedError(BusError):
    """The bus, or the object used, is closed."""


class BusConnectError(BusError):
    """A zenoh session could not be opened (no router reachable, TLS refused, bad config)."""


class BusConfigError(BusError, ValueError):
    """A bus option or :class:`~anunnaki.bus.BusConfig` field is invalid."""


class ServiceError(BusError):
    """A service answered with an error (its handler raised, or it refused the request).

    Args:
        service: The service name, e.g. ``/lm_manager/swap_model``.
        error: The error text the service sent back.

    """

    def __init__(self, service: str, error: str) -> None:
        self.service = service
        self.error = error
        super().__init__(f"service {service!r} failed: {error}")


class TopicNameError(BusError, ValueError):
    """A topic, service, node or pattern name breaks a naming rule.

    The message names the offending name and the rule, e.g.
    ``invalid topic name '/a//b': empty segment (rule: …)``.
    """


class MalformedMessage(BusError, ValueError):
    """Bytes on the wire are not a valid envelope of a known, valid message.

    Subscribers never see this error: a malformed message is dropped, counted in
    ``bus.stats().malformed`` and logged. It is raised by :func:`~anunnaki.bus.decode_envelope`
    for callers that decode by hand (bridges, trace replay).
    """
