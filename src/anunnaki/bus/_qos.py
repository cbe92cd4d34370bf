"""Quality of service: which topics are urgent, which may be dropped (guidelines S1, S2).

One table decides, for a topic and the type of the message sent on it, the priority and the
reliability. The message type decides first (a :class:`RunStop` is always critical, an
:class:`Image` is always a droppable camera frame), then the first topic pattern that matches,
then the default. A publisher may override either field.

==========  ================================  ========  ========  ==========  ================
class       topics / message types            priority  reliable  congestion  zenoh priority
==========  ================================  ========  ========  ==========  ================
run_stop    ``/utu/run_stop``, RunStop        critical  yes       block       REAL_TIME
tactic      ``/utu/execute/**``, ModeRequest  high      yes       block       INTERACTIVE_HIGH
assessment  ``/utu/oracle/**``                high      yes       block       INTERACTIVE_HIGH
camera      ``**/camera/**``, Image           low       no        drop        DATA_LOW
default     everything else                   normal    yes       block       DATA
==========  ================================  ========  ========  ==========  ================

Critical and high messages are sent *express* (not batched).

Priorities also order delivery inside a subscriber: its bounded queue hands out the most
urgent message first and, when full, evicts the oldest message of the *least* urgent class, so
a camera flood never pushes a run-stop out of a shared subscription.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from anunnaki import topics
from anunnaki.bus._errors import BusConfigError
from anunnaki.bus._keys import key_matches

__all__ = ["PRIORITIES", "QOS_TABLE", "QoS", "TopicClass", "qos_for"]

Priority = Literal["critical", "high", "normal", "low"]

#: Priorities from the most to the least urgent; the index is the priority's rank.
PRIORITIES: tuple[Priority, ...] = ("critical", "high", "normal", "low")


@dataclass(frozen=True, slots=True)
class QoS:
    """How messages of one topic travel.

    Attributes:
        priority: ``"critical"``, ``"high"``, ``"normal"`` or ``"low"``.
        reliable: Reliable delivery; a full network queue then blocks the publisher
            (congestion control *block*) instead of dropping (*drop*).
        topic_class: Name of the table row that gave this QoS (``"custom"`` when overridden).

    """

    priority: Priority
    reliable: bool
    topic_class: str = "default"

    @property
    def rank(self) -> int:
        """0 for critical … 3 for low."""
        return PRIORITIES.index(self.priority)

    @property
    def congestion(self) -> Literal["block", "drop"]:
        """``"block"`` for reliable topics, ``"drop"`` for best-effort ones."""
        return "block" if self.reliable else "drop"

    @property
    def express(self) -> bool:
        """Send without batching (critical and high priority)."""
        return self.rank <= 1


@dataclass(frozen=True, slots=True)
class TopicClass:
    """One row of the QoS table.

    Attributes:
        name: The class name.
        patterns: ROS-style topic patterns (``*``, ``**``) of the class.
        message_types: Message type names that belong to the class whatever their topic.
        qos: The class's QoS.

    """

    name: str
    patterns: tuple[str, ...]
    message_types: tuple[str, ...]
    qos: QoS


QOS_TABLE: tuple[TopicClass, ...] = (
    TopicClass("run_stop", (topics.RUN_STOP,), ("RunStop",), QoS("critical", True, "run_stop")),
    TopicClass("tactic", ("/utu/execute/**",), ("ModeRequest",), QoS("high", True, "tactic")),
    TopicClass("assessment", ("/utu/oracle/**",), (), QoS("high", True, "assessment")),
    TopicClass("camera", ("/**/camera/**",), ("Image",), QoS("low", False, "camera")),
)
DEFAULT_QOS = QoS("normal", True, "default")


def qos_for(
    topic: str,
    message_type: str | None = None,
    *,
    priority: Priority | None = None,
    reliable: bool | None = None,
    table: tuple[TopicClass, ...] = QOS_TABLE,
) -> QoS:
    """Return the QoS of a ``message_type`` message on ``topic`` (absolute ROS-style name).

    Args:
        topic: The topic, e.g. ``/rover/camera/image``.
        message_type: The message's type name, when known.
        priority: Override of the table's priority.
        reliable: Override of the table's reliability.
        table: The table to use.

    """
    base = DEFAULT_QOS
    found = False
    if message_type is not None:
        for row in table:
            if message_type in row.message_types:
                base, found = row.qos, True
                break
    if not found:
        for row in table:
            if any(key_matches(p.lstrip("/"), topic.lstrip("/")) for p in row.patterns):
                base = row.qos
                break
    if priority is None and reliable is None:
        return base
    if priority is not None and priority not in PRIORITIES:
        raise BusConfigError(f"priority must be one of {', '.join(PRIORITIES)}, got {priority!r}")
    return QoS(
        priority if priority is not None else base.priority,
        reliable if reliable is not None else base.reliable,
        "custom",
    )
