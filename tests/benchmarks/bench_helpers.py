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
