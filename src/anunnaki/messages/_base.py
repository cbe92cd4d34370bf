"""The base of every message type, and the slot that names them.

A message is a frozen pydantic model deriving from :class:`Message`; its class is
registered in :data:`MESSAGES` under its type name (``Message.type_name()``), so that a
receiver can turn the type name on the wire back into the class. The wire format itself
(the envelope, the binary frame for images) belongs to the transport,
:mod:`anunnaki.bus`.

Message fields must be JSON-native (str, int, float, bool, None, lists, dicts, ``Literal``,
nested models): bodies are validated in pydantic's strict mode, which does not coerce
``"1"`` into ``1``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar, Self

from pydantic import BaseModel, ConfigDict

from anunnaki.errors import AnunnakiError
from anunnaki.plugins import Registry

__all__ = ["MESSAGES", "Message", "MessageError", "body_of"]


class MessageError(AnunnakiError, ValueError):
    """A message cannot be built, registered or encoded (not a Message, a taken name, …)."""


class Message(BaseModel):
    """Base class of every message on the bus.

    Subclass it, give the fields, and register the class in :data:`MESSAGES`::

        @MESSAGES.register
        class Detection(Message):
            VERSION = 1
            label: str
            score: float

    Class attributes:
        VERSION: Schema version written as ``v`` in the envelope; bump it on an incompatible
            change. A receiver accepts only the version it knows.
        TYPE_NAME: Name on the wire; the class name when not set. Must be unique.
        BINARY_FIELD: Name of one ``bytes`` field sent raw after the JSON header, or ``None``.
    """

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)

    VERSION: ClassVar[int] = 1
    TYPE_NAME: ClassVar[str | None] = None
    BINARY_FIELD: ClassVar[str | None] = None

    @classmethod
    def type_name(cls) -> str:
        """Return the name this type travels under (``TYPE_NAME`` or the class name)."""
        return cls.TYPE_NAME or cls.__name__

    def to_body(self) -> dict[str, Any]:
        """Return the JSON body of the envelope (without the binary field, if any)."""
        exclude = {self.BINARY_FIELD} if self.BINARY_FIELD else None
        return self.model_dump(mode="json", exclude=exclude)

    def binary(self) -> bytes | None:
        """Return the raw bytes of the binary field, or ``None`` for a pure-JSON type."""
        if self.BINARY_FIELD is None:
            return None
        value = getattr(self, self.BINARY_FIELD)
        return bytes(value)

    @classmethod
    def from_body(cls, body: dict[str, Any], binary: bytes | None = None) -> Self:
        """Validate a body (and the binary field's bytes) into a message.

        Raises:
            pydantic.ValidationError: The body does not fit the schema.

        """
        if cls.BINARY_FIELD is not None:
            body = {**body, cls.BINARY_FIELD: binary if binary is not None else b""}
        return cls.model_validate(body)


def body_of(message: object) -> dict[str, Any]:
    """The JSON object of a bus message, or of a plain mapping (``{}`` for anything else).

    Handlers that accept both a typed :class:`Message` and a dict (tests, in-process
    callers) read their input through this one function.
    """
    if isinstance(message, Message):
        return message.to_body()  # a copy; a Generic's is its object
    if isinstance(message, Mapping):
        return dict(message)
    return {}


def _check_message(cls: object) -> type[Message]:
    """A registrable message class, or :class:`MessageError` saying what is wrong."""
    if not (isinstance(cls, type) and issubclass(cls, Message)):
        raise MessageError(f"{cls!r} is not a subclass of anunnaki.messages.Message")
    fields: dict[str, Any] = cls.__pydantic_fields__
    if cls.BINARY_FIELD is not None and cls.BINARY_FIELD not in fields:
        raise MessageError(f"{cls.type_name()}: BINARY_FIELD {cls.BINARY_FIELD!r} is not a field")
    return cls


#: The message types: type name on the wire -> class. A slot like every other
#: (:class:`~anunnaki.plugins.Registry`): ``MESSAGES.register`` (a class decorator; the
#: same class twice is harmless, another class under a taken name an error),
#: ``MESSAGES.factory(name)``, ``MESSAGES.names()``; third parties' types by the entry-point
#: group ``anunnaki.messages``.
MESSAGES: Registry[Message] = Registry(
    "message type",
    group="anunnaki.messages",
    kind=Message,
    check=_check_message,
    error=MessageError,
    logger="anunnaki.messages",
    key=lambda cls: cls.type_name(),
)
