"""``anunnaki check LAUNCH``: everything ``run`` would load, checked by the code that loads it.

:func:`check_launch` walks the steps of :class:`~anunnaki.launch._schema._Loader`, the loader
``anunnaki run`` uses, so the two cannot drift: the launch file, the Utu configuration, the
bus, ``notify``, the managed system's own files (a scenario and its phenomena, a model
registry with its models' and oracles' files, the oracles' names, a trace or a bridge), the
goal model, binding and tactics, the fail-safe, and the tactics' model swaps against the
registry. Where a run stops at the first problem, the check records it and goes on with what
does not depend on it, and it lists every finding of the goal model, binding and tactics
(warnings too), with the modes the managed platform declares. It starts nothing: no bus, no
simulator, no node; no weights are loaded.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from anunnaki._findings import Finding
from anunnaki._safeyaml import LineMap, load_yaml, read_text_limited
from anunnaki.check import CheckResult, PlatformModes, check_files
from anunnaki.errors import ModelFileError
from anunnaki.launch._schema import _at_failsafe, _Loader, _Source
from anunnaki.managed import ManagedKind
from anunnaki.utu import UtuConfig, UtuParts

__all__ = ["check_launch"]


def _simulated(platform: str) -> PlatformModes:
    """The modes a simulated platform (``rover``, ``uav``) declares."""
    from anunnaki.sim import PLATFORM_MODES

    cls = {"rover": "RoverSim", "uav": "UavSim"}[platform]
    return PlatformModes(platform, PLATFORM_MODES[platform], f"anunnaki.sim.{cls}.modes")


def check_launch(
    path: str | Path,
    *,
    binding: str | Path | None = None,
    tactics: str | Path | None = None,
    modes: PlatformModes | None = None,
) -> CheckResult:
    """Check a launch file (or a Utu configuration) and everything it names, as ``run`` loads it.

    Args:
        path: The launch file (``anunnaki: launch/1``) or Utu configuration (``utu/1``).
        binding: Check this binding instead of the one the file names.
        tactics: Check this tactics file instead of the one the file names.
        modes: Check ``change_mode`` actions against these modes (default: those the
            launch's managed system declares).

    Returns:
        The findings. ``unreadable`` (exit code 2) only when ``path`` itself cannot be read;
        a problem in what it names is a finding (exit code 1), located in the file at fault.

    """
    result = CheckResult()
    try:
        read_text_limited(path)
    except ModelFileError as exc:
        result.findings.append(Finding.from_error(exc))
        result.unreadable = True
        return result
    try:
        data, lines = load_yaml(path)
        check = _Check(
            data, lines, Path(path), result, binding=binding, tactics=tactics, modes=modes
        )
        launch = check.load()
    except ModelFileError as exc:  # a step nothing after it can go without
        _record(result, Finding.from_error(exc))
        return result
    except _Stop:
        return result
    managed = launch.managed
    result.checked.append(
        f"launch {launch.name!r}"
        + (f" with its managed system ({managed.name})" if managed is not None else "")
    )
    return result


def _record(result: CheckResult, finding: Finding) -> None:
    """Add a finding once (the run's loader may meet one that the review listed)."""
    if finding not in result.findings:
        result.findings.append(finding)


class _Stop(Exception):
    """The check cannot go on: what stops it is among the findings."""


class _Check(_Loader):
    """The loader of a run, recording what a run would stop at instead of stopping."""

    def __init__(
        self,
        data: Any,
        lines: LineMap,
        path: Path,
        result: CheckResult,
        *,
        binding: str | Path | None,
        tactics: str | Path | None,
        modes: PlatformModes | None,
    ) -> None:
        super().__init__(data, lines, path, read_records=True, where=None)
        self.result = result
        self._binding = binding
        self._tactics = tactics
        self._modes = modes
        self._reviewed = False

    def fail(self, exc: ModelFileError) -> None:
        """Record the problem; the steps that do not depend on it go on."""
        _record(self.result, Finding.from_error(exc))

    def found(self, findings: list[Finding]) -> None:
        """Record every finding."""
        for f in findings:
            _record(self.result, f)

    def review(self, utu: UtuConfig, src: _Source, managed: ManagedKind | None) -> UtuConfig:
        """List every finding of the goal model, binding and tactics (a run stops at one)."""
        update = {
            key: str(Path(value).resolve())
            for key, value in (("binding", self._binding), ("tactics", self._tactics))
            if value is not None
        }
        if update:
            utu = utu.model_copy(update=update)
        modes = self._modes
        if modes is None and managed is not None:
            modes = _managed_modes(managed, self.where)
        files = check_files(
            utu.goal_model,
            binding=utu.binding,
            tactics=utu.tactics,
            modes=modes,
            failsafe=utu.failsafe,
        )
        self.result.model, self.result.tactics = files.model, files.tactics
        for f in files.findings:
            if f.element == "failsafe":  # the Utu configuration names it: say where
                _record(self.result, Finding.from_error(_at_failsafe(f.message, f.hint, src)))
            else:
                _record(self.result, f)
        self._reviewed = not any(f.severity == "error" for f in files.findings)
        return utu

    def parts(self, utu: UtuConfig, src: _Source) -> UtuParts:
        """Load them as a run does; after errors in the review, its first one is among them."""
        try:
            return super().parts(utu, src)
        except ModelFileError as exc:
            if self._reviewed:  # a run refuses what the review passed: say so, too
                self.fail(exc)
            raise _Stop from None


def _managed_modes(managed: ManagedKind, launch: str) -> PlatformModes | None:
    """The modes a launch's managed system declares: a simulated platform's, or its option."""
    options = getattr(managed, "options", None)
    scenario = getattr(options, "scenario", None)
    if managed.name == "sim" and scenario is not None:
        from anunnaki.sim import load_scenario

        try:
            return _simulated(load_scenario(scenario).platform)
        except (ModelFileError, KeyError):
            return None  # the managed system's check reports the scenario
    declared = getattr(options, "modes", None)
    if declared:
        return PlatformModes(
            managed.name, tuple(declared), f"{launch}: managed.{managed.name}.modes"
        )
    return None
