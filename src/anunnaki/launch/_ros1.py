"""The managed-system kind ``ros1``: a ROS 1 robot through the bridge process.

A launch file names it like the others::

    managed:
      kind: ros1
      bridge: ros1/bridge.yaml          # which ROS topics and services meet the bus
      master_uri: http://127.0.0.1:11311  # default: $ROS_MASTER_URI
      models: ../models/rover.yaml      # optional: run the LEC node on the bridged camera
      oracle: {name: light}             # optional: an oracle node on the same camera

Starting it starts ``python -m anunnaki.ros1 BRIDGE --connect <the launch's zenoh
endpoint>`` (rospy lives in that process only), waits for it to say it is ready, and runs
the LEC and oracle nodes in the launch's process on the bridged camera. The run ends when
the launch stops it, or when the bridge process exits. The launch's bus must be zenoh (the
bridge is another process).
"""

from __future__ import annotations

import logging
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Annotated, Any, ClassVar

from pydantic import BaseModel, ConfigDict, Field

from anunnaki.bus import on_loopback
from anunnaki.errors import AnunnakiError, ModelFileError
from anunnaki.launch._managed import ManagedContext
from anunnaki.utu import Decision, UtuConfig

__all__ = [
    "RobotKind",
    "Ros1Config",
    "Ros1Kind",
    "check_camera_nodes",
    "start_camera_nodes",
]

log = logging.getLogger("anunnaki.launch")


class _CameraNodes(BaseModel):
    """A bridge file and the nodes a robot kind runs on the bridged camera (ros1, ros2)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    bridge: str
    models: str | None = None
    camera: str = "/rover/camera/image"
    oracle: dict[str, Any] | None = None


def check_camera_nodes(options: _CameraNodes) -> None:
    """Load the registry and check the oracle's name now (B5)."""
    if options.models is not None:
        from anunnaki.lec import load_registry

        load_registry(options.models)
    if options.oracle is not None:
        from anunnaki.oracles import ORACLES

        name = options.oracle.get("name")
        if name not in ORACLES.names():
            raise ModelFileError(
                f"unknown oracle {name!r}",
                element="managed.oracle.name",
                hint=f"known oracles: {', '.join(ORACLES.names())}",
            )


def start_camera_nodes(bus: Any, options: _CameraNodes) -> list[Any]:
    """Start the LEC node and the oracle node on the bridged camera (each if configured)."""
    nodes: list[Any] = []
    detections = None
    if options.models is not None:
        from anunnaki.lec import LecNode, load_registry

        lec = LecNode(bus, load_registry(options.models), camera=options.camera)
        nodes.append(lec)
        detections = lec.detections_topic
    if options.oracle is not None:
        from anunnaki.oracles import OracleNode

        settings: dict[str, Any] = dict(options.oracle)
        name = settings.pop("name")
        if detections:
            settings["detections"] = detections
        nodes.append(OracleNode(bus, name, camera=options.camera, **settings))
    return nodes


class RobotKind:
    """What the ``ros1`` and ``ros2`` kinds share: paths, bring-up checks, real time."""

    speed = 1.0
    relay_clock = False  # a robot lives in real time

    def __init__(self, options: BaseModel, *, base: Path) -> None:
        assert isinstance(options, _CameraNodes)

        def here(p: str) -> str:
            return str(p if Path(p).is_absolute() else base / p)

        self.options = options.model_copy(
            update={
                "bridge": here(options.bridge),
                "models": None if options.models is None else here(options.models),
            }
        )

    def check(self, utu: UtuConfig) -> None:
        """Load the bridge file, the registry and the oracle's name now (B5)."""
        from anunnaki.ros1 import load_bridge

        load_bridge(self.options.bridge)
        check_camera_nodes(self.options)

    def notes(self, utu: UtuConfig, speed: float) -> list[str]:
        """A robot runs in real time: a simulation clock or a speed does not apply."""
        out = []
        if utu.clock == "sim":
            out.append("note: clock: sim with a ROS robot: nothing publishes /clock; use wall")
        if speed != 1:
            out.append(f"note: speed {speed:g}× does not apply to a ROS robot (real time)")
        return out


