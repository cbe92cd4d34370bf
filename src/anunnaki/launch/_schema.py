"""Launch files (``anunnaki: launch/1``): run Utu's nodes and a managed system, like ROS launch.

A launch file says which Utu configuration to run, which of its five nodes, on which bus,
at which rates, and optionally a scripted managed system to run them against::

    anunnaki: launch/1
    name: rover
    utu: utu-config.yaml          # a Utu configuration file, or the same fields inline
    knowledge: run.db             # overrides the Utu configuration's knowledge base
    bus: {kind: zenoh}            # BusConfig fields (see docs/bus.md); overrides utu's bus
    nodes:                        # a list of names, or name -> {rate: Hz}
      monitor: {rate: 50}
      analyze: {rate: 20}
      plan: {rate: 20}
      execute: {rate: 20}
      knowledge: {rate: 10}
    managed:                      # the system Utu adapts: a plugin named by kind
      kind: scripted              # scripted | sim | a third party's (entry points)
      trace: trace.jsonl
      speed: 1.0

Paths are relative to the launch file. :func:`load_launch` validates everything a node
needs at bring-up (guideline B5): the launch file itself, the Utu configuration, the bus,
``notify``, the managed system's files (trace, scenario, model registry, oracle names), the
goal model, binding and tactics, the tactics' model swaps; every error names file and line.
``anunnaki check`` walks the same steps (:func:`~anunnaki.launch.check_launch`).

:func:`~anunnaki.launch.run_launch` starts the nodes in this process (the composed
:class:`~anunnaki.utu.AutonomicManager` when all five run) or one process per node
(``python -m anunnaki.cli.main node NAME``), waits until every node answers its readiness
service (C9), then starts the managed system, prints one line per decision, and shuts
everything down on a signal, at ``until`` or when the trace ends. See docs/running.md.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from anunnaki._findings import Finding
from anunnaki._safeyaml import LineMap, describe_path, load_yaml, validation_error
from anunnaki.bus import BusConfig
from anunnaki.check import ModelCatalogue, check_swaps
from anunnaki.errors import AnunnakiError, ModelFileError
from anunnaki.launch._managed import resolve_kind, split_managed
from anunnaki.managed import MANAGED, ManagedKind, ServesModels
from anunnaki.utu import (
    NODE_NAMES,
    NodeName,
    NotifyConfig,
    UtuConfig,
    UtuParts,
    load_config,
    load_parts,
)

__all__ = ["Launch", "LaunchConfig", "LaunchError", "NodeSettings", "load_launch", "parse_launch"]


class LaunchError(AnunnakiError):
    """A launch could not be brought up (a node failed to start or to become ready)."""


class _StoppedDuringBringUp(LaunchError):
    """A signal arrived before every node was ready."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class NodeSettings(_Strict):
    """Settings of one node.

    Attributes:
        rate: At most this many cycles per second (C5, B2); default the Utu ``rate``.

    """

    rate: Annotated[float, Field(gt=0, le=10_000)] | None = None


class LaunchConfig(_Strict):
    """A launch file (``anunnaki: launch/1``); see the module docstring."""

    anunnaki: Literal["launch/1"]
    name: str | None = None
    utu: str | dict[str, Any]
    knowledge: str | None = None
    bus: BusConfig | None = None
    nodes: dict[NodeName, NodeSettings | None] = Field(
        default_factory=lambda: dict.fromkeys(NODE_NAMES)
    )
    managed: dict[str, Any] | None = None
    ready_timeout: Annotated[float, Field(gt=0)] = 30.0
    stop_timeout: Annotated[float, Field(gt=0)] = 10.0
    linger: Annotated[float, Field(ge=0)] = 0.5
    assurance: str | bool | None = None

    @field_validator("nodes", mode="before")
    @classmethod
    def _node_list(cls, nodes: Any) -> Any:
        """Take ``[monitor, analyze]`` as ``{monitor: null, analyze: null}``."""
        if isinstance(nodes, list):
            names = [n for n in nodes if isinstance(n, str)]
            repeated = sorted({n for n in names if names.count(n) > 1})
            if repeated:
                raise ValueError(f"nodes named twice: {', '.join(repeated)}")
            if len(names) != len(nodes):
                raise ValueError(f"give node names ({', '.join(NODE_NAMES)})")
            return dict.fromkeys(names)
        return nodes

    @field_validator("nodes")
    @classmethod
    def _some_nodes(
        cls, nodes: dict[NodeName, NodeSettings | None]
    ) -> dict[NodeName, NodeSettings | None]:
        if not nodes:
            raise ValueError(f"name at least one node ({', '.join(NODE_NAMES)})")
        return nodes


