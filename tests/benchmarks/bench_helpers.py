"""Helpers of the benchmarks' quick-mode tests: run a script of ``benchmarks/``, read its JSON."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
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
