"""rclpy messages as plain data and back, the way the ROS 1 converters do genpy's.

An rclpy message describes itself (``get_fields_and_field_types()``: ``boolean``, ``octet``,
``float``, ``double``, ``string``, ``sequence<T>``, ``T[N]``, ``pkg/Name``); it becomes a
dict of its fields (nested messages as dicts, ``builtin_interfaces`` Time and Duration as
float seconds, ``uint8``/``octet`` sequences as bytes, other arrays as lists) and back.

Nothing here imports rclpy: nested message classes are found through their package's
``msg`` module (``diagnostic_msgs.msg``) when one is needed. rclpy does not check a field's
type on assignment (``ROS_PYTHON_CHECK_FIELDS`` is off by default since Jazzy; a wrong value
fails only when the message is published), so :func:`fill_ros2_message` checks every value
itself and refuses a wrong one with :class:`~anunnaki.rosbridge.ConversionError` naming the
field.
"""

from __future__ import annotations

import array
import importlib
import re
from collections.abc import Mapping
from typing import Any

from anunnaki.rosbridge import ConversionError, coerce_value

__all__ = ["fill_ros2_message", "ros1_style_type", "ros2_message_to_dict"]

_TIME_TYPES = ("builtin_interfaces/Time", "builtin_interfaces/Duration")
_PRIMITIVES = {
    "boolean": "bool",
    "octet": "uint8",
    "char": "uint8",
    "byte": "uint8",
    "float": "float32",
    "double": "float64",
    "long double": "float64",
    "wstring": "string",
}
_SEQUENCE = re.compile(r"^sequence<([^,>]+)(?:,\s*\d+)?>$")
_FIXED = re.compile(r"^(.+)\[(\d+)\]$")
_BOUNDED_STRING = re.compile(r"^w?string<\d+>$")


def ros1_style_type(type_: str) -> str:
    """An rclpy field type in the ROS 1 spelling of the tables.

    ``sequence<float>`` → ``float32[]``, ``double[9]`` → ``float64[9]``, ``boolean`` → ``bool``.
    """
    m = _SEQUENCE.match(type_)
    if m:
        return f"{ros1_style_type(m.group(1).strip())}[]"
    m = _FIXED.match(type_)
    if m:
        return f"{ros1_style_type(m.group(1))}[{m.group(2)}]"
    if _BOUNDED_STRING.match(type_):
        return "string"
    return _PRIMITIVES.get(type_, type_)


def _is_message(value: Any) -> bool:
    return hasattr(value, "get_fields_and_field_types")


def _type_name(msg: Any) -> str:
    module = type(msg).__module__.split(".")[0]
    return f"{module}/{type(msg).__name__}"


def ros2_message_to_dict(msg: Any) -> dict[str, Any]:
    """All fields of an rclpy message as plain data (times as float seconds)."""
    out: dict[str, Any] = {}
    for name, type_ in msg.get_fields_and_field_types().items():
        out[name] = _value(getattr(msg, name), ros1_style_type(type_))
    return out


def _value(v: Any, type_: str) -> Any:
    if type_ in _TIME_TYPES:
        return float(v.sec) + float(v.nanosec) / 1e9
    if _is_message(v):
        return ros2_message_to_dict(v)
    base = type_.split("[", 1)[0]
    if "[" in type_:
        if base == "uint8":
            return bytes(v.tobytes() if hasattr(v, "tobytes") else bytes(v))
        items = v.tolist() if isinstance(v, array.array) or hasattr(v, "tolist") else list(v)
        return [_value(x, base) for x in items]
    if isinstance(v, bytes):  # an octet
        return v[0] if v else 0
    if hasattr(v, "item"):  # a numpy scalar
        return v.item()
    return v


def _message_class(type_name: str) -> Any:
    package, name = type_name.split("/", 1)
    return getattr(importlib.import_module(f"{package}.msg"), name)


def fill_ros2_message(msg: Any, data: Mapping[str, Any], where: str = "") -> Any:
    """Set the fields of rclpy message ``msg`` from ``data`` (nested dicts, float times).

    Fields not in ``data`` keep their defaults. Returns ``msg``.

    Raises:
        ConversionError: A field ``msg`` does not have, or a value of the wrong kind.

    """
    types = msg.get_fields_and_field_types()
    for key, value in data.items():
        path = f"{where}{key}"
        if key not in types:
            raise ConversionError(f"{_type_name(msg)} has no field '{path}'")
        setattr(msg, key, _field(getattr(msg, key), ros1_style_type(types[key]), value, path))
    return msg


def _field(current: Any, type_: str, value: Any, path: str) -> Any:
    if type_ in _TIME_TYPES:
        return _time(current, value, path)
    base = type_.split("[", 1)[0]
    if _is_message(current):
        if not isinstance(value, Mapping):
            raise ConversionError(f"'{path}' is a {type_}: give its fields as a mapping")
        return fill_ros2_message(current, value, f"{path}.")
    if "[" in type_ and "/" in base:
        return _messages(base, type_, value, path)
    if isinstance(value, Mapping):
        raise ConversionError(f"'{path}' is a {type_}, not a message")
    coerced = coerce_value(type_, value, path)
    if "[" in type_:
        return _array(current, base, coerced, path)
    if base.startswith(("int", "uint")):
        _check_range(base, type_, coerced, path)
        if isinstance(current, bytes):  # an octet field holds one byte
            return bytes([coerced])
    return coerced


def _time(current: Any, value: Any, path: str) -> Any:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConversionError(f"'{path}' is a time (seconds), got {value!r}")
    seconds = float(value)
    sec = int(seconds // 1)
    return type(current)(sec=sec, nanosec=min(999_999_999, round((seconds - sec) * 1e9)))


def _messages(base: str, type_: str, value: Any, path: str) -> list[Any]:
    """A sequence of nested messages (``DiagnosticStatus[]``) from a list of mappings."""
    if not isinstance(value, list | tuple):
        raise ConversionError(f"'{path}' is an array ({type_}), got {type(value).__name__}")
    cls = _message_class(base)
    out = []
    for i, item in enumerate(value):
        if not isinstance(item, Mapping):
            raise ConversionError(f"'{path}[{i}]' is a {base}: give its fields as a mapping")
        out.append(fill_ros2_message(cls(), item, f"{path}[{i}]."))
    return out


def _check_range(base: str, type_: str, value: int, path: str) -> None:
    bits = int(re.sub(r"\D", "", base) or 32)
    signed = not base.startswith("u")
    low, high = (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1) if signed else (0, 2**bits - 1)
    if not low <= value <= high:
        raise ConversionError(f"'{path}' is a {type_}, {value} is out of range")


def _array(current: Any, base: str, values: Any, path: str) -> Any:
    """An array field as rclpy holds it: array.array, a numpy array (fixed size), or a list."""
    if base == "uint8":
        return array.array("B", bytes(values) if isinstance(values, bytes) else values)
    if hasattr(current, "dtype"):  # a fixed-size array is a numpy array in rclpy
        import numpy as np

        arr = np.array(values, dtype=current.dtype)
        if arr.shape != current.shape:
            raise ConversionError(f"'{path}' holds {len(current)} values, got {len(arr)}")
        return arr
    if isinstance(current, array.array):
        return array.array(current.typecode, values)
    return values
