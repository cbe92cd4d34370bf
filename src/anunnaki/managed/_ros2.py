"""The managed-system kind ``ros2``: a ROS 2 robot whose topics travel on zenoh.

ROS 2 reaches zenoh through zenoh-bridge-ros2dds or rmw_zenoh (docs/ros.md, "ROS 2 over
zenoh"); this kind opens a zenoh session to it (``connect``: the robot's zenoh router or
bridge; default: the launch's own session, when the robot's zenoh joins that one) and runs
:class:`~anunnaki.ros1.Ros2ZenohBridge` with a bridge file, plus the LEC and oracle nodes on
the bridged camera as ``ros1`` does::

    managed:
      kind: ros2
      bridge: ros1/bridge.yaml          # the same bridge files (ROS 1 type names)
      flavour: rmw_zenoh                # or ros2dds
      connect: [tcp/192.168.1.20:7447]  # the robot's zenoh
      oracle: {name: light}
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Sequence
from typing import Annotated, Any, ClassVar, Literal

from pydantic import BaseModel, Field

from anunnaki.errors import ModelFileError
from anunnaki.launch._managed import ManagedContext
from anunnaki.launch._ros1 import RobotKind, _CameraNodes, start_camera_nodes
from anunnaki.utu import Decision

__all__ = ["Ros2Config", "Ros2Kind"]


class Ros2Config(_CameraNodes):
    """A ROS 2 robot over zenoh (``managed: {kind: ros2, …}``).

    Attributes:
        bridge: The bridge file (``anunnaki: ros1-bridge/1``; its topics), relative to the
            launch file.
        flavour: ``ros2dds`` (zenoh-bridge-ros2dds keys) or ``rmw_zenoh``.
        domain: The ROS domain id (rmw_zenoh keys).
        namespace: zenoh-bridge-ros2dds's ``namespace`` option, if it sets one.
        connect: zenoh endpoints of the robot's zenoh; empty: the launch's own session.
        models / camera / oracle: as for ``ros1``.

    """

    flavour: Literal["ros2dds", "rmw_zenoh"] = "ros2dds"
    domain: Annotated[int, Field(ge=0, le=232)] = 0
    namespace: str = ""
    connect: list[str] = Field(default_factory=list)


class _Ros2Run:
    """The running ROS 2 bridge: its zenoh session, the bridge, the nodes."""

    def __init__(self, session: Any, bridge: Any, nodes: list[Any], ctx: ManagedContext) -> None:
        self.session = session
        self.bridge = bridge
        self.nodes = nodes
        self.ended = "stopped"
        self._ctx = ctx
        self.thread = threading.Thread(target=self._watch, name="anunnaki-ros2", daemon=True)
        self.thread.start()

    def _watch(self) -> None:
        started = time.monotonic()
        until = self._ctx.until
        while not self._ctx.stop.wait(0.1):
            if until is not None and time.monotonic() - started >= until:
                self.ended = f"ran {until:g} s"
                return

    def finish(self, decisions: Sequence[Decision], ran: float) -> None:
        return None

    def close(self) -> None:
        for node in reversed(self.nodes):
            node.close()
        self.bridge.close()
        self.session.close()


class Ros2Kind(RobotKind):
    """``kind: ros2``: a ROS 2 robot over zenoh; its camera feeds the LEC and oracle nodes."""

    name: ClassVar[str] = "ros2"
    Options: ClassVar[type[BaseModel]] = Ros2Config
    options: Ros2Config

    def start(self, ctx: ManagedContext) -> _Ros2Run:
        """Open a zenoh session to the robot, start the bridge, then the LEC and oracle nodes."""
        import zenoh

        from anunnaki.bus import BusConfig, on_loopback
        from anunnaki.ros1 import Ros2ZenohBridge, load_bridge

        o = self.options
        connect = list(o.connect) or [on_loopback(e) for e in getattr(ctx.bus, "endpoints", ())]
        if not connect:
            raise ModelFileError(
                "a ros2 managed system needs the robot's zenoh endpoints, or the zenoh bus",
                element="managed.connect",
                hint="give connect: [tcp/ROBOT:7447], or write bus: {kind: zenoh}",
            )
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
        )
        nodes: list[Any] = []
        try:
            bridge.start()
            nodes = start_camera_nodes(ctx.bus, o)
        except BaseException:
            _Ros2Run(session, bridge, nodes, ctx).close()
            raise
        ctx.say(
            f"managed: ROS 2 robot over zenoh ({o.flavour}, {', '.join(connect)}) through "
            f"{o.bridge}"
        )
        return _Ros2Run(session, bridge, nodes, ctx)
