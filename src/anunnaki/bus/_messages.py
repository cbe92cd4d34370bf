"""Typed message schemas, their registry and the wire format.

Every message is a frozen pydantic model that derives from :class:`Message`. On the wire a
message travels inside an envelope::

    {"v": 1, "type": "ModeRequest", "t": 1712.25, "seq": 7, "sender": "utu", "body": {...}}

``v`` is the schema version of the body's type (``Message.VERSION``), ``type`` the registered
type name, ``t`` the sender's clock in seconds (wall time or simulation time, whatever clock
the sender's bus was given), ``seq`` the sender's per-topic counter and ``sender`` the name of
the sending bus. The envelope is compact JSON (UTF-8), except for types that carry raw bytes
(:class:`Image`): those travel as a small binary frame so that pixels are not base64-bloated::

    +----------------------+-------------------------+----------------------+
    | header length N      | header: the envelope as | raw bytes of the     |
    | 4 bytes, big-endian  | JSON, without the bytes | binary field         |
    +----------------------+-------------------------+----------------------+

A JSON envelope starts with ``{`` (0x7B); a binary frame starts with a length below 16 MiB, so
its first byte is 0x00: the first byte tells the two apart.

Decoding is strict: undecodable bytes, unknown keys, an unknown type, another schema version
or a body that fails validation raise :class:`MalformedMessage`. Subscribers turn that into a
dropped, counted, logged message; it never reaches a node's code.

Message fields must be JSON-native (str, int, float, bool, None, lists, dicts, ``Literal``,
nested models): bodies are validated in pydantic's strict mode, which does not coerce
``"1"`` into ``1``.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Literal, Self, TypeVar

from pydantic import BaseModel, ConfigDict, Field, JsonValue, ValidationError, model_validator

from anunnaki.bus._errors import MalformedMessage, MessageError, UnknownMessageType

__all__ = [
    "Clock",
    "Envelope",
    "Generic",
    "Image",
    "Message",
    "ModeReply",
    "ModeRequest",
    "RunStop",
    "ServiceReply",
    "body_of",
    "decode_envelope",
    "encode_envelope",
    "message_type",
    "message_types",
    "register_message",
]

MAX_HEADER = 16 * 1024 * 1024
_ENVELOPE_KEYS = frozenset({"v", "type", "t", "seq", "sender", "body"})


class Message(BaseModel):
    """Base class of every message on the bus.

    Subclass it, give the fields, and register the class with :func:`register_message`::

        @register_message
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


_REGISTRY: dict[str, type[Message]] = {}

M = TypeVar("M", bound=type[Message])


def register_message(cls: M) -> M:
    """Register a message type so that receivers can decode it (usable as a decorator).

    Registering the same class twice is harmless; another class under a taken name is an error.

    Raises:
        MessageError: ``cls`` is not a Message subclass, or its name is taken.

    """
    if not (isinstance(cls, type) and issubclass(cls, Message)):
        raise MessageError(f"{cls!r} is not a subclass of anunnaki.bus.Message")
    name = cls.type_name()
    known = _REGISTRY.get(name)
    if known is not None and known is not cls:
        raise MessageError(
            f"message type name {name!r} is already registered by "
            f"{known.__module__}.{known.__qualname__}; set TYPE_NAME to a unique name"
        )
    fields: dict[str, Any] = cls.__pydantic_fields__
    if cls.BINARY_FIELD is not None and cls.BINARY_FIELD not in fields:
        raise MessageError(f"{name}: BINARY_FIELD {cls.BINARY_FIELD!r} is not a field")
    _REGISTRY[name] = cls
    return cls


def message_type(name: str) -> type[Message]:
    """Return the registered message class called ``name``.

    Raises:
        UnknownMessageType: No such type; the message lists the registered names.

    """
    try:
        return _REGISTRY[name]
    except KeyError:
        known = ", ".join(sorted(_REGISTRY))
        raise UnknownMessageType(
            f"unknown message type {name!r}; registered types: {known}"
        ) from None


