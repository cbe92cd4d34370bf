"""The wire format: a message in its envelope, as bytes.

A message is a frozen pydantic model deriving from :class:`anunnaki.messages.Message`,
named by its type name in :data:`anunnaki.messages.MESSAGES`. On the wire it travels inside
an envelope::

    {"v": 1, "type": "ModeRequest", "t": 1712.25, "seq": 7, "sender": "utu", "body": {...}}

``v`` is the schema version of the body's type (``Message.VERSION``), ``type`` the registered
type name, ``t`` the sender's clock in seconds (wall time or simulation time, whatever clock
the sender's bus was given), ``seq`` the sender's per-topic counter and ``sender`` the name of
the sending bus. The envelope is compact JSON (UTF-8), except for types that carry raw bytes
(:class:`~anunnaki.messages.Image`): those travel as a small binary frame so that pixels
are not base64-bloated::

    +----------------------+-------------------------+----------------------+
    | header length N      | header: the envelope as | raw bytes of the     |
    | 4 bytes, big-endian  | JSON, without the bytes | binary field         |
    +----------------------+-------------------------+----------------------+

A JSON envelope starts with ``{`` (0x7B); a binary frame starts with a length below 16 MiB, so
its first byte is 0x00: the first byte tells the two apart.

Decoding is strict: undecodable bytes, unknown keys, an unknown type, another schema version
or a body that fails validation raise :class:`MalformedMessage`. Subscribers turn that into a
dropped, counted, logged message; it never reaches a node's code.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, cast

from pydantic import ValidationError

from anunnaki.bus._errors import MalformedMessage
from anunnaki.errors import validation_message
from anunnaki.messages import MESSAGES, Generic, Message, MessageError

__all__ = ["Envelope", "decode_envelope", "encode_envelope"]

MAX_HEADER = 16 * 1024 * 1024
_ENVELOPE_KEYS = frozenset({"v", "type", "t", "seq", "sender", "body"})


@dataclass(frozen=True, slots=True)
class Envelope:
    """A message with the sender's metadata, as it travels on the bus.

    Attributes:
        message: The message.
        t: The sender's clock when it was sent, in seconds.
        seq: The sender's counter for this topic (starts at 0).
        sender: The sending bus's name.

    """

    message: Message
    t: float
    seq: int
    sender: str

    @property
    def type(self) -> str:
        """The message's type name."""
        return self.message.type_name()

    @property
    def v(self) -> int:
        """The message's schema version."""
        return self.message.VERSION


def _dumps(obj: Any) -> bytes:
    try:
        return json.dumps(obj, separators=(",", ":"), ensure_ascii=False, allow_nan=False).encode()
    except (TypeError, ValueError) as exc:
        raise MessageError(f"message is not JSON-serialisable: {exc}") from None


def encode_envelope(envelope: Envelope) -> bytes:
    """Encode an envelope to wire bytes (compact JSON, or the binary frame for bytes types).

    Raises:
        MessageError: The message is not a :class:`Message` or cannot be serialised.

    """
    msg = envelope.message
    if not isinstance(msg, Message):
        raise MessageError(f"expected an anunnaki.messages.Message, got {type(msg).__name__}")
    header = {
        "v": msg.VERSION,
        "type": msg.type_name(),
        "t": float(envelope.t),
        "seq": int(envelope.seq),
        "sender": envelope.sender,
        "body": msg.to_body(),
    }
    raw = _dumps(header)
    blob = msg.binary()
    if blob is None:
        return raw
    if len(raw) >= MAX_HEADER:
        raise MessageError(f"{msg.type_name()}: header of {len(raw)} bytes is too large")
    return struct.pack(">I", len(raw)) + raw + blob


def _generic(body: dict[str, Any]) -> Generic:
    """A :class:`Generic` around a decoded JSON object, without pydantic's construct overhead."""
    msg = Generic.__new__(Generic)
    object.__setattr__(msg, "__dict__", {"data": body})
    object.__setattr__(msg, "__pydantic_fields_set__", {"data"})
    object.__setattr__(msg, "__pydantic_extra__", None)
    object.__setattr__(msg, "__pydantic_private__", None)
    return msg


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not valid JSON")


