"""The native ROS 2 bridge: a bridge file's topics and services between rclpy and the bus.

The counterpart of the ROS 1 bridge (:mod:`anunnaki.ros1._bridge`), on rclpy: one
:class:`Ros2Bridge` lives in its own process (``python -m anunnaki.ros2``, run from the ROS 2
environment that scripts/setup-ros2.sh builds, or any environment where ``import rclpy``
works, e.g. after sourcing a ROS 2 install's ``setup.bash``) and is a ROS 2 node there:

* a ``to_bus`` topic is a subscription, a ``to_ros`` topic a publisher, with the entry's
  QoS (``sensor``: best effort, as drivers publish sensor data; ``reliable``: commands,
  states), history depth ``queue``;
* camera frames (``sensor_msgs/Image``, ``sensor_msgs/CompressedImage``) become the bus's
  ``Image`` and back (a raw ``Image`` to ROS decodes the frame: OpenCV);
* a service with ``serve: bus`` (the default) answers a bus request by calling the ROS
  service; with ``serve: ros`` the bridge offers the ROS service and answers a ROS call by
  requesting the bus service;
* a heartbeat: ``std_msgs/Empty`` on ``/<name>/heartbeat``, liveliness ``MANUAL_BY_TOPIC``
  with the bridge file's lease (``heartbeat``, default 1 s), published every quarter lease
  from the executor. A robot subscribed with that lease sees the bridge's ``alive_count``
  fall to 0 a lease after the bridge stops, hangs or is killed (``kill -9`` too), and goes to
  its safe state on its own (examples/rover/ros2/rover_robot.py does).

Each message costs the executor two rebuilds of its wait set, in Python, and each waitable
in it adds to both; rclpy gives every publisher and subscription two QoS event handlers
(incompatible QoS, incompatible type) unless told not to: 64 waitables on a bridge of 31
topics, and 49 of the 115 µs of CPU a wake took on the benchmark's bridge (docs/results.md).
So the bridge declares its topics without them and checks its peers itself, every
:data:`PEER_CHECK_PERIOD` seconds from a timer: an endpoint on a bridged topic (or the
heartbeat) whose QoS cannot match the bridge's, or whose type differs, is logged once
(``stats["incompatible_peers"]``), as rclpy's handlers did.

Nothing here waits inside an executor callback, so one thread spins the node
(``SingleThreadedExecutor``, the faster one here: docs/results.md): a bus request a ROS call
needs is sent with ``request_start`` from a coroutine callback, which awaits its reply
without holding the executor; a ROS service a bus request needs is called with
``call_async`` from the bus service's own thread, which the executor's thread answers.

It never dies from one bad message: a message that does not convert is counted
(``stats["malformed"]``) and logged with the topic and the reason, and the next one goes
through. Nothing here imports rclpy at import time: the process passes the imported module in.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable
from importlib import import_module
from types import ModuleType
from typing import Any

from anunnaki._closing import Closing
from anunnaki.bus import Bus, BusError, BusTimeout
from anunnaki.errors import AnunnakiError
from anunnaki.messages import Image, ServiceReply, body_of
from anunnaki.ros2._bridge import ros2_type
from anunnaki.ros2._rclpy_convert import fill_ros2_message, ros2_message_to_dict
from anunnaki.rosbridge import (
    BridgeSpec,
    ConversionError,
    ServiceBridge,
    ToBus,
    TopicBridge,
    bus_image_to_compressed,
    bus_image_to_raw,
    ros_reply,
    to_bus_fields,
    to_ros_fields,
)

__all__ = [
    "PEER_CHECK_PERIOD",
    "Ros2Bridge",
    "Ros2Unavailable",
    "import_rclpy",
    "message_class",
    "service_class",
]

log = logging.getLogger("anunnaki.ros2")

#: Seconds between two checks of the peers' QoS and types on the bridged topics.
PEER_CHECK_PERIOD = 2.0

#: What a message that does not convert raises (rclpy's own checks raise AssertionError).
_BAD = (ConversionError, KeyError, ValueError, TypeError, OverflowError, AssertionError)


class Ros2Unavailable(AnunnakiError):
    """rclpy cannot be imported here; the message says how to get it."""


def import_rclpy() -> ModuleType:
    """Import rclpy (and its QoS and executors).

    Raises:
        Ros2Unavailable: rclpy is not installed in this environment.

    """
    try:
        rclpy = import_module("rclpy")
        import_module("rclpy.qos")
        import_module("rclpy.executors")
        import_module("rclpy.callback_groups")
        import_module("rclpy.event_handler")
        import_module("rclpy.signals")
    except ImportError as exc:
        raise Ros2Unavailable(
            f"cannot import rclpy ({exc}); run the ROS 2 bridge with the ROS 2 environment's "
            "Python (scripts/setup-ros2.sh builds .venv-ros2: .venv-ros2/bin/python -m "
            "anunnaki.ros2 ...), or source your ROS 2 install's setup.bash first"
        ) from None
    return rclpy


def message_class(type_name: str) -> Any:
    """The rclpy class of ROS message type ``pkg/Name`` (``pkg.msg.Name``)."""
    package, name = type_name.split("/", 1)
    return getattr(import_module(f"{package}.msg"), name)


def service_class(type_name: str) -> Any:
    """The rclpy class of ROS service type ``pkg/Name`` (``pkg.srv.Name``)."""
    package, name = type_name.split("/", 1)
    return getattr(import_module(f"{package}.srv"), name)


def heartbeat_qos(rclpy: ModuleType, lease: float) -> Any:
    """The heartbeat's QoS: reliable, keep last 1, liveliness by topic with ``lease`` seconds."""
    q = rclpy.qos
    return q.QoSProfile(
        history=q.HistoryPolicy.KEEP_LAST,
        depth=1,
        reliability=q.ReliabilityPolicy.RELIABLE,
        durability=q.DurabilityPolicy.VOLATILE,
        liveliness=q.LivelinessPolicy.MANUAL_BY_TOPIC,
        liveliness_lease_duration=import_module("rclpy.duration").Duration(seconds=lease),
    )


