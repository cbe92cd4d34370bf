"""Utu's configuration file (``anunnaki: utu/1``), validated on load.

A configuration names the goal model, binding and tactics (paths relative to the config
file), the knowledge database, the bus, the clock and the policies of the MAPE-K loop::

    anunnaki: utu/1
    name: rover
    goal_model: goals.yaml
    binding: binding.yaml
    tactics: tactics.xml
    knowledge: rover-run.db        # ":memory:" for throw-away runs
    clock: wall                    # or "sim": time from the simulator's /clock topic
    bus: {kind: inproc}            # or {kind: zenoh, ...}: see docs/bus.md
    rate: 20                       # Hz: how often time-driven checks run in spin()
    dwell: 0.0                     # s a precondition must hold before its tactic is queued
    warmup: 2.0                    # s at start when unknown goals trigger nothing
    failsafe: fail-safe            # tactic to escalate to when a postcondition fails
    run_stop: {service: /rover/stop}
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from anunnaki import topics
from anunnaki._safeyaml import LineMap, load_yaml, validation_error
from anunnaki.errors import ModelFileError
from anunnaki.tokens import service_operator_token

__all__ = ["RunStopConfig", "UtuConfig", "load_config", "parse_config"]

log = logging.getLogger("anunnaki.utu")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class RunStopConfig(_Strict):
    """What a run-stop does to the managed system (guideline S4)."""

    service: str | None = None
    topic: str | None = None
    payload: dict[str, Any] = Field(default_factory=lambda: {"reason": "run-stop"})
    timeout: Annotated[float, Field(gt=0)] = 2.0


class UtuConfig(_Strict):
    """A Utu configuration file."""

    anunnaki: Literal["utu/1"]
    name: str = "utu"
    goal_model: str
    binding: str | None = None
    tactics: str | None = None
    knowledge: str = ":memory:"
    clock: Literal["wall", "sim"] = "wall"
    clock_topic: str = topics.CLOCK
    bus: dict[str, Any] = Field(default_factory=lambda: {"kind": "inproc"})
    rate: Annotated[float, Field(gt=0, le=10_000)] = 20.0
    dwell: Annotated[float, Field(ge=0)] = 0.0
    warmup: Annotated[float, Field(ge=0)] = 2.0
    failsafe: str | None = None
    escalate_to_run_stop: bool = True
    run_stop: RunStopConfig = Field(default_factory=RunStopConfig)
    queue: Annotated[int, Field(ge=1, le=1_000_000)] = 1024
    #: Messages a step takes from each monitored topic at most (at most ``queue``); under a
    #: flood the rest waits in the topic's queue (beyond it the oldest are dropped and
    #: counted). Lower keeps steps shorter under a flood, but a backlog taken by a later
    #: step is stamped no earlier than that step's predecessor, so rates read from it
    #: compress (docs/utu.md).
    intake: Annotated[int, Field(ge=1, le=1_000_000)] = 1024
    #: Seconds ahead of Utu's time beyond which a ``/clock`` or a monitor batch is refused.
    max_time_jump: Annotated[float, Field(gt=0)] | None = 60.0
    notify: dict[str, Any] = Field(default_factory=dict)
    publish_state: bool = True
    #: Seconds a live loop may go without finishing a step before its watchdog run-stops
    #: the platform (``None``: no watchdog).
    watchdog: Annotated[float, Field(gt=0)] | None = 3.0
    #: Seconds a live loop on the wall clock waits for a request's reply before going on
    #: with the request in flight (its outcome is taken by a later cycle). On sim time, or
    #: stepped by hand, it waits up to the action's timeout, so a run repeats itself.
    action_settle: Annotated[float, Field(ge=0, le=5)] = 0.05
    #: Folders a hot reload may read from, besides those of goal_model, binding and tactics.
    reload_dirs: list[str] = Field(default_factory=list)
    #: A file holding the operator token (``$ANUNNAKI_OPERATOR_TOKEN`` takes precedence).
    operator_token_file: str | None = None
    #: Who chooses the tactics (``anunnaki run --manager``): ``utu`` (the planner),
    #: ``none`` (nothing is started: no adaptation) or ``random`` (a baseline: whenever
    #: the planner would start tactics, one drawn uniformly among those it could start,
    #: seeded by ``manager_seed``; docs/whole-loop.md "Managers compared").
    manager: Literal["utu", "none", "random"] = "utu"
    manager_seed: Annotated[int, Field(ge=0)] = 0

    def operator_token(self) -> str:
        """The token pause, resume, approve and reload requests must carry.

        ``$ANUNNAKI_OPERATOR_TOKEN``, else ``operator_token_file``, else the user's own token
        file (:func:`anunnaki.tokens.user_operator_token`: written first if missing, and
        logged where), so the operator services are never open by accident.

        Raises:
            ModelFileError: The token file is unreadable or the token too weak.

        """
        return service_operator_token("utu", file=self.operator_token_file)

    def reload_roots(self) -> list[Path]:
        """The folders a hot reload may read files from (symlinks resolved)."""
        named = [self.goal_model, self.binding, self.tactics]
        roots = [Path(p).resolve().parent for p in named if p] + [
            Path(d).resolve() for d in self.reload_dirs
        ]
        return list(dict.fromkeys(roots))

    def resolve(self, base: Path) -> UtuConfig:
        """Return a copy with file paths made absolute against ``base``."""

        def fix(p: str | None) -> str | None:
            if p is None or p == ":memory:":
                return p
            path = Path(p)
            return str(path if path.is_absolute() else (base / path))

        return self.model_copy(
            update={
                "goal_model": fix(self.goal_model),
                "binding": fix(self.binding),
                "tactics": fix(self.tactics),
                "knowledge": fix(self.knowledge),
                "reload_dirs": [str(fix(d)) for d in self.reload_dirs],
                "operator_token_file": fix(self.operator_token_file),
            }
        )


def _parse(data: Any, lines: LineMap | None, path: str) -> UtuConfig:
    if not isinstance(data, dict) or data.get("anunnaki") != "utu/1":
        raise ModelFileError(
            "not a Utu configuration",
            path=path,
            line=1,
            hint="start the file with 'anunnaki: utu/1'",
        )
    try:
        return UtuConfig.model_validate(data)
    except ValidationError as exc:
        raise validation_error(exc, data, lines, path) from None


def parse_config(text: str, *, source: str = "<config>", base: Path | None = None) -> UtuConfig:
    """Parse a configuration from YAML text; paths resolve against ``base`` (default: cwd)."""
    data, lines = load_yaml(source, text=text)
    return _parse(data, lines, source).resolve(base or Path.cwd())


def load_config(path: str | Path) -> UtuConfig:
    """Load a configuration file; its paths resolve against the file's folder."""
    data, lines = load_yaml(path)
    return _parse(data, lines, str(path)).resolve(Path(path).resolve().parent)
