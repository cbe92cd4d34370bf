"""A managed-system kind in one module: a toy robot closing in on a wall (docs/architecture.md).

It publishes ``/toy/status`` (``range`` to the wall in m, ``buzzer``) ``rate`` times per
second of its own time, that time on ``/clock``, and obeys ``/toy/buzzer`` (``{on}``). In one
process on sim time the run is one deterministic program (``deterministic``): the robot's
thread delivers every message of the run, draining the launch's executor after each instant
(``ctx.executor``), so Utu has acted on an instant before the robot moves on. A third party
registers it with one entry point::

    [project.entry-points."anunnaki.managed"]
    toy_robot = "toy_robot:ToyRobotKind"

and names it in a launch file: ``managed: {kind: toy_robot, approach: 0.5}`` (toy.yaml).
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any, ClassVar

from pydantic import BaseModel, ConfigDict, Field

from anunnaki.managed import ManagedContext
from anunnaki.messages import Clock, body_of


class ToyOptions(BaseModel):
    """The launch file's keys under ``managed:`` (validated with file and line)."""

    model_config = ConfigDict(extra="forbid")
    start: float = Field(3.0, gt=0)  # m to the wall at t = 0
    approach: float = Field(0.5, gt=0)  # m/s
    rate: float = Field(10.0, gt=0)  # status messages per second
    seconds: float = Field(8.0, gt=0)  # then it has arrived: the run ends


class ToyRun:
    """The running robot: a thread that drives it, a buzzer that follows Utu."""

    ended = "the toy robot arrived"

    def __init__(self, ctx: ManagedContext, options: ToyOptions) -> None:
        self.buzzer = False
        self._sub = ctx.bus.subscribe("/toy/buzzer", self._on_buzzer, queue=16)
        self.thread = threading.Thread(target=self._drive, args=(ctx, options), daemon=True)
        self.thread.start()

    def _on_buzzer(self, sample: Any) -> None:
        self.buzzer = bool(body_of(sample.message).get("on", False))

    def _drive(self, ctx: ManagedContext, o: ToyOptions) -> None:
        executor = ctx.executor
        if executor is not None:
            executor.bind()  # this thread delivers every message of the run
        try:
            self._instants(ctx, o)
        finally:
            if executor is not None:
                executor.spin_until_idle()
                executor.release()

    def _instants(self, ctx: ManagedContext, o: ToyOptions) -> None:
        wall0, k = time.monotonic(), 0
        end = o.seconds if ctx.until is None else min(o.seconds, ctx.until)
        while (t := k / o.rate) <= end:
            delay = wall0 + t / ctx.speed - time.monotonic() if ctx.speed > 0 else 0.0
            if ctx.stop.wait(max(delay, 0.0)):
                return
            ctx.bus.publish("/clock", Clock(time=t))  # Utu's time (clock: sim)
            distance = max(o.start - o.approach * t, 0.0)
            ctx.bus.publish("/toy/status", {"range": distance, "buzzer": self.buzzer})
            if ctx.executor is not None:
                ctx.executor.spin_until_idle()  # every node takes the instant first
            k += 1

    def finish(self, decisions: Any, ran: float) -> None:
        """Nothing to report."""

    def close(self) -> None:
        """Release what it declared on the bus."""
        self._sub.close()


class ToyRobotKind:
    """``kind: toy_robot`` (see :class:`anunnaki.managed.ManagedKind`)."""

    name: ClassVar[str] = "toy_robot"
    Options: ClassVar[type[BaseModel]] = ToyOptions
    deterministic = True  # in one process on sim time, it drains the run's executor
    speed = 1.0

    def __init__(self, options: BaseModel, *, base: Path) -> None:
        assert isinstance(options, ToyOptions)
        self.options = options

    def check(self, utu: Any) -> None:
        """Nothing to load."""

    def notes(self, utu: Any, speed: float) -> list[str]:
        """It keeps its own time: Utu should read it from /clock."""
        return [] if utu.clock == "sim" else ["note: the toy robot wants clock: sim"]

    def start(self, ctx: ManagedContext) -> ToyRun:
        """Drive in a thread."""
        o = self.options
        ctx.say(f"managed: toy robot {o.start:g} m from the wall at {o.approach:g} m/s")
        return ToyRun(ctx, o)
