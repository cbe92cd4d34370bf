"""The layers of the house hold: import-linter's contracts, and no package reaches into another's
private modules (``anunnaki.<package>._<module>``); each package's ``__init__`` is its face."""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "anunnaki"


def _package_of(path: Path) -> str:
    rel = path.relative_to(SRC)
    return rel.parts[0].removesuffix(".py") if len(rel.parts) > 1 else ""


def test_no_package_imports_another_packages_private_module() -> None:
    offenders = []
    for path in sorted(SRC.rglob("*.py")):
        mine = _package_of(path)
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ImportFrom) or not node.module:
                continue
            parts = node.module.split(".")
            if parts[0] != "anunnaki" or len(parts) < 3 or parts[1] == mine:
                continue
            if any(p.startswith("_") for p in parts[2:]):
                offenders.append(f"{path.relative_to(SRC)}:{node.lineno}: from {node.module}")
    assert offenders == []


def test_import_linter_contracts_hold() -> None:
    exe = shutil.which("lint-imports", path=str(Path(sys.executable).parent))
    if exe is None:
        pytest.fail("lint-imports is missing: it is in the dev extra (scripts/setup.sh)")
    done = subprocess.run([exe], cwd=ROOT, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stdout[-3000:]
    declared = (
        (ROOT / "pyproject.toml")
        .read_text(encoding="utf-8")
        .count("[[tool.importlinter.contracts]]")
    )
    assert f"{declared} kept, 0 broken" in done.stdout
