"""Helpers of the benchmarks' quick-mode tests: run a script of ``benchmarks/``, read its JSON."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
BENCH = ROOT / "benchmarks"


def run(script: str, *args: str, timeout: float = 240) -> None:
    """Run ``benchmarks/<script>`` with ``args`` from the repository's root; it must succeed."""
    result = subprocess.run(
        [sys.executable, str(BENCH / script), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
        cwd=ROOT,
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-4000:]


def load(path: Path) -> Any:
    """The JSON document a benchmark wrote."""
    return json.loads(path.read_text(encoding="utf-8"))


def script_module(script: str, name: str) -> ModuleType:
    """``benchmarks/<script>`` imported as module *name* (registered in ``sys.modules``:
    dataclasses look their module up), so a test can call its functions."""
    spec = importlib.util.spec_from_file_location(name, BENCH / script)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def check_after_degraded(phase: dict[str, Any]) -> None:
    """A phase of case_studies.py's ``onset_delays`` that was adapted to: its delay after the
    ground truth first found the active model degraded in it (the onset's ramp may leave the
    model in use fine for a while) is measured from that frame, 0 when the action came first.
    """
    assert phase["delay_s"] is not None, phase
    hurt, acted = phase["degraded_at"], phase["onset"] + phase["delay_s"]
    assert hurt is None or hurt >= phase["onset"], phase
    assert 0.0 <= phase["after_degraded_s"] <= phase["delay_s"], phase
    expected = 0.0 if hurt is None or hurt > acted else acted - hurt
    assert abs(phase["after_degraded_s"] - expected) <= 0.002, phase


def check_repeats(tmp_path: Path, case: str, until: float) -> None:
    """benchmarks/determinism.py's two runs of ``case`` to ``until`` (the second beside a busy
    process) and ``anunnaki replay`` of the first: the same report and decision log."""
    out = tmp_path / "determinism.json"
    args = ["--cases", case, "--runs", "2", "--until", str(until), "--output", str(out)]
    run("determinism.py", *args, timeout=560)
    doc = load(out)
    assert set(doc["cases"]) == {case}
    c = doc["cases"][case]
    assert c["until"] == until and [r["beside_busy"] for r in c["runs"]] == [False, True]
    quiet, loaded = c["runs"]
    assert abs(quiet["simulated_s"] - until) <= 0.2, quiet
    assert quiet["decisions"] > 0, "the stretch should decide something"
    assert loaded["log_sha256"] == quiet["log_sha256"]  # the same decisions at the same times
    assert loaded["report_sha256"] == quiet["report_sha256"]  # the same report, byte for byte
    assert c["identical_reports"] is True and c["identical_logs"] is True
    assert c["replay_exit_code"] == 0, c["replay"]  # `anunnaki replay` of the run
