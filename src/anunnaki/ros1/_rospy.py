"""Importing Debian's rospy into this process, and the message classes the bridge needs.

ROS 1 comes from Debian (``python3-rospy`` and friends, ``scripts/setup-ros.sh``) and lives
in ``/usr/lib/python3/dist-packages``. :func:`import_rospy` *appends* that folder to
``sys.path`` of the bridge process — never ``PYTHONPATH``, which would let Debian's PyYAML
and others shadow the virtual environment's. Only the bridge process calls it.
"""

from __future__ import annotations

import hashlib
import importlib
import os
import sys
from types import ModuleType
from typing import Any

from anunnaki.errors import AnunnakiError
from anunnaki.rosbridge import SET_STRING_SRV

__all__ = [
    "ROS_DIST_PACKAGES",
    "RosUnavailable",
    "import_rospy",
    "master_pid",
    "message_class",
    "reregister_node",
    "service_class",
]

#: Where Debian installs ROS 1's Python packages (``$ANUNNAKI_ROS_PYTHONPATH`` overrides).
ROS_DIST_PACKAGES = os.environ.get("ANUNNAKI_ROS_PYTHONPATH", "/usr/lib/python3/dist-packages")

APT_PACKAGES = (
    "python3-rospy python3-rosmaster python3-std-msgs python3-sensor-msgs "
    "python3-geometry-msgs python3-std-srvs"
)


class RosUnavailable(AnunnakiError):
    """rospy cannot be imported here; the message says what to install."""


def import_rospy() -> ModuleType:
    """Import rospy, appending Debian's ROS folder to ``sys.path`` when needed.

    Raises:
        RosUnavailable: rospy is not installed (the message names the apt packages).

    """
    try:
        return importlib.import_module("rospy")
    except ImportError:
        pass
    if ROS_DIST_PACKAGES not in sys.path:
        sys.path.append(ROS_DIST_PACKAGES)
    try:
        return importlib.import_module("rospy")
    except ImportError as exc:
        raise RosUnavailable(
            f"cannot import rospy ({exc}); the ROS 1 bridge needs Debian's ROS 1 packages: "
            f"apt-get install {APT_PACKAGES} (or run scripts/setup-ros.sh as root)"
        ) from None


def message_class(type_name: str) -> Any:
    """The genpy class of ROS message type ``pkg/Name``."""
    package, name = type_name.split("/", 1)
    module = importlib.import_module(f"{package}.msg")
    return getattr(module, name)


_SERVICES: dict[str, Any] = {}


def service_class(type_name: str) -> Any:
    """The class of ROS service type ``pkg/Name`` (``anunnaki_msgs/SetString`` is built here)."""
    if type_name in _SERVICES:
        return _SERVICES[type_name]
    if type_name == "anunnaki_msgs/SetString":
        cls = _set_string()
    else:
        package, name = type_name.split("/", 1)
        cls = getattr(importlib.import_module(f"{package}.srv"), name)
    _SERVICES[type_name] = cls
    return cls


def _set_string() -> Any:
    """``anunnaki_msgs/SetString`` from its text, as genpy would generate it (same md5)."""
    import genpy.dynamic

    request_text, response_text = SET_STRING_SRV.split("---\n")
    req = genpy.dynamic.generate_dynamic("anunnaki_msgs/SetStringRequest", request_text)[
        "anunnaki_msgs/SetStringRequest"
    ]
    resp = genpy.dynamic.generate_dynamic("anunnaki_msgs/SetStringResponse", response_text)[
        "anunnaki_msgs/SetStringResponse"
    ]
    md5 = hashlib.md5(
        (request_text.strip() + response_text.strip()).encode(), usedforsecurity=False
    ).hexdigest()

    class SetString:
        _type = "anunnaki_msgs/SetString"
        _md5sum = md5
        _request_class = req
        _response_class = resp

    req._service_class = SetString
    resp._service_class = SetString
    return SetString


def master_pid(caller_id: str) -> int | None:
    """The pid of the ROS master now answering at ``$ROS_MASTER_URI`` (``None``: none)."""
    try:
        import rosgraph

        return int(rosgraph.Master(caller_id).getPid())
    except Exception:  # refused, timed out, or no master: all mean "none now"
        return None


def reregister_node() -> int:
    """Register this node's publishers, subscribers and services with the master again.

    A restarted master knows nobody; rospy does not notice. This tells it everything this
    node declared, through rospy's own registration manager, without closing any
    connection (peers keep talking; new ones find us). Returns how many were registered.
    """
    from rospy.impl.registration import (
        Registration,
        RegManager,
        get_registration_listeners,
        get_service_manager,
        get_topic_manager,
    )

    managers = [m for m in get_registration_listeners().listeners if isinstance(m, RegManager)]
    tm, sm = get_topic_manager(), get_service_manager()
    n = 0
    for manager in managers:
        for name, type_ in tm.get_publications():
            manager.reg_added(name, type_, Registration.PUB)
            n += 1
        for name, type_ in tm.get_subscriptions():
            manager.reg_added(name, type_, Registration.SUB)
            n += 1
        for name, uri in sm.get_services():
            manager.reg_added(name, uri, Registration.SRV)
            n += 1
    return n