def message_types() -> dict[str, type[Message]]:
    """Return a copy of the registry: type name -> class."""
    return dict(_REGISTRY)


# --- the message types -------------------------------------------------------------------


@register_message
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


_MAGIC: dict[str, tuple[bytes, ...]] = {
    "jpeg": (b"\xff\xd8\xff",),
    "png": (b"\x89PNG\r\n\x1a\n",),
}


@register_message
class Image(Message):
    """One compressed camera frame.

    Frames travel as raw bytes after the JSON header (no base64) and are never persisted by
    the framework (guideline P1: media is compressed and not stored); only what is derived
    from them (assessments, detections) is kept.

    Attributes:
        encoding: ``"jpeg"`` or ``"png"``; ``data`` must start with that format's signature.
        width: Width in pixels (> 0).
        height: Height in pixels (> 0).
        channels: 1 (grey), 3 (RGB) or 4 (RGBA).
        data: The encoded image file's bytes.
        frame_id: The camera's frame (ROS ``header.frame_id``).
        seq: The camera's frame counter.

    """

    BINARY_FIELD: ClassVar[str | None] = "data"

    encoding: Literal["jpeg", "png"]
    width: int = Field(gt=0)
    height: int = Field(gt=0)
    channels: Literal[1, 3, 4] = 3
    data: bytes = Field(min_length=1)
    frame_id: str = ""
    seq: int = Field(default=0, ge=0)

    @model_validator(mode="after")
    def _signature(self) -> Self:
        if not self.data.startswith(_MAGIC[self.encoding]):
            raise ValueError(f"data does not start with the {self.encoding} signature")
        return self

    @classmethod
    def from_array(
        cls,
        rgb: Any,
        *,
        encoding: Literal["jpeg", "png"] = "jpeg",
        quality: int = 90,
        frame_id: str = "",
        seq: int = 0,
    ) -> Image:
        """Encode an ``(H, W, 3)`` RGB ``uint8`` array (or ``(H, W)`` grey) as a frame.

        ``quality`` is the JPEG quality (1–100); PNG uses fast compression (level 1).

        Raises:
            ValueError: The array is not an ``(H, W)``/``(H, W, 3)`` ``uint8`` image.
            MissingExtraError: OpenCV is not installed (``anunnaki[phenomena]``).

        """
        cv2, np = _cv2()
        arr = np.asarray(rgb)
        if arr.dtype != np.uint8 or arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] != 3):
            raise ValueError(
                f"an image must be (H, W) or (H, W, 3) uint8, got {arr.shape} {arr.dtype}"
            )
        pixels = arr if arr.ndim == 2 else np.ascontiguousarray(arr[:, :, ::-1])
        if encoding == "jpeg":
            ok, buf = cv2.imencode(".jpg", pixels, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
        else:
            ok, buf = cv2.imencode(".png", pixels, [cv2.IMWRITE_PNG_COMPRESSION, 1])
        if not ok:  # pragma: no cover - OpenCV encodes any uint8 image
            raise ValueError("image encoding failed")
        return cls(
            encoding=encoding,
            width=int(arr.shape[1]),
            height=int(arr.shape[0]),
            channels=1 if arr.ndim == 2 else 3,
            data=bytes(buf.tobytes()),
            frame_id=frame_id,
            seq=seq,
        )

    def to_array(self) -> Any:
        """Decode the frame into an ``(H, W, 3)`` RGB ``uint8`` array (grey/RGBA become RGB).

        Raises:
            ValueError: The bytes do not decode.
            MissingExtraError: OpenCV is not installed (``anunnaki[phenomena]``).

        """
        cv2, np = _cv2()
        bgr = cv2.imdecode(np.frombuffer(self.data, dtype=np.uint8), cv2.IMREAD_COLOR)
        if bgr is None:
            raise ValueError(f"frame {self.seq}: the {self.encoding} bytes do not decode")
        return np.ascontiguousarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8)