def qos_profile(rclpy: ModuleType, t: TopicBridge) -> Any:
    """The rclpy QoS of an entry: best effort (``sensor``) or reliable, keep last ``queue``."""
    q = rclpy.qos
    reliability = (
        q.ReliabilityPolicy.BEST_EFFORT
        if t.effective_qos == "sensor"
        else q.ReliabilityPolicy.RELIABLE
    )
    return q.QoSProfile(
        history=q.HistoryPolicy.KEEP_LAST,
        depth=t.queue,
        reliability=reliability,
        durability=q.DurabilityPolicy.VOLATILE,
    )


class Ros2Bridge(Closing):
    """Carries a bridge file's topics and services between ROS 2 (rclpy) and the bus.

    Args:
        spec: The bridge file, loaded (:func:`~anunnaki.rosbridge.load_bridge`).
        bus: The bus to publish and serve on (usually zenoh, shared with Utu's nodes).
        node: The rclpy node to declare on; an executor spins it (one thread is enough: no
            callback here waits; several are safe too).
        rclpy: The imported rclpy module (:func:`import_rclpy`).

    Attributes:
        stats: Counters: ``to_bus``, ``to_ros``, ``calls``, ``failed_calls``, ``ros_calls``
            (ROS calls served), ``malformed`` (messages that did not convert).

    """

    def __init__(self, spec: BridgeSpec, bus: Bus, node: Any, rclpy: ModuleType) -> None:
        self.spec = spec
        self.bus = bus
        self.node = node
        self.rclpy = rclpy
        self.stats: Counter[str] = Counter()
        self._to_bus = ToBus(spec, strict=spec.ros2)
        self._ros_handles: list[tuple[str, Any]] = []
        self._bus_handles: list[Any] = []
        self._group = rclpy.callback_groups.ReentrantCallbackGroup()
        self._warned: set[tuple[str, bytes]] = set()
        # every topic of the bridge (the heartbeat too) is declared without rclpy's QoS event
        # handlers (the module docstring says why); check_peers does their work from a timer
        events = rclpy.event_handler
        self._quiet_pub = events.PublisherEventCallbacks(use_default_callbacks=False)
        self._quiet_sub = events.SubscriptionEventCallbacks(use_default_callbacks=False)

    # -- life ----------------------------------------------------------------------------------
    def start(self) -> None:
        """Declare every topic and service on ROS 2 and on the bus."""
        node = self.node
        for t in self.spec.topics:
            cls = message_class(t.type)
            qos = qos_profile(self.rclpy, t)
            if t.direction == "to_bus":
                sub = node.create_subscription(
                    cls,
                    t.ros,
                    self._from_ros(t),
                    qos,
                    callback_group=self._group,
                    event_callbacks=self._quiet_sub,
                )
                self._ros_handles.append(("subscription", sub))
            else:
                pub = node.create_publisher(cls, t.ros, qos, event_callbacks=self._quiet_pub)
                self._ros_handles.append(("publisher", pub))
                self._bus_handles.append(
                    self.bus.subscribe(t.bus_topic, self._from_bus(t, cls, pub), queue=t.queue)
                )
        for s in self.spec.services:
            srv = service_class(s.type)
            if s.serve == "bus":
                client = node.create_client(srv, s.ros_service, callback_group=self._group)
                self._ros_handles.append(("client", client))
                self._bus_handles.append(self.bus.service(s.bus, self._bus_handler(s, client)))
            else:
                service = node.create_service(
                    srv, s.ros_service, self._ros_handler(s), callback_group=self._group
                )
                self._ros_handles.append(("service", service))
        self._start_heartbeat()
        timer = node.create_timer(PEER_CHECK_PERIOD, self.check_peers)
        self._ros_handles.append(("timer", timer))

    def _start_heartbeat(self) -> None:
        """Publish ``/<name>/heartbeat`` every quarter lease (liveliness by topic)."""
        empty = message_class("std_msgs/Empty")
        lease = self.spec.heartbeat_lease
        pub = self.node.create_publisher(
            empty,
            self.spec.heartbeat_topic,
            heartbeat_qos(self.rclpy, lease),
            event_callbacks=self._quiet_pub,
        )
        self._ros_handles.append(("publisher", pub))
        timer = self.node.create_timer(lease / 4, lambda: pub.publish(empty()))
        self._ros_handles.append(("timer", timer))
        pub.publish(empty())  # alive from the first moment, not a quarter lease later

    def check_peers(self) -> int:
        """Log, once each, the peers on bridged topics (and the heartbeat) that cannot match.

        A peer cannot match when its QoS is incompatible with the bridge's (a best-effort
        publisher for the bridge's reliable subscription, say) or when it uses another type
        on the topic; for a type, the message names the fix (the bridge's type for the peer,
        or the peer's in the bridge file's entry). rclpy's default QoS event handlers said so;
        the bridge declares its topics without them (the module docstring says why) and calls
        this from a timer.

        Returns:
            How many peers were newly found not to match.

        """
        q = self.rclpy.qos
        me = self.node.get_name()
        found = 0
        entries = [(t.ros, t.type, t.direction, True) for t in self.spec.topics]
        entries.append((self.spec.heartbeat_topic, "std_msgs/Empty", "to_ros", False))
        for topic, type_name, direction, in_file in entries:
            ros_type = ros2_type(type_name)
            if direction == "to_bus":
                ends = self.node.get_subscriptions_info_by_topic(topic)
                peers = self.node.get_publishers_info_by_topic(topic)
                role = "publisher"
            else:
                ends = self.node.get_publishers_info_by_topic(topic)
                peers = self.node.get_subscriptions_info_by_topic(topic)
                role = "subscription"
            # the bridge's own endpoint as the graph reports it: its QoS with the defaults
            # resolved, comparable with the peers' (the profile it was declared with is not)
            ours = next((e.qos_profile for e in ends if e.node_name == me), None)
            if ours is None:
                continue  # not in the graph yet: the next check sees it
            for peer in peers:
                if peer.node_name == me:
                    continue
                key = (topic, bytes(peer.endpoint_gid))
                if key in self._warned:
                    continue
                fix = ""
                if peer.topic_type != ros_type:
                    why = f"its type is {peer.topic_type}, the bridge's {ros_type}"
                    fix = f": give the {role} the type {type_name}"
                    if in_file:
                        theirs = peer.topic_type.replace("/msg/", "/", 1)
                        fix += f", or the bridge file's entry for {topic} 'type: {theirs}'"
                else:
                    pair = (
                        (peer.qos_profile, ours)
                        if role == "publisher"
                        else (ours, peer.qos_profile)
                    )
                    compatible, reason = q.qos_check_compatible(*pair)
                    if compatible != q.QoSCompatibility.ERROR:
                        continue
                    parts = (p.strip().removeprefix("ERROR: ") for p in reason.split(";"))
                    why = "incompatible QoS: " + "; ".join(p for p in parts if p)
                    fix = _qos_fix(role, topic, why, in_file)
                self._warned.add(key)
                self.stats["incompatible_peers"] += 1
                found += 1
                where = f"{peer.node_namespace.rstrip('/')}/{peer.node_name}"
                log.warning(
                    "the %s of %s on %s cannot match the bridge (%s); no message will pass "
                    "between them%s",
                    role,
                    where,
                    topic,
                    why,
                    fix,
                )
        return found

    def close(self) -> None:
        """Release everything declared on the bus and on ROS 2."""
        for handle in self._bus_handles:
            handle.close()
        self._bus_handles.clear()
        handles, self._ros_handles = self._ros_handles, []
        for kind, handle in handles:
            try:
                getattr(self.node, f"destroy_{kind}")(handle)
            except Exception as exc:  # the node or its context already gone
                log.debug("destroy %s %r: %r", kind, handle, exc)

    def __enter__(self) -> Ros2Bridge:
        self.start()
        return self

    # -- ROS 2 → bus ---------------------------------------------------------------------------
    def _from_ros(self, t: TopicBridge) -> Callable[[Any], None]:
        def on_message(msg: Any) -> None:
            try:
                message = self._to_bus.message(t, ros2_message_to_dict(msg))
                if message is not None:
                    self.bus.publish(t.bus_topic, message)
            except _BAD as exc:
                self.stats["malformed"] += 1
                log.warning("dropped a message from %s (%s): %s", t.ros, t.type, exc)
                return
            self.stats["to_bus"] += 1

        return on_message

    # -- bus → ROS 2 ---------------------------------------------------------------------------
    def _from_bus(self, t: TopicBridge, cls: Any, pub: Any) -> Callable[[Any], None]:
        def on_sample(sample: Any) -> None:
            try:
                msg = fill_ros2_message(cls(), self._ros_fields(t, sample.message))
                pub.publish(msg)
            except _BAD as exc:
                self.stats["malformed"] += 1
                log.warning("dropped a bus message on %s for %s: %s", t.bus_topic, t.ros, exc)
                return
            self.stats["to_ros"] += 1

        return on_sample

    def _ros_fields(self, t: TopicBridge, message: Any) -> dict[str, Any]:
        if isinstance(message, Image):
            if t.type == "sensor_msgs/CompressedImage":
                fields = bus_image_to_compressed(message, time.time())
            elif t.type == "sensor_msgs/Image":
                fields = bus_image_to_raw(message, time.time())
            else:
                raise ConversionError(f"a camera frame cannot become a {t.type}")
            fields["header"].pop("seq", None)  # ROS 2's Header has no seq
            return fields
        return to_ros_fields(body_of(message), t.fields)

    # -- services: bus → ROS 2 -----------------------------------------------------------------
    def _bus_handler(self, s: ServiceBridge, client: Any) -> Callable[[Any], ServiceReply]:
        srv = service_class(s.type)

        def handle(request: Any) -> ServiceReply:
            self.stats["calls"] += 1
            try:
                ros_request = srv.Request()
                # a request type without fields (Trigger, Empty) takes no payload: a reason
                # or note in Utu's request is for the decision log, not for the robot
                has_fields = bool(ros_request.get_fields_and_field_types())
                fields = s.ros_request(body_of(request)) if has_fields else {}
                fill_ros2_message(ros_request, fields)
            except _BAD as exc:
                self.stats["failed_calls"] += 1
                return ServiceReply(ok=False, error=f"bad request for {s.ros_service}: {exc}")
            try:
                reply = self._call(client, ros_request, s)
            except _CallFailed as exc:
                self.stats["failed_calls"] += 1
                return ServiceReply(ok=False, error=f"{s.ros_service}: {exc}")
            answer = ros_reply(reply)
            if not answer.ok:
                self.stats["failed_calls"] += 1
            return answer

        return handle

    def _call(self, client: Any, request: Any, s: ServiceBridge) -> dict[str, Any]:
        if not client.wait_for_service(timeout_sec=s.timeout):
            raise _CallFailed(f"no ROS 2 service answers within {s.timeout:g} s")
        done = threading.Event()
        future = client.call_async(request)
        future.add_done_callback(lambda _f: done.set())
        if not done.wait(s.timeout):
            future.cancel()
            raise _CallFailed(f"no reply within {s.timeout:g} s")
        if future.exception() is not None:
            exc = future.exception()
            raise _CallFailed(f"{type(exc).__name__}: {exc}")
        return ros2_message_to_dict(future.result())

    # -- services: ROS 2 → bus -----------------------------------------------------------------
    def _ros_handler(self, s: ServiceBridge) -> Callable[[Any, Any], Any]:
        inverse = {ros: bus for bus, ros in s.fields.items()}

        async def handle(request: Any, response: Any) -> Any:
            # a coroutine: the executor runs other callbacks while the bus answers (a wait
            # here would hold a single-threaded executor, and deadlock a bus service that
            # calls back into ROS through this bridge)
            self.stats["ros_calls"] += 1
            body = ros2_message_to_dict(request)
            payload = to_bus_fields(body, inverse) if inverse else body
            fields = response.get_fields_and_field_types()
            try:
                reply = await self._bus_reply(s, payload)
                ok, text, answer = True, "", body_of(reply)
                if isinstance(reply, ServiceReply):
                    ok, text, answer = reply.ok, reply.error or "", dict(reply.body)
            except BusError as exc:
                self.stats["failed_calls"] += 1
                ok, text, answer = False, f"{s.bus}: {exc}", {}
            values = {k: v for k, v in answer.items() if k in fields}
            if "success" in fields:
                values["success"] = ok
            if "message" in fields and text:
                values["message"] = text
            try:
                fill_ros2_message(response, values)
            except _BAD as exc:
                self.stats["failed_calls"] += 1
                log.warning("the reply of bus service %s does not fit %s: %s", s.bus, s.type, exc)
            return response

        return handle

    async def _bus_reply(self, s: ServiceBridge, payload: dict[str, Any]) -> Any:
        """The bus service's reply, awaited on the executor (never blocking it).

        Raises:
            BusError: As :meth:`~anunnaki.bus.Bus.request` (no reply in time, an error).

        """
        task = import_module("rclpy.task")
        waiting = task.Future(executor=self.node.executor)
        # a done callback makes set_result wake the executor (it schedules the callback as a
        # task), which then resumes this coroutine; without one it would wait for the next
        # message or timer
        waiting.add_done_callback(lambda _f: None)
        deadline = threading.Timer(s.timeout + 1.0, _expire, (waiting, s))
        deadline.daemon = True  # zenoh ends the query at its timeout; this is the backstop
        deadline.start()

        def settle(sent: Any) -> None:
            if waiting.done():
                return
            if sent.exception() is not None:
                waiting.set_exception(sent.exception())
            else:
                waiting.set_result(sent.result())

        try:
            self.bus.request_start(s.bus, payload, timeout=s.timeout).add_done_callback(settle)
            return await waiting
        finally:
            deadline.cancel()


