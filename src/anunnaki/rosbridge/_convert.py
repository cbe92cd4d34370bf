"""Converting between ROS 1 messages and bus messages, in plain Python.

A ROS message becomes a dict of its fields (nested messages as dicts, ``time`` and
``duration`` as float seconds, arrays as lists) and back; a bridge entry's ``fields`` then
picks and renames (:func:`to_bus_fields`, :func:`to_ros_fields`). Camera frames are the
exception: ``sensor_msgs/Image`` (``rgb8``, ``bgr8``, ``rgba8``, ``bgra8``, ``mono8``) is
written as a PNG (zlib, no OpenCV) and ``sensor_msgs/CompressedImage`` keeps its JPEG/PNG
bytes, both as the bus's :class:`~anunnaki.messages.Image`; the other way a bus frame becomes a
``CompressedImage`` as it is (a raw ``Image`` needs OpenCV to decode it).

Nothing here imports rospy: message objects are read through genpy's ``__slots__`` and
``_slot_types`` and written through attributes, so the converters are tested without ROS.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Mapping
from typing import Any

from anunnaki.messages import Image, ServiceReply

__all__ = [
    "bus_image_to_compressed",
    "bus_image_to_raw",
    "coerce_value",
    "compressed_to_image",
    "fill_message",
    "image_size",
    "message_to_dict",
    "raw_to_image",
    "to_bus_fields",
    "to_ros_fields",
]

# encoding → (channels in the ROS data, PNG colour type, channel order to RGB(A))
_RAW: dict[str, tuple[int, int, bool]] = {
    "rgb8": (3, 2, False),
    "bgr8": (3, 2, True),
    "rgba8": (4, 6, False),
    "bgra8": (4, 6, True),
    "mono8": (1, 0, False),
    "8UC1": (1, 0, False),
    "8UC3": (3, 2, True),  # OpenCV's order
}

RAW_ENCODINGS = tuple(_RAW)


class ConversionError(ValueError):
    """A message cannot be converted (bad encoding, truncated data, wrong field value)."""


# -- ROS message <-> dict -----------------------------------------------------------------------
def message_to_dict(msg: Any) -> dict[str, Any]:
    """All fields of a genpy message as plain data (times as float seconds)."""
    return {name: _value(getattr(msg, name)) for name in msg.__slots__}


def _is_time(v: Any) -> bool:
    """Tell a genpy Time or Duration (they have slots too: test them before messages)."""
    return hasattr(v, "to_sec") and hasattr(v, "secs")


def _value(v: Any) -> Any:
    if _is_time(v):
        return float(v.to_sec())
    if hasattr(v, "__slots__") and hasattr(v, "_slot_types"):
        return message_to_dict(v)
    if isinstance(v, bytes | bytearray):
        return bytes(v)
    if isinstance(v, list | tuple):
        return [_value(x) for x in v]
    return v


def fill_message(msg: Any, data: Mapping[str, Any], where: str = "") -> Any:
    """Set the fields of genpy message ``msg`` from ``data`` (nested dicts, float times).

    Fields not in ``data`` keep their defaults. Returns ``msg``.

    Raises:
        ConversionError: A field ``msg`` does not have, or a value of the wrong kind.

    """
    types = dict(zip(msg.__slots__, msg._slot_types, strict=True))
    for key, value in data.items():
        path = f"{where}{key}"
        if key not in types:
            raise ConversionError(f"{msg._type} has no field '{path}'")
        current = getattr(msg, key)
        if isinstance(value, Mapping):
            if not hasattr(current, "__slots__") or _is_time(current):
                raise ConversionError(f"'{path}' is a {types[key]}, not a message")
            fill_message(current, value, f"{path}.")
        elif _is_time(current):
            setattr(msg, key, type(current).from_sec(float(value)))
        elif hasattr(current, "__slots__") and hasattr(current, "_slot_types"):
            raise ConversionError(f"'{path}' is a {types[key]}: give its fields as a mapping")
        else:
            setattr(msg, key, coerce_value(types[key], value, path))
    return msg


def coerce_value(type_: str, value: Any, path: str) -> Any:
    """``value`` as a field of ROS 1-style type ``type_`` (``float32``, ``uint8[]``) at ``path``.

    Raises:
        ConversionError: A value of the wrong kind (a string for a number, a float for an int).

    """
    base = type_.split("[", 1)[0]
    if "[" in type_:
        if base == "uint8" and isinstance(value, bytes | bytearray):
            return bytes(value)
        if not isinstance(value, list | tuple):
            raise ConversionError(f"'{path}' is an array ({type_}), got {type(value).__name__}")
        return [coerce_value(base, x, path) for x in value]
    try:
        if base == "bool":
            if not isinstance(value, bool):
                raise TypeError
            return value
        if base == "string":
            return value if isinstance(value, str) else str(value)
        if base.startswith(("int", "uint")):
            if isinstance(value, bool) or float(value) != int(value):
                raise TypeError
            return int(value)
        if base.startswith("float"):
            if isinstance(value, bool):
                raise TypeError
            return float(value)
    except (TypeError, ValueError):
        raise ConversionError(f"'{path}' is a {type_}, got {value!r}") from None
    return value


# -- field mappings ------------------------------------------------------------------------------
def _get(data: Mapping[str, Any], path: str) -> Any:
    node: Any = data
    for part in path.split("."):
        if not isinstance(node, Mapping) or part not in node:
            raise KeyError(path)
        node = node[part]
    return node


def _put(out: dict[str, Any], path: str, value: Any) -> None:
    parts = path.split(".")
    node = out
    for part in parts[:-1]:
        node = node.setdefault(part, {})
    node[parts[-1]] = value


def to_bus_fields(
    ros: Mapping[str, Any], fields: Mapping[str, str], *, strict: bool = True
) -> dict[str, Any]:
    """What the bus gets of a ROS message dict: every field, or ``{bus: ros path}`` picked.

    With ``strict=False`` a mapped field the message lacks is left out (a ROS 2 recording
    read through a ROS 1 bridge file: ROS 2's Header has no ``seq``); else it is a KeyError.
    """
    if not fields:
        return dict(ros)
    out: dict[str, Any] = {}
    for bus_field, ros_field in fields.items():
        try:
            _put(out, bus_field, _get(ros, ros_field))
        except KeyError:
            if strict:
                raise
    return out


def to_ros_fields(bus: Mapping[str, Any], fields: Mapping[str, str]) -> dict[str, Any]:
    """The ROS fields (nested) a bus message's fields set: as they are, or renamed.

    Raises:
        ConversionError: A mapped bus field is missing from the message.

    """
    if not fields:
        return dict(bus)
    out: dict[str, Any] = {}
    for bus_field, ros_field in fields.items():
        try:
            value = _get(bus, bus_field)
        except KeyError:
            raise ConversionError(f"the bus message has no field '{bus_field}'") from None
        _put(out, ros_field, value)
    return out


# -- images --------------------------------------------------------------------------------------
def _png_chunk(kind: bytes, body: bytes) -> bytes:
    return (
        struct.pack(">I", len(body))
        + kind
        + body
        + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)
    )


def encode_png(pixels: bytes, width: int, height: int, colour: int, channels: int) -> bytes:
    """A PNG file of tightly packed 8-bit rows (colour type 0 grey, 2 RGB, 6 RGBA)."""
    row = width * channels
    raw = b"".join(b"\x00" + pixels[y * row : (y + 1) * row] for y in range(height))
    header = struct.pack(">IIBBBBB", width, height, 8, colour, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + _png_chunk(b"IHDR", header)
        + _png_chunk(b"IDAT", zlib.compress(raw, 1))
        + _png_chunk(b"IEND", b"")
    )


def _swap_red_blue(data: bytes, channels: int) -> bytes:
    out = bytearray(data)
    out[0::channels] = data[2::channels]
    out[2::channels] = data[0::channels]
    return bytes(out)


def raw_to_image(msg: Mapping[str, Any]) -> Image:
    """A ``sensor_msgs/Image`` dict as the bus's PNG ``Image`` (seq and frame_id kept).

    Raises:
        ConversionError: An unsupported encoding, a 16-bit or big-endian image, or data
            shorter than ``step * height``.

    """
    encoding = str(msg.get("encoding", ""))
    if encoding not in _RAW:
        raise ConversionError(
            f"image encoding {encoding!r} is not converted; use one of {', '.join(_RAW)}"
        )
    channels, colour, swap = _RAW[encoding]
    width, height, step = int(msg["width"]), int(msg["height"]), int(msg["step"])
    data = bytes(msg["data"])
    row = width * channels
    if width <= 0 or height <= 0 or step < row or len(data) < step * (height - 1) + row:
        raise ConversionError(
            f"image data of {len(data)} bytes does not hold {height} rows of {row} (step {step})"
        )
    if step != row:  # rows padded: keep the pixels only
        data = b"".join(data[y * step : y * step + row] for y in range(height))
    else:
        data = data[: row * height]
    if swap:
        data = _swap_red_blue(data, channels)
    header = msg.get("header") or {}
    return Image(
        encoding="png",
        width=width,
        height=height,
        channels=channels,  # type: ignore[arg-type]
        data=encode_png(data, width, height, colour, channels),
        frame_id=str(header.get("frame_id", "")),
        seq=max(0, int(header.get("seq", 0))),
    )


_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}
_PNG_CHANNELS = {0: 1, 2: 3, 3: 3, 4: 1, 6: 4}


def image_size(data: bytes) -> tuple[str, int, int, int]:
    """``(encoding, width, height, channels)`` read from a JPEG or PNG file's header.

    Raises:
        ConversionError: Neither a JPEG nor a PNG, or its header is cut short.

    """
    if data.startswith(b"\x89PNG\r\n\x1a\n") and len(data) >= 33 and data[12:16] == b"IHDR":
        width, height, _, colour = struct.unpack(">IIBB", data[16:26])
        return "png", width, height, _PNG_CHANNELS.get(colour, 3)
    if data.startswith(b"\xff\xd8"):
        i = 2
        while i + 9 < len(data):
            if data[i] != 0xFF:
                break
            marker = data[i + 1]
            if marker == 0xFF:  # fill byte
                i += 1
                continue
            length = struct.unpack(">H", data[i + 2 : i + 4])[0]
            if marker in _SOF:
                height, width = struct.unpack(">HH", data[i + 5 : i + 9])
                return "jpeg", width, height, data[i + 9]
            i += 2 + length
        raise ConversionError("a JPEG without a frame header (SOF)")
    raise ConversionError("the compressed image is neither JPEG nor PNG")


def compressed_to_image(msg: Mapping[str, Any]) -> Image:
    """A ``sensor_msgs/CompressedImage`` dict as the bus's ``Image`` (bytes unchanged)."""
    data = bytes(msg["data"])
    encoding, width, height, channels = image_size(data)
    if channels not in (1, 3, 4):
        channels = 3
    header = msg.get("header") or {}
    return Image(
        encoding=encoding,  # type: ignore[arg-type]
        width=width,
        height=height,
        channels=channels,  # type: ignore[arg-type]
        data=data,
        frame_id=str(header.get("frame_id", "")),
        seq=max(0, int(header.get("seq", 0))),
    )


def bus_image_to_compressed(image: Image, stamp: float) -> dict[str, Any]:
    """The ``sensor_msgs/CompressedImage`` fields of a bus frame."""
    return {
        "header": {"seq": image.seq, "stamp": stamp, "frame_id": image.frame_id},
        "format": image.encoding,
        "data": image.data,
    }


def bus_image_to_raw(image: Image, stamp: float) -> dict[str, Any]:
    """The ``sensor_msgs/Image`` (``rgb8``) fields of a bus frame (decodes: needs OpenCV)."""
    rgb = image.to_array()
    height, width = int(rgb.shape[0]), int(rgb.shape[1])
    return {
        "header": {"seq": image.seq, "stamp": stamp, "frame_id": image.frame_id},
        "height": height,
        "width": width,
        "encoding": "rgb8",
        "is_bigendian": 0,
        "step": width * 3,
        "data": rgb.tobytes(),
    }


def ros_reply(reply: Mapping[str, Any]) -> ServiceReply:
    """A ROS service's response (as plain data) as the bus's reply.

    ``ok`` is its ``success`` field (true when it has none: Empty, Trigger-less types), the
    error its ``message`` (or "refused") when it refused; the body is the response whole.
    """
    ok = bool(reply.get("success", True))
    error = None if ok else str(reply.get("message") or "refused")
    return ServiceReply(ok=ok, error=error, body=dict(reply))
