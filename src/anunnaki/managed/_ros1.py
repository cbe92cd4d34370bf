"""The managed-system kind ``ros1``: a ROS 1 robot through the bridge process.

A launch file names it like the others::

    managed:
      kind: ros1
      bridge: ros1/bridge.yaml          # which ROS topics and services meet the bus
      master_uri: http://127.0.0.1:11311  # default: $ROS_MASTER_URI
      models: ../models/rover.yaml      # optional: run the LEC node on the bridged camera
      oracle: {name: light}             # optional: an oracle node on the same camera

Starting it starts ``python -m anunnaki.ros1 BRIDGE --connect <the launch's zenoh
endpoint> --exit-with-parent`` (rospy lives in that process only; it stops once the launch
is gone, even after a ``kill -9``) and waits for it to say it is ready; the
rest (the camera chain on the bridged camera, the run) is every robot kind's
(:mod:`anunnaki.managed._robot`). The run ends when the launch stops it, or when the bridge
process exits. The launch's bus must be zenoh (the bridge is another process).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from typing import Annotated, ClassVar

from pydantic import BaseModel, Field

from anunnaki.bus import on_loopback
from anunnaki.errors import ModelFileError
from anunnaki.managed._bridgeproc import BridgeProcess, start_bridge
from anunnaki.managed._robot import RobotConfig, RobotKind
from anunnaki.managed._slot import ManagedContext

__all__ = ["Ros1Config", "Ros1Kind"]


class Ros1Config(RobotConfig):
    """A ROS 1 robot through the bridge (``managed: {kind: ros1, …}``).

    Attributes:
        bridge: The bridge file (``anunnaki: ros1-bridge/1``), relative to the launch file.
        master_uri: The robot's ROS master (default ``$ROS_MASTER_URI``).
        ros_ip: This machine's address as the robot reaches it (default ``$ROS_IP``).
        models / camera / oracle / scorer: the camera chain (:class:`RobotConfig`).
        ready_timeout: Seconds to wait for the bridge to say it is ready.

    """

    master_uri: str | None = None
    ros_ip: str | None = None
    ready_timeout: Annotated[float, Field(gt=0, le=600)] = 60.0


class Ros1Kind(RobotKind):
    """``kind: ros1``: a ROS 1 robot, bridged; its camera feeds the camera chain."""

    name: ClassVar[str] = "ros1"
    Options: ClassVar[type[BaseModel]] = Ros1Config
    options: Ros1Config

    def connect(self, ctx: ManagedContext) -> BridgeProcess:
        """Start the bridge process on the launch's zenoh bus; wait until it is ready."""
        endpoints = [on_loopback(e) for e in getattr(ctx.bus, "endpoints", ())]
        if getattr(ctx.bus, "kind", None) != "zenoh" or not endpoints:
            raise ModelFileError(
                "a ros1 managed system needs the zenoh bus (the bridge is another process)",
                element="bus",
                hint="write bus: {kind: zenoh} in the launch file",
            )
        return self._start_bridge(endpoints[0], ctx.say)

    def describe(self, ctx: ManagedContext) -> str:
        """``ROS 1 robot through BRIDGE (master URI)``."""
        return f"ROS 1 robot through {self.options.bridge} (master {self._env()['ROS_MASTER_URI']})"

    def _env(self) -> dict[str, str]:
        env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        env.setdefault("ROS_MASTER_URI", "http://localhost:11311")
        if self.options.master_uri:
            env["ROS_MASTER_URI"] = self.options.master_uri
        if self.options.ros_ip:
            env["ROS_IP"] = self.options.ros_ip
        env["PYTHONUNBUFFERED"] = "1"
        return env

    def _start_bridge(self, endpoint: str, say: Callable[[str], None]) -> BridgeProcess:
        args = [sys.executable, "-m", "anunnaki.ros1", self.options.bridge, "--connect", endpoint]
        return start_bridge(args, self._env(), "ros1", self.options.ready_timeout, say)