#: One decoder for every envelope (``json.loads`` with a hook builds a new one per call).
_DECODER = json.JSONDecoder(parse_constant=_reject_constant)


def _split_frame(data: bytes) -> tuple[bytes, bytes | None]:
    """The JSON header and the binary blob (``None`` for a pure-JSON envelope)."""
    if not data:
        raise MalformedMessage("empty payload")
    if data[:1] == b"{":
        return data, None
    if len(data) < 4:
        raise MalformedMessage("payload too short for a binary frame")
    (n,) = struct.unpack(">I", data[:4])
    if n >= MAX_HEADER or 4 + n > len(data):
        raise MalformedMessage(f"binary frame header length {n} is out of bounds")
    return data[4 : 4 + n], data[4 + n :]


def _header(header_bytes: bytes) -> dict[str, Any]:
    """The envelope's header, parsed and checked key by key."""
    try:
        header = _DECODER.decode(header_bytes.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise MalformedMessage(f"not a JSON envelope: {exc}") from None
    if not isinstance(header, dict):
        raise MalformedMessage("envelope is not a JSON object")
    keys = set(header)
    if keys != _ENVELOPE_KEYS:
        missing = sorted(_ENVELOPE_KEYS - keys)
        extra = sorted(keys - _ENVELOPE_KEYS)
        raise MalformedMessage(f"bad envelope keys (missing {missing}, unexpected {extra})")
    for key, ok, what in _HEADER_RULES:
        if not ok(header[key]):
            got = header[key]
            raise MalformedMessage(
                f"envelope '{key}' must be {what}" + ("" if key == "body" else f", got {got!r}")
            )
    return header


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


#: ``(key, check, what it must be)`` for each envelope field.
_HEADER_RULES: tuple[tuple[str, Callable[[Any], bool], str], ...] = (
    ("v", _is_int, "an integer"),
    ("type", lambda v: isinstance(v, str), "a string"),
    ("t", lambda v: isinstance(v, int | float) and not isinstance(v, bool), "a number"),
    ("seq", lambda v: _is_int(v) and v >= 0, "a non-negative integer"),
    ("sender", lambda v: isinstance(v, str), "a string"),
    ("body", lambda v: isinstance(v, dict), "a JSON object"),
)


def decode_envelope(data: bytes | bytearray | memoryview) -> Envelope:
    """Decode wire bytes into an envelope, strictly.

    Raises:
        MalformedMessage: Undecodable bytes, bad envelope, unknown type, wrong version or a
            body that fails validation; the message says which.

    """
    header_bytes, blob = _split_frame(bytes(data))
    header = _header(header_bytes)
    v, name, body = header["v"], header["type"], header["body"]
    try:
        cls = cast(type[Message], MESSAGES.factory(name))
    except MessageError:
        raise MalformedMessage(f"unknown message type {name!r}") from None
    if v != cls.VERSION:
        raise MalformedMessage(f"{name} version {v} is not the known version {cls.VERSION}")
    if (blob is None) != (cls.BINARY_FIELD is None):
        form = "binary frame" if blob is not None else "JSON envelope"
        raise MalformedMessage(f"{name} cannot travel as a {form}")
    try:
        if cls is Generic:
            # json.loads (NaN/Infinity rejected) only yields JSON values: nothing to check.
            message: Message = _generic(body)
        else:
            message = cls.from_body(body, blob)
    except ValidationError as exc:
        first = exc.errors(include_url=False)[0]
        where = ".".join(str(p) for p in first["loc"]) or "body"
        raise MalformedMessage(
            f"invalid {name} body: {where}: {validation_message(first)}"
        ) from None
    return Envelope(
        message=message, t=float(header["t"]), seq=header["seq"], sender=header["sender"]
    )