@dataclass(frozen=True)
class Launch:
    """A launch file loaded, resolved and checked.

    Attributes:
        config: The file's content.
        path: The launch file (``None`` for text given in memory).
        utu: The Utu configuration (paths absolute, knowledge override applied).
        parts: Its goal model, binding and tactics, loaded and checked.
        bus: The bus configuration.
        nodes: The nodes to run -> rate (Hz).
        managed: The managed system (a plugin of :data:`MANAGED`, paths resolved and
            checked), or ``None`` when the robot is real.
        lines: Where each element of the launch file starts.

    """

    config: LaunchConfig
    path: Path | None
    utu: UtuConfig
    parts: UtuParts
    bus: BusConfig
    nodes: dict[str, float]
    managed: ManagedKind | None = None
    lines: LineMap | None = None

    @property
    def name(self) -> str:
        """The launch's name (default: the Utu configuration's)."""
        return self.config.name or self.utu.name

    def line_of(self, *path: str | int) -> int | None:
        """The line where the element at ``path`` starts in the launch file."""
        return self.lines.line(path) if self.lines is not None else None

    def error(self, message: str, *path: str | int, hint: str | None = None) -> ModelFileError:
        """A :class:`ModelFileError` located at an element of the launch file."""
        return ModelFileError(
            message,
            path=self.path,
            line=self.line_of(*path),
            element=".".join(str(p) for p in path) or None,
            hint=hint,
        )


class _Prefixed:
    """A pydantic ValidationError seen from an enclosing document (``loc`` prefixed)."""

    def __init__(self, exc: ValidationError, prefix: tuple[str | int, ...]) -> None:
        self._exc = exc
        self._prefix = prefix

    def errors(self, include_url: bool = False) -> list[Any]:
        return [
            {**e, "loc": (*self._prefix, *(p for p in e["loc"] if p != "[key]"))}
            for e in self._exc.errors(include_url=include_url)
        ]


def load_launch(path: str | Path, *, read_records: bool = True) -> Launch:
    """Load a launch file (or a plain Utu configuration, run with every node).

    Args:
        path: The file (``anunnaki: launch/1`` or ``anunnaki: utu/1``).
        read_records: Check the managed system too (read its trace, load its scenario and
            models); node processes, which do not run it, skip this.

    Raises:
        ModelFileError: Any file is unreadable or invalid; names file and line.

    """
    data, lines = load_yaml(path)
    return _resolve(data, lines, Path(path), read_records=read_records)


def parse_launch(
    text: str, *, source: str = "<launch>", base: Path | None = None, read_records: bool = True
) -> Launch:
    """Parse a launch file from text; paths resolve against ``base`` (default: cwd).

    Args:
        text: The launch file's text (``anunnaki: launch/1``).
        source: What errors name as the file (e.g. the file the text came from).
        base: The folder relative paths in the text resolve against (default: cwd).
        read_records: As for :func:`load_launch`.

    Raises:
        ModelFileError: The text or a file it names is invalid; names ``source`` (or that
            file) and the line.

    """
    data, lines = load_yaml(source, text=text)
    tag = data.get("anunnaki") if isinstance(data, dict) else None
    if tag == "utu/1":  # a Utu configuration names no file of its own to run
        raise ModelFileError(
            "a Utu configuration (utu/1) given as text",
            path=source,
            line=lines.line(("anunnaki",)),
            element="anunnaki",
            hint="load it from its file with load_launch, or write a launch file "
            "('anunnaki: launch/1') with the configuration inline under 'utu:'",
        )
    launch = _resolve(
        data, lines, (base or Path.cwd()) / "<launch>", read_records=read_records, where=source
    )
    return dataclasses.replace(launch, path=None)


def _resolve(
    data: Any, lines: LineMap, path: Path, *, read_records: bool, where: str | None = None
) -> Launch:
    """The launch read from ``path`` (or text named ``where``), checked and resolved."""
    return _Loader(data, lines, path, read_records=read_records, where=where).load()


