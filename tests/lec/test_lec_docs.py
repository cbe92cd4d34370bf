"""The Python examples of the LEC pages import public names that exist (issue 22, item 8).

docs/model-manager.md's example imported ``anunnaki.lec._node`` and ``anunnaki.lec._registry``
although ``anunnaki.lec`` exports both; every block is parsed, and every ``from anunnaki…
import`` in it must name a public module and names that module has.
"""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[2] / "docs"
PAGES = ("model-manager.md", "detector.md")


def blocks(page: str) -> list[tuple[int, str]]:
    text = (DOCS / page).read_text(encoding="utf-8")
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
            where = f"docs/{page}:{line + node.lineno - 1}"
            assert not any(p.startswith("_") for p in module.split(".")), (
                f"{where}: imports the private module {module}"
            )
            public = importlib.import_module(module)
            for alias in node.names:
                assert hasattr(public, alias.name), f"{where}: {module} has no {alias.name}"
