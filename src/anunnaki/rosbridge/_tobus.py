"""What the bus gets of a ROS message, as a bridge file says: written once for every reader.

The ROS 1 bridge (genpy messages), the ROS 2 bridge (CDR samples) and :func:`read_bag` (a
recording) all turn a ROS message, once it is plain data, into the bus message of its
``to_bus`` entry the same way: a camera frame becomes the bus's
:class:`~anunnaki.messages.Image`; other messages their mapped fields
(:func:`~anunnaki.ros1.to_bus_fields`). Several ROS topics may feed one bus topic, each with
its own fields (the bridge file's check refuses a field from two topics): each message then
carries the latest values of all of them, merged, so the goal model never sees half a state.
"""

from __future__ import annotations

import threading
from collections import Counter
from collections.abc import Mapping
from typing import Any

from anunnaki.messages import Image
from anunnaki.rosbridge._convert import compressed_to_image, raw_to_image, to_bus_fields
from anunnaki.rosbridge._schema import BridgeSpec, TopicBridge

__all__ = ["ToBus", "diagnostic_fields", "diagnostic_value"]


def diagnostic_value(text: str) -> bool | int | float | str:
    """A diagnostic key/value pair's value as the goal model wants it.

    A number or a boolean when it reads as one (``"42.5"`` → 42.5, ``"true"`` → True), else
    the text.
    """
    lowered = text.strip().lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            continue
    return text


def diagnostic_fields(data: Mapping[str, Any], status: str) -> dict[str, Any] | None:
    """One status of a ``DiagnosticArray`` (by name) as flat fields.

    ``level`` (0 OK, 1 WARN, 2 ERROR, 3 STALE), ``message``, ``hardware_id`` and each
    key/value pair (values as :func:`diagnostic_value` reads them); ``None`` if the array has
    no such status.
    """
    for entry in data.get("status") or ():
        if entry.get("name") == status:
            level = entry.get("level", 0)
            flat: dict[str, Any] = {
                "level": level[0] if isinstance(level, bytes | bytearray) else int(level),
                "message": entry.get("message", ""),
                "hardware_id": entry.get("hardware_id", ""),
            }
            for pair in entry.get("values") or ():
                flat[str(pair.get("key", ""))] = diagnostic_value(str(pair.get("value", "")))
            return flat
    return None


class ToBus:
    """Turns the plain data of a ROS message into the bus message of its ``to_bus`` entry.

    Thread-safe: the merged values of a shared bus topic are updated under a lock (ROS
    callbacks of different topics run on different threads).

    Args:
        spec: The bridge file.
        strict: Whether a mapped field the message lacks is an error (a KeyError, ROS 1)
            or left out (ROS 2 samples and bags read through a ROS 1 bridge file: ROS 2's
            Header has no ``seq``).

    """

    def __init__(self, spec: BridgeSpec, *, strict: bool = True) -> None:
        self._strict = strict
        feeds = Counter(
            t.bus_topic for t in spec.topics if t.direction == "to_bus" and not t.as_image
        )
        # bus topics fed by several ROS topics: each message publishes the merged latest values
        self._shared = {topic for topic, n in feeds.items() if n > 1}
        self._merged: dict[str, dict[str, Any]] = {}
        self._lock = threading.Lock()

    def message(self, t: TopicBridge, data: Mapping[str, Any]) -> Image | dict[str, Any] | None:
        """The bus message of ``data``, a message of entry ``t``'s ROS topic as plain data.

        ``None``: the message holds nothing for this entry (a ``/diagnostics`` array without
        the entry's ``status``); nothing is published.

        Raises:
            ConversionError: A camera frame that does not decode.
            KeyError: (``strict``) A mapped field the message lacks.

        """
        if t.as_image:
            if t.type == "sensor_msgs/CompressedImage":
                return compressed_to_image(data)
            return raw_to_image(data)
        return self.fields(t, data)

    def fields(self, t: TopicBridge, data: Mapping[str, Any]) -> dict[str, Any] | None:
        """The bus fields of ``data`` for a non-image entry: mapped, and merged if shared.

        A ``status`` entry (``diagnostic_msgs/DiagnosticArray``) first becomes that status's
        fields (:func:`diagnostic_fields`); ``None`` when the array does not hold it.

        Raises:
            KeyError: (``strict``) A mapped field the message lacks.

        """
        if t.status is not None:
            flat = diagnostic_fields(data, t.status)
            if flat is None:
                return None
            data = flat
        fields = to_bus_fields(data, t.fields, strict=self._strict)
        if t.bus_topic not in self._shared:
            return fields
        with self._lock:
            merged = self._merged.setdefault(t.bus_topic, {})
            merged.update(fields)
            return dict(merged)
