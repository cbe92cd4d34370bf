"""The managed-system kind ``ros2``: a ROS 2 robot, natively (rclpy) or over zenoh.

``flavour: rclpy`` (the default) starts the native bridge as a process of its own,
``PYTHON -m anunnaki.ros2 BRIDGE --connect <the launch's zenoh endpoint> --exit-with-parent``
with a Python that imports rclpy (``python``, else ``$ANUNNAKI_ROS2_PYTHON``, else this
Python if it imports rclpy, else the ``.venv-ros2`` scripts/setup-ros2.sh builds), and waits
until it says it is ready, as the ``ros1`` kind does::

    managed:
      kind: ros2
      bridge: ros2/bridge.yaml          # anunnaki: ros2-bridge/1
      models: ../models/rover.yaml
      oracle: {name: light}

``flavour: ros2dds`` or ``rmw_zenoh`` reach ROS 2 through zenoh-bridge-ros2dds or rmw_zenoh
(docs/ros.md, "ROS 2 over zenoh"): this kind opens a zenoh session to it (``connect``: the
robot's zenoh router or bridge; default: the launch's own session) and runs
:class:`~anunnaki.ros2.Ros2ZenohBridge` in the launch's process. Either way the camera chain
on the bridged camera and the run are every robot kind's (:mod:`anunnaki.managed._robot`).
"""

from __future__ import annotations

import importlib.util
import json
import os
import sys
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal

from pydantic import BaseModel, Field

from anunnaki.errors import AnunnakiError, ModelFileError
from anunnaki.managed._bridgeproc import BridgeProcess, start_bridge
from anunnaki.managed._robot import RobotConfig, RobotKind
from anunnaki.managed._slot import ManagedContext

__all__ = ["Ros2Config", "Ros2Kind"]


class Ros2Config(RobotConfig):
    """A ROS 2 robot (``managed: {kind: ros2, …}``).

    Attributes:
        bridge: The bridge file (``anunnaki: ros2-bridge/1``, or a ROS 1 one over zenoh),
            relative to the launch file.
        flavour: ``rclpy`` (the native bridge process), ``ros2dds`` (zenoh-bridge-ros2dds
            keys) or ``rmw_zenoh``.
        python: (rclpy) The Python that runs the bridge (one that imports rclpy).
        ready_timeout: (rclpy) Seconds to wait for the bridge to say it is ready.
        domain: The ROS domain id (rmw_zenoh keys).
        namespace: zenoh-bridge-ros2dds's ``namespace`` option, if it sets one.
        connect: zenoh endpoints of the robot's zenoh; empty: the launch's own session.
        distro: The robot's ROS 2 distribution (default: the bridge file's, else
            ``$ROS_DISTRO``); its message definitions decode the samples.
        models / camera / oracle / scorer: the camera chain (:class:`RobotConfig`).

    """

    flavour: Literal["rclpy", "ros2dds", "rmw_zenoh"] = "rclpy"
    python: str | None = None
    ready_timeout: Annotated[float, Field(gt=0, le=600)] = 60.0
    domain: Annotated[int, Field(ge=0, le=232)] = 0
    namespace: str = ""
    connect: list[str] = Field(default_factory=list)
    distro: Literal["humble", "jazzy", "kilted"] | None = None


class _ZenohLink:
    """The zenoh session to the robot and the bridge on it (reachable until closed)."""

    gone = "the zenoh session closed"

    def __init__(self, session: Any, bridge: Any) -> None:
        self.session = session
        self.bridge = bridge

    def alive(self) -> bool:
        return True  # zenoh reconnects by itself; liveliness says when the robot is gone

    def close(self) -> None:
        self.bridge.close()
        self.session.close()