def _expire(waiting: Any, s: ServiceBridge) -> None:
    """End a bus request that its transport never ended (the in-process bus can't)."""
    if not waiting.done():
        waiting.set_exception(BusTimeout(f"no reply from service {s.bus!r} within {s.timeout} s"))


class _CallFailed(Exception):
    """A ROS 2 service call that got no answer."""


def _qos_fix(role: str, topic: str, why: str, in_file: bool) -> str:
    """What to change when a peer's QoS cannot match the bridge's (``why``: rclpy's reason).

    A best-effort publisher cannot feed a reliable subscription: make it reliable, or let
    the bridge read the topic best effort (``qos: sensor`` in its entry). Anything else
    (durability, deadline, liveliness): the peer takes the bridge's profile for the topic.
    """
    if "Best effort publisher and reliable subscription" in why and role == "publisher":
        fix = ": make the publisher reliable"
        if in_file:
            fix += f", or give the bridge file's entry for {topic} 'qos: sensor' (best effort)"
        return fix
    if not in_file:  # the heartbeat
        return (
            f": give the {role} a QoS the heartbeat offers (reliable, volatile, liveliness "
            "manual by topic; docs/ros.md)"
        )
    return (
        f": give the {role} the QoS the bridge uses on {topic} ('sensor': best effort, keep "
        "last; 'reliable': reliable, keep last; both volatile; docs/ros.md)"
    )