def _cv2() -> tuple[Any, Any]:
    """OpenCV and NumPy, imported on first use (the bus itself needs neither)."""
    try:
        import cv2
        import numpy
    except ImportError as exc:  # pragma: no cover - part of the phenomena/vision extras
        from anunnaki.errors import MissingExtraError

        raise MissingExtraError("opencv-python-headless", "phenomena") from exc
    return cv2, numpy


@register_message
class Clock(Message):
    """Simulation time (the ROS ``/clock`` topic).

    Attributes:
        time: Simulated time in seconds since the start of the simulation (>= 0).

    """

    time: float = Field(ge=0.0)


@register_message
class Assessment(Message):
    """A behavior assessment of an LEC (agent A4 on ``/utu/oracle/output``, paper §3.2).

    Attributes:
        category: Behavior category: 0 = F1 drop under 5 %, 1 = degraded (over 5 %),
            2 = compromised (over 10 %), relative to the model's F1 on clean data.
        confidence: The assessor's confidence in the category, in [0, 1].
        context: The perceived context, e.g. ``{"phenomenon": "fog", "density": 4}``.
        model_id: The id of the model whose behaviour is assessed.
        assessor: The assessor's name (an oracle, or ``ground_truth``).
        frame_seq: The camera frame the assessment is about, when there is one.
        drop: The predicted relative F1 drop of the model, when the assessor predicts
            one (an oracle with a drop head); ``None`` in older messages and files.

    """

    category: int = Field(ge=0, le=2)
    confidence: float = Field(ge=0.0, le=1.0)
    context: dict[str, JsonValue] = Field(default_factory=dict)
    model_id: str
    assessor: str
    frame_seq: int | None = None
    drop: float | None = None


@register_message
class Detections(Message):
    """What an LEC detected in one camera frame.

    Attributes:
        frame_seq: The frame's sequence number (every frame gets exactly one).
        model_id: The model that produced the detections.
        domain: That model's domain (``default``, ``fog``, ``low_light`` …).
        width: Frame width in pixels.
        height: Frame height in pixels.
        boxes: ``[x1, y1, x2, y2]`` per detection, in pixels.
        labels: Class name per detection.
        scores: Confidence per detection, in [0, 1].
        latency_ms: Inference time, when measured.

    """

    frame_seq: int = Field(ge=0)
    model_id: str
    domain: str = "default"
    width: int = Field(gt=0)
    height: int = Field(gt=0)
    boxes: list[list[float]] = Field(default_factory=list)
    labels: list[str] = Field(default_factory=list)
    scores: list[float] = Field(default_factory=list)
    latency_ms: float | None = None

    @model_validator(mode="after")
    def _parallel(self) -> Self:
        if not (len(self.boxes) == len(self.labels) == len(self.scores)):
            raise ValueError("boxes, labels and scores must have the same length")
        if any(len(b) != 4 for b in self.boxes):
            raise ValueError("each box is [x1, y1, x2, y2]")
        return self


@register_message
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


@register_message
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


@register_message
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


@register_message
class RunStop(Message):
    """Stop the whole system now (guideline S4). Sent on ``/utu/run_stop`` at top priority.

    Attributes:
        reason: Why the system is stopped.
        caller: Who stopped it.

    """

    reason: str = Field(min_length=1)
    caller: str = Field(min_length=1)


# --- envelope and codec ------------------------------------------------------------------


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
        raise MessageError(f"expected an anunnaki.bus.Message, got {type(msg).__name__}")
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
    cls = _REGISTRY.get(name)
    if cls is None:
        raise MalformedMessage(f"unknown message type {name!r}")
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
        raise MalformedMessage(f"invalid {name} body: {where}: {first['msg']}") from None
    return Envelope(
        message=message, t=float(header["t"]), seq=header["seq"], sender=header["sender"]
    )
