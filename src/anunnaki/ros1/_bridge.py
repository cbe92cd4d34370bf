"""The bridge node: ROS 1 topics and services to and from the bus, as a bridge file says.

One :class:`Bridge` lives in its own process (:mod:`anunnaki.ros1.__main__`), which imports
Debian's rospy (:func:`~anunnaki.ros1._rospy.import_rospy`). It never dies from one bad
message: a message that does not convert is counted (:attr:`Bridge.stats`) and logged, and
the next one goes through.

The master may restart under it (a robot's roscore restarted): a watchdog asks the master
for its pid every ``watch_every`` seconds and, when a new master answers, registers every
ROS subscriber, publisher and service with it again (:func:`reregister_node`; open
connections stay up), so the bridge carries on without a restart of its own. A ROS node
that dies simply stops sending; the goal model's staleness turns its agent unknown (the
bridge invents nothing).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable
from types import ModuleType
from typing import Any

from anunnaki._closing import Closing
from anunnaki.bus import Bus
from anunnaki.messages import Image, ServiceReply, body_of
from anunnaki.ros1._rospy import master_pid, message_class, reregister_node, service_class
from anunnaki.rosbridge import (
    BridgeSpec,
    ConversionError,
    ServiceBridge,
    ToBus,
    TopicBridge,
    bus_image_to_compressed,
    bus_image_to_raw,
    fill_message,
    message_to_dict,
    ros_reply,
    to_ros_fields,
)

__all__ = ["Bridge"]

log = logging.getLogger("anunnaki.ros1")


class Bridge(Closing):
    """Carries a bridge file's topics and services between ROS 1 and the bus.

    Args:
        spec: The bridge file, loaded (:func:`~anunnaki.ros1.load_bridge`).
        bus: The bus to publish and serve on (usually zenoh, shared with Utu's nodes).
        rospy: The imported rospy module, with ``init_node`` already called.
        watch_every: Seconds between the watchdog's looks at the master (0: no watchdog).

    Attributes:
        stats: Counters: ``to_bus``, ``to_ros``, ``calls``, ``failed_calls``,
            ``malformed`` (messages that did not convert), ``reregistered``.

    """

    def __init__(
        self, spec: BridgeSpec, bus: Bus, rospy: ModuleType, *, watch_every: float = 0.5
    ) -> None:
        self.spec = spec
        self.bus = bus
        self.rospy = rospy
        self.stats: Counter[str] = Counter()
        self._lock = threading.Lock()
        self._to_bus = ToBus(spec)
        self._ros_handles: list[Any] = []
        self._publishers: dict[int, Any] = {}
        self._bus_handles: list[Any] = []
        self._stop = threading.Event()
        self._watch_every = watch_every
        self._watchdog: threading.Thread | None = None
        self._master_pid: int | None = None

    # -- life ----------------------------------------------------------------------------------
    def start(self) -> None:
        """Declare everything on ROS and on the bus, and start the master watchdog."""
        self._declare_ros()
        for i, t in enumerate(self.spec.topics):
            if t.direction == "to_ros":
                self._bus_handles.append(
                    self.bus.subscribe(t.bus_topic, self._from_bus(i, t), queue=t.queue)
                )
        for s in self.spec.services:
            self._bus_handles.append(self.bus.service(s.bus, self._service_handler(s)))
        self._master_pid = master_pid(self.rospy.get_name())
        if self._watch_every > 0:
            self._watchdog = threading.Thread(
                target=self._watch, name="anunnaki-ros1-watchdog", daemon=True
            )
            self._watchdog.start()

    def close(self) -> None:
        """Stop the watchdog and release everything declared on ROS and the bus."""
        self._stop.set()
        if self._watchdog is not None:
            self._watchdog.join(timeout=5.0)
        self._undeclare_ros()
        for handle in self._bus_handles:
            handle.close()
        self._bus_handles.clear()

    def __enter__(self) -> Bridge:
        self.start()
        return self

    # -- ROS side ------------------------------------------------------------------------------
    def _declare_ros(self) -> None:
        rospy = self.rospy
        with self._lock:
            for i, t in enumerate(self.spec.topics):
                cls = message_class(t.type)
                if t.direction == "to_bus":
                    self._ros_handles.append(
                        rospy.Subscriber(t.ros, cls, self._from_ros(t), queue_size=t.queue)
                    )
                else:
                    pub = rospy.Publisher(t.ros, cls, queue_size=t.queue)
                    self._publishers[i] = pub
                    self._ros_handles.append(pub)

    def _undeclare_ros(self) -> None:
        with self._lock:
            handles, self._ros_handles = self._ros_handles, []
            self._publishers = {}
        for handle in handles:
            try:
                handle.unregister()
            except Exception as exc:  # a master gone away: nothing left to tell it
                log.debug("unregister %s: %r", getattr(handle, "name", handle), exc)

    def _watch(self) -> None:
        while not self._stop.wait(self._watch_every):
            pid = master_pid(self.rospy.get_name())
            if pid is None or pid == self._master_pid:
                continue
            if self._master_pid is not None:
                log.warning("a new ROS master answers (pid %s): registering again", pid)
                reregister_node()
                self.stats["reregistered"] += 1
            self._master_pid = pid

    # -- ROS → bus -----------------------------------------------------------------------------
    def _from_ros(self, t: TopicBridge) -> Callable[[Any], None]:
        def on_message(msg: Any) -> None:
            try:
                message = self._to_bus.message(t, message_to_dict(msg))
                if message is not None:
                    self.bus.publish(t.bus_topic, message)
            except (ConversionError, KeyError, ValueError, TypeError) as exc:
                self.stats["malformed"] += 1
                log.warning("dropped a message from %s (%s): %s", t.ros, t.type, exc)
                return
            self.stats["to_bus"] += 1

        return on_message

    # -- bus → ROS -----------------------------------------------------------------------------
    def _from_bus(self, index: int, t: TopicBridge) -> Callable[[Any], None]:
        cls = message_class(t.type)

        def on_sample(sample: Any) -> None:
            with self._lock:
                pub = self._publishers.get(index)
            if pub is None:
                return
            try:
                msg = fill_message(cls(), self._ros_fields(t, sample.message))
            except (ConversionError, ValueError, TypeError) as exc:
                self.stats["malformed"] += 1
                log.warning("dropped a bus message on %s for %s: %s", t.bus_topic, t.ros, exc)
                return
            pub.publish(msg)
            self.stats["to_ros"] += 1

        return on_sample

    def _ros_fields(self, t: TopicBridge, message: Any) -> dict[str, Any]:
        if isinstance(message, Image):
            if t.type == "sensor_msgs/CompressedImage":
                return bus_image_to_compressed(message, time.time())
            if t.type == "sensor_msgs/Image":
                return bus_image_to_raw(message, time.time())
            raise ConversionError(f"a camera frame cannot become a {t.type}")
        return to_ros_fields(body_of(message), t.fields)

    # -- services ------------------------------------------------------------------------------
    def _service_handler(self, s: ServiceBridge) -> Callable[[Any], ServiceReply]:
        srv = service_class(s.type)

        def handle(request: Any) -> ServiceReply:
            self.stats["calls"] += 1
            try:
                ros_request = srv._request_class()
                # a request type without fields (Trigger, Empty) takes no payload: a reason
                # or note in Utu's request is for the decision log, not for the robot
                fields = s.ros_request(body_of(request)) if ros_request.__slots__ else {}
                fill_message(ros_request, fields)
            except (ConversionError, ValueError, TypeError) as exc:
                self.stats["failed_calls"] += 1
                return ServiceReply(ok=False, error=f"bad request for {s.ros_service}: {exc}")
            try:
                self.rospy.wait_for_service(s.ros_service, timeout=s.timeout)
                proxy = self.rospy.ServiceProxy(s.ros_service, srv)
                reply = message_to_dict(proxy.call(ros_request))
            except Exception as exc:  # ROS exceptions: unavailable, timed out, refused
                self.stats["failed_calls"] += 1
                return ServiceReply(ok=False, error=f"{s.ros_service}: {type(exc).__name__}: {exc}")
            answer = ros_reply(reply)
            if not answer.ok:
                self.stats["failed_calls"] += 1
            return answer

        return handle
