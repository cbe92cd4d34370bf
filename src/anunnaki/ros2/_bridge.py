"""ROS 2 over zenoh: the same bridge files, with CDR samples on zenoh key expressions.

ROS 2 speaks zenoh two ways, and Anunnaki's bus is zenoh already, so no ROS 2 install is
needed on Anunnaki's side:

* **zenoh-bridge-ros2dds** (any ROS 2 with DDS): topic ``/rover/controller/mode`` is the key
  ``rover/controller/mode`` (the leading ``/`` dropped; the bridge's ``namespace`` option,
  if set, comes first), the payload the CDR bytes DDS carries (4-byte encapsulation header,
  then the message).
* **rmw_zenoh** (ROS 2 Jazzy on): the key is
  ``<domain>/<topic without the leading />/<pkg>::msg::dds_::<Name>_/<type hash>``, e.g.
  ``0/rover/controller/mode/std_msgs::msg::dds_::String_/RIHS01_df66…``; the payload is
  CDR the same way, and every sample carries an attachment (:func:`rmw_zenoh_attachment`:
  sequence number, source time, the publisher's 16-byte gid), without which rmw_zenoh's
  subscribers drop it. The type hash is the message type's RIHS01 hash in the robot's
  distribution (:func:`type_hash`, from ``rosbags``' type store; the same as ROS 2 Jazzy's
  own type descriptions); a subscriber here uses ``*`` for it.

:class:`Ros2ZenohBridge` reads and writes those samples with ``rosbags``' CDR serializers and
the type store of the robot's ROS 2 distribution (the bridge file's ``distro``, else
``$ROS_DISTRO``: :func:`~anunnaki.ros2._distro.resolve_distro`; never assumed), through a
bridge file (``ros2-bridge/1``, or one written for ROS 1: types ``std_msgs/String``
map to ``std_msgs/msg/String``; a mapped field a ROS 2 type lacks — Header's ``seq`` — is
left out), and publishes on Anunnaki's bus what the ROS 1 bridge publishes.
"""

from __future__ import annotations

import itertools
import logging
import os
import struct
import time
from collections.abc import Callable, Mapping
from typing import Any, Literal

from anunnaki._closing import Closing
from anunnaki.bus import Bus
from anunnaki.messages import Image, body_of
from anunnaki.ros2._distro import resolve_distro, type_store
from anunnaki.rosbridge import (
    BridgeSpec,
    ConversionError,
    ToBus,
    TopicBridge,
    bag_message_to_dict,
    bus_image_to_compressed,
    to_ros_fields,
)

__all__ = [
    "Flavour",
    "Ros2ZenohBridge",
    "dds_type_name",
    "decode_cdr",
    "encode_cdr",
    "rmw_zenoh_attachment",
    "ros2_key",
    "type_hash",
]

log = logging.getLogger("anunnaki.ros2")

Flavour = Literal["ros2dds", "rmw_zenoh"]


def ros2_type(ros1_type: str) -> str:
    """``std_msgs/String`` → ``std_msgs/msg/String``."""
    package, name = ros1_type.split("/", 1)
    return f"{package}/msg/{name}"


def dds_type_name(ros1_type: str) -> str:
    """The DDS name rmw_zenoh puts in its keys: ``std_msgs::msg::dds_::String_``."""
    package, name = ros1_type.split("/", 1)
    return f"{package}::msg::dds_::{name}_"


def ros2_key(
    topic: str,
    ros1_type: str,
    *,
    flavour: Flavour = "ros2dds",
    domain: int = 0,
    type_hash: str = "*",
    namespace: str = "",
) -> str:
    """The zenoh key expression a ROS 2 topic's samples travel on (see the module's doc)."""
    name = topic.lstrip("/")
    if flavour == "ros2dds":
        return f"{namespace.strip('/')}/{name}" if namespace else name
    return f"{domain}/{name}/{dds_type_name(ros1_type)}/{type_hash}"


