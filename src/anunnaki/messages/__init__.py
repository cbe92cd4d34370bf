"""The shared vocabulary: the typed messages every part of Anunnaki speaks.

What travels is defined here, where it travels in :mod:`anunnaki.topics` and how in
:mod:`anunnaki.bus` (the transport: sessions, envelopes, QoS, liveliness). The split is ROS's:
message packages beside the client library, so that a part that only builds or reads
messages (a trace player, a bridge, a test) needs no transport, and the transport knows no
message of the LEC, the oracles, the platforms or Utu's cycle::

    from anunnaki import topics
    from anunnaki.bus import open_bus
    from anunnaki.messages import ModeReply, ModeRequest

    with open_bus("inproc") as bus:
        bus.service("/rover/set_mode", lambda req: ModeReply(mode=req.mode, accepted=True))
        bus.request("/rover/set_mode", ModeRequest(mode="manual"), timeout=2.0)
        bus.subscribe(topics.ORACLE_OUTPUT, print)

Every message is a frozen, strictly validated pydantic model deriving from :class:`Message`
(``VERSION``: the schema version on the wire; ``TYPE_NAME``: the name on the wire, the class
name by default; ``BINARY_FIELD``: a ``bytes`` field sent raw after the JSON header).

The message types (:data:`MESSAGES`, a :class:`~anunnaki.plugins.Registry` like every slot)
    ==============================  ==============================================================
    who speaks                      types
    ==============================  ==============================================================
    any node                        :class:`Generic` (any JSON object), :class:`Clock`,
                                    :class:`ServiceReply`
    Utu to a managed system         :class:`ModeRequest`, :class:`ModeReply`, :class:`RunStop`
    the perception chain            :class:`Image` (a camera frame), :class:`Detections` (the
                                    LEC), :class:`Assessment` (a behaviour oracle)
    Utu's cycle between its parts   :class:`MonitorBatch` of :class:`MonitorInput`,
                                    :class:`AnalysisState`, :class:`ExecuteStatus`,
                                    :class:`PlanStart`, :class:`CycleDone` (:data:`MAX_BATCH`)
    ==============================  ==============================================================

Add a type with the class decorator ``@MESSAGES.register`` (its type name follows the one
name rule of every slot, :data:`anunnaki.plugins.NAME_RULE`), or from another package by
the entry-point group ``anunnaki.messages``. ``MESSAGES.factory(name)`` returns a class,
``MESSAGES.names()`` the registered names; an unknown name raises :class:`MessageError`
listing them. :func:`body_of` reads a message or a plain mapping as a JSON object.
"""

from __future__ import annotations

from anunnaki.messages._base import MESSAGES, Message, MessageError, body_of
from anunnaki.messages._basic import Clock, Generic, ModeReply, ModeRequest, RunStop, ServiceReply
from anunnaki.messages._cycle import (
    MAX_BATCH,
    AnalysisState,
    CycleDone,
    ExecuteStatus,
    MonitorBatch,
    MonitorInput,
    PlanStart,
)
from anunnaki.messages._image import Image
from anunnaki.messages._perception import Assessment, Detections

__all__ = [
    "MAX_BATCH",
    "MESSAGES",
    "AnalysisState",
    "Assessment",
    "Clock",
    "CycleDone",
    "Detections",
    "ExecuteStatus",
    "Generic",
    "Image",
    "Message",
    "MessageError",
    "ModeReply",
    "ModeRequest",
    "MonitorBatch",
    "MonitorInput",
    "PlanStart",
    "RunStop",
    "ServiceReply",
    "body_of",
]
