"""A real robot as a managed system: what the ``ros1`` and ``ros2`` kinds share.

A robot kind differs from another only in how it reaches the robot — a :class:`Link`: the
ROS 1 bridge process (``ros1``), a zenoh session with the ROS 2 bridge (``ros2``). The
rest is written once here: the options (a bridge file and the camera chain), the bring-up
checks, the notes on clocks and speeds, the start (link first, then the camera chain on
the bridged camera, both closed if either fails) and the run (it ends with the launch, at
``until`` wall seconds, or when the link is gone).
"""

from __future__ import annotations

import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Sequence
from pathlib import Path
from typing import Any, ClassVar, Protocol

from pydantic import BaseModel, ConfigDict

from anunnaki.managed._camera import CameraChain, check_camera_chain
from anunnaki.managed._slot import DecisionLike, ManagedContext, UtuSettings

__all__ = ["Link", "RobotConfig", "RobotKind", "RobotRun"]


class RobotConfig(BaseModel):
    """A bridge file and the camera chain on the bridged camera (``ros1``, ``ros2``).

    Attributes:
        bridge: The bridge file (``anunnaki: ros1-bridge/1``), relative to the launch file.
        models: A model registry: run the LEC node on ``camera`` (the bridged frames).
        camera: The bus topic the bridge puts the camera's frames on.
        oracle: An oracle node on ``camera``: ``name`` (e.g. ``light``) and its options.
        scorer: A second oracle beside it as its live scorer (same form), on
            ``/sim/oracle/scorer``, which Utu does not read.

    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    bridge: str
    models: str | None = None
    camera: str = "/rover/camera/image"
    oracle: dict[str, Any] | None = None
    scorer: dict[str, Any] | None = None


class Link(Protocol):
    """How a robot kind reaches its robot, once started (a bridge process, a session)."""

    #: Why the run ended when the link went by itself, e.g. ``the bridge process exited``.
    gone: str

    def alive(self) -> bool:
        """Whether the robot is still reachable (polled about every 0.1 s)."""
        ...

    def close(self) -> None:
        """Stop and release it (idempotent)."""
        ...


class RobotRun:
    """A started robot: its link, the camera chain beside it, a thread that watches both."""

    def __init__(self, link: Link, chain: CameraChain, ctx: ManagedContext, name: str) -> None:
        self.link = link
        self.chain = chain
        self.ended = "stopped"
        self._ctx = ctx
        self.thread = threading.Thread(target=self._watch, name=f"anunnaki-{name}", daemon=True)
        self.thread.start()

    def _watch(self) -> None:
        """End with the launch, at ``until`` (wall seconds), or when the link is gone."""
        started = time.monotonic()
        until = self._ctx.until
        while not self._ctx.stop.wait(0.1):
            if not self.link.alive():
                self.ended = self.link.gone
                return
            if until is not None and time.monotonic() - started >= until:
                self.ended = f"ran {until:g} s"
                return

    def finish(self, decisions: Sequence[DecisionLike], ran: float) -> None:
        """Nothing to report: a robot's run is in Utu's log."""
        return None

    def close(self) -> None:
        """Close the camera chain, then the link."""
        self.chain.close()
        self.link.close()


class RobotKind(ABC):
    """The start, checks and notes of a robot kind; a subclass says how to reach the robot.

    A subclass sets ``name`` and ``Options`` (a :class:`RobotConfig`) and defines
    :meth:`connect` and :meth:`describe`.
    """

    name: ClassVar[str]
    speed = 1.0
    options: RobotConfig

    def __init__(self, options: BaseModel, *, base: Path) -> None:
        assert isinstance(options, RobotConfig)

        def here(p: str) -> str:
            return str(p if Path(p).is_absolute() else base / p)

        self.options = options.model_copy(
            update={
                "bridge": here(options.bridge),
                "models": None if options.models is None else here(options.models),
            }
        )

    @abstractmethod
    def connect(self, ctx: ManagedContext) -> Link:
        """Reach the robot from the launch's bus (raise a ModelFileError with the fix)."""

    @abstractmethod
    def describe(self, ctx: ManagedContext) -> str:
        """How the robot is reached, for the start line (``ROS 1 robot through …``)."""

    def model_registry(self) -> str | None:
        """The detector's model registry (:class:`~anunnaki.managed.ServesModels` hook)."""
        return self.options.models

    def check(self, utu: UtuSettings) -> None:
        """Load the bridge file, the registry and the oracles' names now (B5)."""
        from anunnaki.rosbridge import load_bridge

        o = self.options
        load_bridge(o.bridge)
        check_camera_chain(models=o.models, oracle=o.oracle, scorer=o.scorer)

    def notes(self, utu: UtuSettings, speed: float) -> list[str]:
        """A robot runs in real time: a simulation clock or a speed does not apply."""
        out = []
        if utu.clock == "sim":
            out.append("note: clock: sim with a ROS robot: nothing publishes /clock; use wall")
        if speed != 1:
            out.append(f"note: speed {speed:g}× does not apply to a ROS robot (real time)")
        return out

    def start(self, ctx: ManagedContext) -> RobotRun:
        """Reach the robot, then start the camera chain on the bridged camera."""
        o = self.options
        link = self.connect(ctx)
        try:
            chain = CameraChain(
                ctx.bus, camera=o.camera, models=o.models, oracle=o.oracle, scorer=o.scorer
            )
        except BaseException:
            link.close()
            raise
        ctx.say(f"managed: {self.describe(ctx)}; {chain.describe()}")
        return RobotRun(link, chain, ctx, self.name)