def type_hash(ros1_type: str, store: Any, distro: str) -> str:
    """The type hash rmw_zenoh puts in a key: ``RIHS01_<sha256>`` (Humble has none)."""
    if distro == "humble":
        return "TypeHashNotSupported"  # rmw_zenoh's Humble port
    return str(store.hash_rihs01(ros2_type(ros1_type)))


def rmw_zenoh_attachment(sequence: int, stamp_ns: int, gid: bytes) -> bytes:
    """rmw_zenoh's sample attachment, without which its subscribers drop a sample.

    CDR (little endian, no encapsulation header) of the int64 sequence number, the int64
    source timestamp (ns), the uint8 gid length (16) and the 16-byte gid.
    """
    if len(gid) != 16:
        raise ValueError(f"a gid is 16 bytes, got {len(gid)}")
    return struct.pack("<qqB16s", sequence, stamp_ns, 16, gid)


def _store(store: Any | None, distro: str | None) -> Any:
    return store if store is not None else type_store(resolve_distro(distro, where="the call"))


def decode_cdr(
    ros1_type: str, raw: bytes, store: Any | None = None, *, distro: str | None = None
) -> dict[str, Any]:
    """A CDR sample of ``ros1_type``'s ROS 2 message as plain data (times as float seconds).

    ``store`` (a rosbags type store), else ``distro``'s, else the installed distribution's.
    """
    store = _store(store, distro)
    return bag_message_to_dict(store.deserialize_cdr(raw, ros2_type(ros1_type)))


def encode_cdr(
    ros1_type: str, data: Mapping[str, Any], store: Any | None = None, *, distro: str | None = None
) -> bytes:
    """Plain data as a CDR sample of ``ros1_type``'s ROS 2 message (missing fields: zero).

    Raises:
        ConversionError: A field the ROS 2 type does not have.

    """
    store = _store(store, distro)
    msgtype = ros2_type(ros1_type)
    return bytes(store.serialize_cdr(_build(store, msgtype, data, ""), msgtype))


def _build(store: Any, msgtype: str, data: Mapping[str, Any], where: str) -> Any:
    _, fields = store.fielddefs[msgtype]
    names = {name for name, _ in fields}
    for key in data:
        if key not in names:
            raise ConversionError(f"{msgtype} has no field '{where}{key}'")
    values = {name: _field(store, desc, data.get(name), f"{where}{name}.") for name, desc in fields}
    return store.types[msgtype](**values)