class Ros2Kind(RobotKind):
    """``kind: ros2``: a ROS 2 robot, bridged; its camera feeds the camera chain."""

    name: ClassVar[str] = "ros2"
    Options: ClassVar[type[BaseModel]] = Ros2Config
    options: Ros2Config

    def connect(self, ctx: ManagedContext) -> _ZenohLink | BridgeProcess:
        """Start the native bridge process, or open a zenoh session to the robot's zenoh."""
        if self.options.flavour == "rclpy":
            return self._start_native(ctx)
        import zenoh

        from anunnaki.bus import BusConfig
        from anunnaki.ros2 import Ros2ZenohBridge
        from anunnaki.rosbridge import load_bridge

        o = self.options
        connect = self._endpoints(ctx)
        config = BusConfig(kind="zenoh", mode="peer", connect=connect)
        # listening too (a free loopback port): peers that reach the same session find this
        # one through zenoh's gossip and connect directly (peers do not route for others)
        listen = config.effective_listen()
        session = zenoh.open(zenoh.Config.from_json5(json.dumps(config.to_zenoh(listen))))
        bridge = Ros2ZenohBridge(
            load_bridge(o.bridge),
            ctx.bus,
            session,
            flavour="rmw_zenoh" if o.flavour == "rmw_zenoh" else "ros2dds",
            domain=o.domain,
            namespace=o.namespace,
            distro=o.distro,
        )
        link = _ZenohLink(session, bridge)
        try:
            bridge.start()
        except BaseException:
            link.close()
            raise
        return link

    def _start_native(self, ctx: ManagedContext) -> BridgeProcess:
        from anunnaki.bus import on_loopback

        endpoints = [on_loopback(e) for e in getattr(ctx.bus, "endpoints", ())]
        if getattr(ctx.bus, "kind", None) != "zenoh" or not endpoints:
            raise ModelFileError(
                "a ros2 managed system needs the zenoh bus (the bridge is another process)",
                element="bus",
                hint="write bus: {kind: zenoh} in the launch file",
            )
        o = self.options
        args = [ros2_python(o.python), "-m", "anunnaki.ros2", o.bridge, "--connect", endpoints[0]]
        env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        env["PYTHONUNBUFFERED"] = "1"
        return start_bridge(args, env, "ros2", o.ready_timeout, ctx.say)

    def _endpoints(self, ctx: ManagedContext) -> list[str]:
        from anunnaki.bus import on_loopback

        connect = list(self.options.connect) or [
            on_loopback(e) for e in getattr(ctx.bus, "endpoints", ())
        ]
        if not connect:
            raise ModelFileError(
                "a ros2 managed system needs the robot's zenoh endpoints, or the zenoh bus",
                element="managed.connect",
                hint="give connect: [tcp/ROBOT:7447], or write bus: {kind: zenoh}",
            )
        return connect

    def describe(self, ctx: ManagedContext) -> str:
        """``ROS 2 robot through BRIDGE (rclpy)`` or ``... over zenoh (FLAVOUR, ENDPOINTS)``."""
        o = self.options
        if o.flavour == "rclpy":
            return f"ROS 2 robot through {o.bridge} (rclpy)"
        where = ", ".join(self._endpoints(ctx))
        return f"ROS 2 robot over zenoh ({o.flavour}, {where}) through {o.bridge}"


def ros2_python(named: str | None = None) -> str:
    """The Python that runs the native bridge: one that imports rclpy.

    ``named`` (the launch's ``python``), else ``$ANUNNAKI_ROS2_PYTHON``, else this Python if
    it imports rclpy, else ``.venv-ros2/bin/python`` in the working folder or in the
    checkout anunnaki runs from (scripts/setup-ros2.sh builds it).

    Raises:
        AnunnakiError: None of them exists (the message says how to get one).

    """
    for candidate in (named, os.environ.get("ANUNNAKI_ROS2_PYTHON")):
        if candidate:
            if not Path(candidate).exists():
                raise AnunnakiError(f"the ROS 2 Python {candidate} does not exist")
            return candidate
    if importlib.util.find_spec("rclpy") is not None:
        return sys.executable
    checkout = Path(__file__).resolve().parents[3]
    for root in (Path.cwd(), checkout):
        venv = root / ".venv-ros2" / "bin" / "python"
        if venv.exists():
            return str(venv)
    raise AnunnakiError(
        "no Python with rclpy for the ROS 2 bridge: run scripts/setup-ros2.sh (builds "
        ".venv-ros2, no root), or name one: managed.python or $ANUNNAKI_ROS2_PYTHON"
    )
