"""The Python examples of the docs import public names that exist (issue 22, item 8).

docs/model-manager.md's example imported ``anunnaki.lec._node`` and ``anunnaki.lec._registry``
although ``anunnaki.lec`` exports both, and docs/notify.md's ``anunnaki.utu.host._notify``;
every block of every page (and the README) is parsed, and every ``from anunnaki… import`` in
it must name a public module and names that module has.
"""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted(
    str(p.relative_to(ROOT))
    for p in [ROOT / "README.md", *(ROOT / "docs").glob("*.md")]
    if "```python" in p.read_text(encoding="utf-8")
)


def blocks(page: str) -> list[tuple[int, str]]:
    text = (ROOT / page).read_text(encoding="utf-8")
    return [
        (text[: m.start()].count("\n") + 2, m.group(1))
        for m in re.finditer(r"```python\n(.*?)```", text, re.S)
    ]


@pytest.mark.parametrize("page", PAGES)
def test_python_examples_import_public_names(page: str) -> None:
    found = blocks(page)
    assert found, f"{page} has no Python example"
    for line, code in found:
        tree = ast.parse(code, filename=f"{page}:{line}")
        for node in ast.walk(tree):
            if not isinstance(node, ast.ImportFrom) or not (node.module or "").startswith(
                "anunnaki"
            ):
                continue
            module = node.module or ""
            where = f"{page}:{line + node.lineno - 1}"
            assert not any(p.startswith("_") for p in module.split(".")), (
                f"{where}: imports the private module {module}"
            )
            public = importlib.import_module(module)
            for alias in node.names:
                assert hasattr(public, alias.name), f"{where}: {module} has no {alias.name}"