def _field(store: Any, desc: Any, value: Any, where: str) -> Any:
    import numpy as np

    kind, detail = desc
    kind_name = getattr(kind, "name", str(kind))
    if kind_name == "NAME":
        if detail in ("builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration"):
            t = float(value or 0.0)
            return store.types[detail](sec=int(t // 1), nanosec=round((t % 1) * 1e9))
        return _build(store, detail, value or {}, where)
    if kind_name == "BASE":
        base = detail[0]
        if base == "string":
            return "" if value is None else str(value)
        if base == "bool":
            return bool(value)
        if base.startswith("float"):
            return float(value or 0.0)
        return int(value or 0)
    (inner_kind, inner), count = detail
    base = inner[0] if getattr(inner_kind, "name", "") == "BASE" else None
    if base is None:
        return [_build(store, inner, v, where) for v in (value or [])]
    if base == "uint8":
        return np.frombuffer(bytes(value or b""), np.uint8)
    items = list(value or ([0] * count if count else []))
    return np.array(items, dtype=np.dtype(base))


class Ros2ZenohBridge(Closing):
    """ROS 2 topics as zenoh samples (CDR) to and from the bus, as a bridge file says.

    Args:
        spec: A bridge file (the ``topics``; ROS 2 services are not bridged).
        bus: Anunnaki's bus (where the bridged values go, and actions come from).
        session: A zenoh session that reaches ROS 2's zenoh (zenoh-bridge-ros2dds, or
            rmw_zenoh's router); it may be another session than the bus's.
        flavour: ``ros2dds`` or ``rmw_zenoh`` key expressions.
        domain: The ROS domain id (rmw_zenoh keys).
        namespace: zenoh-bridge-ros2dds's ``namespace`` option, if it sets one.
        distro: The robot's ROS 2 distribution (default: the bridge file's ``distro``, else
            ``$ROS_DISTRO``, else the installed rclpy's; none of them: an error).

    """

    def __init__(
        self,
        spec: BridgeSpec,
        bus: Bus,
        session: Any,
        *,
        flavour: Flavour = "ros2dds",
        domain: int = 0,
        namespace: str = "",
        distro: str | None = None,
    ) -> None:
        self.spec = spec
        self.bus = bus
        self.session = session
        self.flavour: Flavour = flavour
        self.domain = domain
        self.namespace = namespace
        self.distro = resolve_distro(distro or spec.distro)
        self.store = type_store(self.distro)
        self.stats: dict[str, int] = {"to_bus": 0, "to_ros": 0, "malformed": 0}
        self._to_bus = ToBus(spec, strict=False)
        self._handles: list[Any] = []

    def key(self, t: TopicBridge, *, type_hash: str = "*") -> str:
        """The zenoh key of a bridge entry's ROS 2 topic."""
        return ros2_key(
            t.ros,
            t.type,
            flavour=self.flavour,
            domain=self.domain,
            type_hash=type_hash,
            namespace=self.namespace,
        )

    def start(self) -> None:
        """Subscribe to the ROS 2 samples (to_bus) and to the bus topics (to_ros)."""
        for t in self.spec.topics:
            if t.direction == "to_bus":
                handle = self.session.declare_subscriber(self.key(t), self._from_ros2(t))
                self._handles.append(handle.undeclare)
            else:
                sub = self.bus.subscribe(t.bus_topic, self._from_bus(t), queue=t.queue)
                self._handles.append(sub.close)

    def close(self) -> None:
        """Undeclare everything."""
        for undo in reversed(self._handles):
            undo()
        self._handles.clear()

    def __enter__(self) -> Ros2ZenohBridge:
        self.start()
        return self

    def _from_ros2(self, t: TopicBridge) -> Callable[[Any], None]:
        def on_sample(sample: Any) -> None:
            try:
                data = decode_cdr(t.type, sample.payload.to_bytes(), self.store)
                message = self._to_bus.message(t, data)
                if message is not None:
                    self.bus.publish(t.bus_topic, message)
            except Exception as exc:  # a bad sample is counted and dropped, never fatal
                self.stats["malformed"] += 1
                log.warning("dropped a ROS 2 sample on %s (%s): %s", t.ros, t.type, exc)
                return
            self.stats["to_bus"] += 1

        return on_sample

    def _from_bus(self, t: TopicBridge) -> Callable[[Any], None]:
        key = self.key(t, type_hash=type_hash(t.type, self.store, self.distro))
        gid = os.urandom(16)  # this publisher's id, as rmw_zenoh gives each one
        sequence = itertools.count(1)

        def on_sample(sample: Any) -> None:
            try:
                message = sample.message
                if isinstance(message, Image):
                    fields = bus_image_to_compressed(message, 0.0)
                    fields["header"].pop("seq", None)
                else:
                    fields = to_ros_fields(body_of(message), t.fields)
                raw = encode_cdr(t.type, fields, self.store)
            except Exception as exc:  # a bad bus message is counted and dropped
                self.stats["malformed"] += 1
                log.warning("dropped a bus message on %s for %s: %s", t.bus_topic, t.ros, exc)
                return
            if self.flavour == "rmw_zenoh":
                attachment = rmw_zenoh_attachment(next(sequence), time.time_ns(), gid)
                self.session.put(key, raw, attachment=attachment)
            else:
                self.session.put(key, raw)
            self.stats["to_ros"] += 1

        return on_sample
