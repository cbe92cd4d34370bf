"""The message bus (transport): topics, services and liveliness, in a process or across hosts.

Every Anunnaki node (oracles, the LEC, the model manager, Utu's MAPE-K services, the
dashboard) talks through one small interface, modelled on zenoh: open a bus, declare
everything else from it, close it (or use ``with``). Two implementations share the
interface and one contract suite: ``"inproc"`` (in-process, for tests and single-process
runs) and ``"zenoh"`` (eclipse-zenoh; ``pip install 'anunnaki[bus]'``)::

    from anunnaki.bus import open_bus
    from anunnaki.messages import ModeReply, ModeRequest

    with open_bus("zenoh") as bus:                      # peer on tcp/127.0.0.1:<free port>
        bus.subscribe("/utu/oracle/**", lambda s: print(s.topic, s.message))
        bus.publish("/rover/sensors", {"mode": "autonomous", "buzzer": False})
        bus.service("/rover/set_mode", lambda req: ModeReply(mode=req.mode, accepted=True))
        reply = bus.request("/rover/set_mode", ModeRequest(mode="manual"), timeout=2.0)
        with bus.liveliness_token("/utu_monitor"):
            print(bus.alive_nodes())

The interface
    :func:`open_bus` -> :class:`Bus`; ``bus.publisher(topic)`` -> :class:`Publisher`
    (``put``); ``bus.publish(topic, msg)``; ``bus.subscribe(pattern, callback=None,
    queue=16, drop="oldest")`` -> :class:`Subscriber` (callback, or ``recv``/``try_recv``/
    iteration); ``bus.service(name, handler)`` -> :class:`Service`; ``bus.request(name,
    msg, timeout)``; ``bus.liveliness_token(node)``, ``bus.alive_nodes()``,
    ``bus.watch_liveliness(callback)``; ``bus.stats()``; ``bus.close()``. Every declared
    object is a context manager with ``close()``; closing the bus closes them all.

Names and keys
    ROS-style names map to keys by prefixing the namespace: ``/utu/oracle/output`` <->
    ``anunnaki/utu/oracle/output``; services live under ``<namespace>/srv/``, liveliness
    tokens under ``<namespace>/node/`` (:func:`ros_to_key`, :func:`key_to_ros`).

Messages
    What travels is not defined here: the typed, versioned message types are
    :mod:`anunnaki.messages` (``MESSAGES``, a plugin slot) and the well-known names
    :mod:`anunnaki.topics`. The bus carries any registered message in an envelope ``{"v",
    "type", "t", "seq", "sender", "body"}`` (:class:`Envelope`, :func:`encode_envelope`,
    :func:`decode_envelope`): compact JSON, or a binary frame for a type with a
    ``BINARY_FIELD`` (images). Malformed messages are dropped, counted
    (``stats().malformed``) and logged (logger ``anunnaki.bus``); they never reach a node.

Kinds
    :data:`BUS_KINDS` is the slot of transports (a :class:`~anunnaki.plugins.Registry`):
    ``"inproc"`` and ``"zenoh"`` built in, others by the entry-point group
    ``anunnaki.buses``.

One thread of delivery
    An in-process bus opened with an :class:`Executor` (``open_bus("inproc",
    executor=ex)``) has no threads of its own: every message is delivered on the executor's
    thread in publication order, services are answered in the same drain, and
    ``ex.spin_until_idle()`` runs until nothing is pending. A simulated run is then one
    deterministic program (:mod:`anunnaki.bus._executor`, docs/architecture.md).

Robustness (guidelines S1, S2, S4)
    Subscribers have bounded queues (latest-value: the oldest, least urgent message goes
    first, and is counted); callbacks run on one thread per subscriber, never on the network
    thread. A QoS table (:data:`QOS_TABLE`) makes run-stop, tactic actions and assessments
    reliable and urgent, camera frames best-effort and droppable.

See ``docs/bus.md`` for the wire format, the QoS table, TLS/access-control deployment and
measured latencies.
"""

from __future__ import annotations

from anunnaki.bus._api import (
    Bus,
    BusStats,
    LivelinessToken,
    LivelinessWatch,
    Publisher,
    Sample,
    Service,
    Subscriber,
)
from anunnaki.bus._codec import Envelope, decode_envelope, encode_envelope
from anunnaki.bus._config import AccessControl, AccessRule, BusConfig, TlsConfig, on_loopback
from anunnaki.bus._errors import (
    BusClosedError,
    BusConfigError,
    BusConnectError,
    BusError,
    BusTimeout,
    MalformedMessage,
    ServiceError,
    TopicNameError,
)
from anunnaki.bus._executor import Executor, ExecutorOverrun
from anunnaki.bus._guard import LivelinessGuard
from anunnaki.bus._inproc import InprocBus, InprocHub
from anunnaki.bus._keys import (
    DEFAULT_NAMESPACE,
    key_matches,
    key_to_ros,
    node_key,
    ros_to_key,
    service_key,
    validate_name,
    validate_pattern,
)
from anunnaki.bus._kinds import BUS_KINDS
from anunnaki.bus._node import Node
from anunnaki.bus._open import open_bus
from anunnaki.bus._qos import PRIORITIES, QOS_TABLE, QoS, TopicClass, qos_for

__all__ = [
    "BUS_KINDS",
    "DEFAULT_NAMESPACE",
    "PRIORITIES",
    "QOS_TABLE",
    "AccessControl",
    "AccessRule",
    "Bus",
    "BusClosedError",
    "BusConfig",
    "BusConfigError",
    "BusConnectError",
    "BusError",
    "BusStats",
    "BusTimeout",
    "Envelope",
    "Executor",
    "ExecutorOverrun",
    "InprocBus",
    "InprocHub",
    "LivelinessGuard",
    "LivelinessToken",
    "LivelinessWatch",
    "MalformedMessage",
    "Node",
    "Publisher",
    "QoS",
    "Sample",
    "Service",
    "ServiceError",
    "Subscriber",
    "TlsConfig",
    "TopicClass",
    "TopicNameError",
    "decode_envelope",
    "encode_envelope",
    "key_matches",
    "key_to_ros",
    "node_key",
    "on_loopback",
    "open_bus",
    "qos_for",
    "ros_to_key",
    "service_key",
    "validate_name",
    "validate_pattern",
]
