"""Shared fixtures for the managed-system tests."""

from __future__ import annotations

import io
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from anunnaki.bus import Executor, open_bus
from anunnaki.launch import load_launch, run_launch
from anunnaki.managed import SimKind


@pytest.fixture
def bus() -> Iterator[Any]:
    """An in-process bus delivered by a deterministic executor, as ``anunnaki run`` opens
    for a simulated run: the simulation's thread delivers every message (drain it by hand,
    ``b.executor.spin_until_idle()``, outside a run)."""
    with open_bus("inproc", executor=Executor()) as b:
        yield b


@dataclass(frozen=True)
class DemoRun:
    """One simulated demo run: its result, printed log and report file."""

    result: Any
    log: str
    report: Path

    @property
    def swaps(self) -> list[tuple[float, str]]:
        """``(t, domain)`` of each model swap, in order."""
        return [
            (d.t, d.data["domain"])
            for d in self.result.decisions
            if d.kind == "action" and d.data.get("type") == "swap_model"
        ]

    @property
    def verified(self) -> list[str]:
        """The tactics whose postconditions were verified."""
        return [d.tactic for d in self.result.decisions if d.kind == "postcondition_ok"]

    def started(self, tactic: str) -> bool:
        """Whether *tactic* was started."""
        return ("started", tactic) in [(d.kind, d.tactic) for d in self.result.decisions]


@pytest.fixture
def run_demo(tmp_path: Path) -> Callable[[Path], DemoRun]:
    """Run a simulated launch file at 1000 x speed with its report in *tmp_path*."""

    def run(path: Path) -> DemoRun:
        launch = load_launch(path)
        assert isinstance(launch.managed, SimKind)
        report = tmp_path / "demo.json"
        launch.managed.with_reports(report=str(report), plot=None)
        out = io.StringIO()
        result = run_launch(launch, speed=1000, out=out, handle_signals=False)
        log = out.getvalue()
        assert result.exit_code == 0, log
        return DemoRun(result, log, report)

    return run