class _Loader:
    """Loading a launch, step by step: what ``run`` loads is what ``check`` checks.

    A run stops at the first problem (:meth:`fail` raises it); ``anunnaki check`` uses a
    subclass (``anunnaki.launch._check``) that records it and goes on with the steps that
    do not depend on the one that failed, and lists every finding of the goal model,
    binding and tactics before they are loaded here as a run loads them (:meth:`review`).
    Nothing here starts anything: no bus, no simulator, no weights.
    """

    def __init__(
        self, data: Any, lines: LineMap, path: Path, *, read_records: bool, where: str | None
    ) -> None:
        self.data = data
        self.lines = lines
        self.path = path
        self.read_records = read_records
        self.where = str(path) if where is None else where

    def fail(self, exc: ModelFileError) -> None:
        """A step found a problem: a run stops here."""
        raise exc

    def found(self, findings: list[Finding]) -> None:
        """A step's findings: a run stops at the first error (it prints warnings at start)."""
        errors = [f for f in findings if f.severity == "error"]
        if errors:
            raise errors[0].to_error()

    def review(self, utu: UtuConfig, src: _Source, managed: ManagedKind | None) -> UtuConfig:
        """Before the goal model, binding and tactics load (a run: nothing to do)."""
        return utu

    def parts(self, utu: UtuConfig, src: _Source) -> UtuParts:
        """The goal model, binding and tactics, loaded and checked as every node loads them."""
        return _parts_of(utu, src)

    def _step(self, step: Callable[[], object]) -> bool:
        """Run a step; whether it passed (a run: it raised otherwise)."""
        try:
            step()
        except ModelFileError as exc:
            self.fail(exc)
            return False
        return True

    def load(self) -> Launch:
        """Every step, in order; the loaded launch."""
        data, lines, path, where = self.data, self.lines, self.path, self.where
        tag = data.get("anunnaki") if isinstance(data, dict) else None
        if tag == "utu/1":
            data = {"anunnaki": "launch/1", "utu": str(path.resolve())}
            lines = LineMap()
        elif tag != "launch/1":
            raise ModelFileError(
                "not a launch file",
                path=where,
                line=1,
                hint="start it with 'anunnaki: launch/1' (or give a Utu configuration, utu/1)",
            )
        try:
            config = LaunchConfig.model_validate(data)
        except ValidationError as exc:
            raise validation_error(_Prefixed(exc, ()), data, lines, where) from None
        base = path.resolve().parent
        launch_src = _Source(data, lines, where, ())
        utu, src = _utu_of(config, launch_src, base)
        if config.knowledge is not None:
            kb = config.knowledge
            utu = utu.model_copy(
                update={"knowledge": kb if kb == ":memory:" else str(_here(base, kb))}
            )
        bus = _bus_of(config, utu, src)
        _check_notify(utu, src)
        # Nodes and rates.
        rates: dict[str, float] = {
            n: (s.rate if s is not None and s.rate is not None else utu.rate)
            for n, s in config.nodes.items()
        }
        nodes: dict[str, float] = {n: rates[n] for n in NODE_NAMES if n in rates}  # cycle order
        managed = _managed(config.managed, data, lines, where, base)
        utu = self.review(utu, src, managed)
        # The managed system's own files (scenario, registry, oracles), then the goal model,
        # binding and tactics, then the tactics' model swaps against the registry.
        checked = (
            managed is not None
            and self.read_records
            and self._step(lambda: _check_managed(managed, utu, launch_src))
        )
        parts = self.parts(utu, src)
        if managed is not None and checked:
            swaps = _swap_findings(managed, parts)
            self.found(swaps)
            parts = dataclasses.replace(parts, warnings=[*parts.warnings, *swaps])
        return Launch(config, path, utu, parts, bus, nodes, managed, lines)


@dataclass(frozen=True)
class _Source:
    """Where a configuration was read: its data, lines, file and path prefix within it."""

    data: Any
    lines: LineMap | None
    where: str
    prefix: tuple[str | int, ...]


def _here(base: Path, p: str) -> Path:
    """``p`` relative to the launch file's folder (``~`` expanded)."""
    q = Path(p).expanduser()
    return q if q.is_absolute() else base / q


def _utu_of(config: LaunchConfig, launch: _Source, base: Path) -> tuple[UtuConfig, _Source]:
    """The Utu configuration (a file, or inline) and where it was read."""
    if isinstance(config.utu, str):
        utu_path = _here(base, config.utu)
        utu = load_config(utu_path)
        utu_data, utu_lines = load_yaml(utu_path)
        return utu, _Source(utu_data, utu_lines, str(utu_path), ())
    inline = {**config.utu, "anunnaki": "utu/1"}
    try:
        utu = UtuConfig.model_validate(inline).resolve(base)
    except ValidationError as exc:
        raise validation_error(
            _Prefixed(exc, ("utu",)), launch.data, launch.lines, launch.where
        ) from None
    return utu, dataclasses.replace(launch, prefix=("utu",))