class Ros1Config(_CameraNodes):
    """A ROS 1 robot through the bridge (``managed: {kind: ros1, …}``).

    Attributes:
        bridge: The bridge file (``anunnaki: ros1-bridge/1``), relative to the launch file.
        master_uri: The robot's ROS master (default ``$ROS_MASTER_URI``).
        ros_ip: This machine's address as the robot reaches it (default ``$ROS_IP``).
        models: A model registry: run the LEC node on ``camera`` (the bridged frames).
        camera: The bus topic the bridge puts the camera's frames on.
        oracle: An oracle node on ``camera``: ``name`` (e.g. ``light``) and its options.
        ready_timeout: Seconds to wait for the bridge to say it is ready.

    """

    master_uri: str | None = None
    ros_ip: str | None = None
    ready_timeout: Annotated[float, Field(gt=0, le=600)] = 60.0


class _BridgeRun:
    """The started bridge process and the nodes beside it."""

    def __init__(
        self,
        proc: subprocess.Popen[str],
        nodes: list[Any],
        stop: threading.Event | None = None,
        until: float | None = None,
    ) -> None:
        self.proc = proc
        self.nodes = nodes
        self.ended = "the bridge process exited"
        self._stop = stop or threading.Event()
        self._until = until
        self.thread = threading.Thread(target=self._watch, name="anunnaki-ros1", daemon=True)
        self.thread.start()

    def _watch(self) -> None:
        """End with the launch, at ``until`` (wall seconds), or when the bridge exits."""
        started = time.monotonic()
        while not self._stop.wait(0.1):
            if self.proc.poll() is not None:
                return
            if self._until is not None and time.monotonic() - started >= self._until:
                self.ended = f"ran {self._until:g} s"
                return

    def finish(self, decisions: Sequence[Decision], ran: float) -> None:
        return None

    def close(self) -> None:
        for node in reversed(self.nodes):
            node.close()
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.proc.stdout is not None:
            self.proc.stdout.close()


class Ros1Kind(RobotKind):
    """``kind: ros1``: a ROS 1 robot, bridged; its camera feeds the LEC and oracle nodes."""

    name: ClassVar[str] = "ros1"
    Options: ClassVar[type[BaseModel]] = Ros1Config
    options: Ros1Config

    def start(self, ctx: ManagedContext) -> _BridgeRun:
        """Start the bridge process on the launch's zenoh bus, then the LEC and oracle nodes."""
        o = self.options
        endpoints = [on_loopback(e) for e in getattr(ctx.bus, "endpoints", ())]
        if getattr(ctx.bus, "kind", None) != "zenoh" or not endpoints:
            raise ModelFileError(
                "a ros1 managed system needs the zenoh bus (the bridge is another process)",
                element="bus",
                hint="write bus: {kind: zenoh} in the launch file",
            )
        proc = self._start_bridge(endpoints[0], ctx.say)
        nodes: list[Any] = []
        try:
            nodes = start_camera_nodes(ctx.bus, o)
        except BaseException:
            _BridgeRun(proc, nodes, ctx.stop).close()
            raise
        ctx.say(
            f"managed: ROS 1 robot through {o.bridge} (master {self._env()['ROS_MASTER_URI']})"
            + (f"; detector on {o.camera}" if o.models else "")
            + (f"; oracle {o.oracle.get('name')}" if o.oracle else "")
        )
        return _BridgeRun(proc, nodes, ctx.stop, ctx.until)

    def _env(self) -> dict[str, str]:
        env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        env.setdefault("ROS_MASTER_URI", "http://localhost:11311")
        if self.options.master_uri:
            env["ROS_MASTER_URI"] = self.options.master_uri
        if self.options.ros_ip:
            env["ROS_IP"] = self.options.ros_ip
        env["PYTHONUNBUFFERED"] = "1"
        return env

    def _start_bridge(self, endpoint: str, say: Callable[[str], None]) -> subprocess.Popen[str]:
        args = [sys.executable, "-m", "anunnaki.ros1", self.options.bridge, "--connect", endpoint]
        proc = subprocess.Popen(
            args,
            env=self._env(),
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            bufsize=1,
        )
        ready = threading.Event()
        lines: list[str] = []

        def read() -> None:
            assert proc.stdout is not None
            for line in proc.stdout:
                text = line.rstrip("\n")
                lines.append(text)
                if "ros1 bridge ready" in text:
                    ready.set()
                if text.startswith(("ros1 bridge", "error", "WARNING", "ERROR")):
                    say(f"ros1: {text}")
            ready.set()  # the process ended: stop waiting

        threading.Thread(target=read, name="anunnaki-ros1-out", daemon=True).start()
        ready.wait(self.options.ready_timeout)
        if proc.poll() is not None or not any("ros1 bridge ready" in x for x in lines):
            proc.kill()
            proc.wait()
            raise AnunnakiError(
                "the ROS 1 bridge did not start: " + (" | ".join(lines[-5:]) or "no output")
            )
        return proc
