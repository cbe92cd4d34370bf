"""The managed-system kind ``ros2``: a ROS 2 robot whose topics travel on zenoh.

ROS 2 reaches zenoh through zenoh-bridge-ros2dds or rmw_zenoh (docs/ros.md, "ROS 2 over
zenoh"); this kind opens a zenoh session to it (``connect``: the robot's zenoh router or
bridge; default: the launch's own session, when the robot's zenoh joins that one) and runs
:class:`~anunnaki.ros2.Ros2ZenohBridge` with a bridge file; the camera chain on the bridged
camera and the run are every robot kind's (:mod:`anunnaki.managed._robot`)::

    managed:
      kind: ros2
      bridge: ros1/bridge.yaml          # the same bridge files (ROS 1 type names)
      flavour: rmw_zenoh                # or ros2dds
      connect: [tcp/192.168.1.20:7447]  # the robot's zenoh
      oracle: {name: light}
"""

from __future__ import annotations

import json
from typing import Annotated, Any, ClassVar, Literal

from pydantic import BaseModel, Field

from anunnaki.errors import ModelFileError
from anunnaki.managed._robot import RobotConfig, RobotKind
from anunnaki.managed._slot import ManagedContext

__all__ = ["Ros2Config", "Ros2Kind"]


class Ros2Config(RobotConfig):
    """A ROS 2 robot over zenoh (``managed: {kind: ros2, …}``).

    Attributes:
        bridge: The bridge file (``anunnaki: ros1-bridge/1``; its topics), relative to the
            launch file.
        flavour: ``ros2dds`` (zenoh-bridge-ros2dds keys) or ``rmw_zenoh``.
        domain: The ROS domain id (rmw_zenoh keys).
        namespace: zenoh-bridge-ros2dds's ``namespace`` option, if it sets one.
        connect: zenoh endpoints of the robot's zenoh; empty: the launch's own session.
        distro: The robot's ROS 2 distribution (default: the bridge file's, else
            ``$ROS_DISTRO``); its message definitions decode the samples.
        models / camera / oracle / scorer: the camera chain (:class:`RobotConfig`).

    """

    flavour: Literal["ros2dds", "rmw_zenoh"] = "ros2dds"
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
    """``kind: ros2``: a ROS 2 robot over zenoh; its camera feeds the camera chain."""

    name: ClassVar[str] = "ros2"
    Options: ClassVar[type[BaseModel]] = Ros2Config
    options: Ros2Config

    def connect(self, ctx: ManagedContext) -> _ZenohLink:
        """Open a zenoh session to the robot and start the bridge on it."""
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
            flavour=o.flavour,
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
        """``ROS 2 robot over zenoh (FLAVOUR, ENDPOINTS) through BRIDGE``."""
        o = self.options
        where = ", ".join(self._endpoints(ctx))
        return f"ROS 2 robot over zenoh ({o.flavour}, {where}) through {o.bridge}"