def _bus_of(config: LaunchConfig, utu: UtuConfig, src: _Source) -> BusConfig:
    """The bus: the launch file's, else the Utu configuration's."""
    if config.bus is not None:
        return config.bus
    try:
        return BusConfig.model_validate(utu.bus)
    except ValidationError as exc:
        raise validation_error(
            _Prefixed(exc, (*src.prefix, "bus")), src.data, src.lines, src.where
        ) from None


def _check_notify(utu: UtuConfig, src: _Source) -> None:
    """The ``notify:`` section, as the notifier reads it at start (e-mail, webhooks, log)."""
    if not utu.notify:
        return
    try:
        NotifyConfig.model_validate(utu.notify)
    except ValidationError as exc:
        raise validation_error(
            _Prefixed(exc, (*src.prefix, "notify")), src.data, src.lines, src.where
        ) from None


def _parts_of(utu: UtuConfig, src: _Source) -> UtuParts:
    """The goal model, binding and tactics (B5: fail here, with file and line)."""
    try:
        return load_parts(utu)
    except ModelFileError as exc:
        if exc.element != "failsafe":
            raise
        raise _at_failsafe(exc.message, exc.hint, src) from None


def _at_failsafe(message: str, hint: str | None, src: _Source) -> ModelFileError:
    """A problem with the fail-safe, located at ``failsafe`` in the Utu configuration."""
    real, element = describe_path(src.data, (*src.prefix, "failsafe"))
    return ModelFileError(
        message,
        path=src.where,
        line=src.lines.line(real) if src.lines is not None else None,
        element=element,
        hint=hint,
    )


def _swap_findings(managed: ManagedKind, parts: UtuParts) -> list[Finding]:
    """The tactics' ``swap_model`` actions the managed system's model manager would refuse.

    Warnings (:func:`~anunnaki.check.check_swaps`): a run prints them at start.
    """
    if not isinstance(managed, ServesModels):
        return []
    registry_file = managed.model_registry()
    if registry_file is None:
        return []
    from anunnaki.lec import load_registry

    registry = load_registry(registry_file)
    where = os.path.normpath(registry_file)
    models = ModelCatalogue(registry.lec, tuple(registry.ids()), tuple(registry.domains()), where)
    t = parts.sources.get("tactics")
    return check_swaps(parts.model, parts.tactics, t[0] if t else None, models)


def _check_managed(managed: ManagedKind, utu: UtuConfig, launch: _Source) -> None:
    """Let the managed system check what it needs; its errors name the launch file's element."""
    try:
        managed.check(utu)
    except ModelFileError as exc:
        if exc.path is not None:
            raise
        # The plugin's problem is with an element of the launch file: say where it is.
        element = exc.element or "managed"
        real, _ = describe_path(launch.data, tuple(element.split(".")))
        raise ModelFileError(
            exc.message,
            path=launch.where,
            line=launch.lines.line(real) if launch.lines is not None else None,
            element=element,
            hint=exc.hint,
        ) from None


def _managed(
    raw: dict[str, Any] | None, data: Any, lines: LineMap, where: str, base: Path
) -> ManagedKind | None:
    """The ``managed:`` section as a plugin, its options validated with file and line."""
    try:
        name, options, prefix = split_managed(raw)
    except ValueError as exc:
        raise ModelFileError(
            str(exc), path=where, line=lines.line(("managed",)), element="managed"
        ) from None
    if name is None:
        return None
    if name not in MANAGED:
        raise ModelFileError(
            str(MANAGED.unknown(name)).split(": ", 1)[-1],
            path=where,
            line=lines.line(("managed", "kind")) or lines.line(prefix),
            element=".".join(prefix) if prefix != ("managed",) else "managed.kind",
        )
    cls = MANAGED.factory(name)
    removed: dict[str, str] = getattr(cls.Options, "removed", {})  # type: ignore[attr-defined]
    for key in options:
        if key in removed:
            raise ModelFileError(
                f"'{key}' was removed",
                path=where,
                line=lines.line((*prefix, key)),
                element=".".join((*prefix, key)),
                hint=removed[key],
            )
    try:
        validated = cls.Options.model_validate(options)  # type: ignore[attr-defined]
    except ValidationError as exc:
        raise validation_error(_Prefixed(exc, prefix), data, lines, where) from None
    return resolve_kind(name, validated, base)
