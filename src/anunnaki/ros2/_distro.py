"""Which ROS 2 distribution's message definitions apply: named, or found, never assumed.

Message definitions change between distributions (Jazzy's ``sensor_msgs/Range`` gained
``variance``; a Humble definition reads a Jazzy sample as a ``CDR message size mismatch``).
:func:`resolve_distro` takes, in order: the distribution named (a bridge file's ``distro``,
a launch's option), ``$ROS_DISTRO`` (set by a ROS 2 install's ``setup.bash``), the ROS 2
wheels installed in this environment (``ros-<distro>-rclpy``, scripts/setup-ros2.sh); with
none of them it is an error that says what to write.
"""

from __future__ import annotations

import os
from importlib import metadata
from typing import Any

from anunnaki.errors import AnunnakiError, MissingExtraError
from anunnaki.rosbridge import DISTROS, Distro

__all__ = ["installed_distro", "resolve_distro", "type_store"]


def installed_distro() -> Distro | None:
    """The ROS 2 distribution of the rclpy installed here (``$ROS_DISTRO`` first), if any."""
    env = os.environ.get("ROS_DISTRO", "").strip().lower()
    if env in DISTROS:
        return env
    for distro in DISTROS:
        try:
            metadata.version(f"ros-{distro}-rclpy")
        except metadata.PackageNotFoundError:
            continue
        return distro
    return None


def resolve_distro(named: str | None = None, *, where: str = "the bridge file") -> Distro:
    """The ROS 2 distribution to use: ``named``, else the installed one.

    Raises:
        AnunnakiError: An unknown name, or none named and none installed.

    """
    if named is not None:
        if named not in DISTROS:
            raise AnunnakiError(
                f"unknown ROS 2 distribution {named!r} in {where}; known: {', '.join(DISTROS)}"
            )
        return named
    found = installed_distro()
    if found is None:
        raise AnunnakiError(
            f"which ROS 2 distribution does the robot run? Name it in {where} "
            f"(distro: {' | '.join(DISTROS)}) or set $ROS_DISTRO; its message definitions differ "
            "(Jazzy's sensor_msgs/Range has 'variance', Humble's has not)"
        )
    return found


_STORES: dict[str, Any] = {}


def type_store(distro: Distro) -> Any:
    """``rosbags``' type store of a ROS 2 distribution (cached)."""
    if distro not in _STORES:
        try:
            from rosbags.typesys import Stores, get_typestore
        except ImportError:
            raise MissingExtraError("rosbags", "ros") from None
        _STORES[distro] = get_typestore(getattr(Stores, f"ROS2_{distro.upper()}"))
    return _STORES[distro]
