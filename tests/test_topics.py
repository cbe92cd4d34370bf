"""The catalogue of well-known names: one place, valid bus names, no literal copies in src."""

from __future__ import annotations

import ast
from pathlib import Path

from anunnaki import topics
from anunnaki.bus import validate_name

SRC = Path(__file__).resolve().parents[1] / "src" / "anunnaki"


def test_every_name_is_a_valid_bus_name() -> None:
    names = [v for k, v in vars(topics).items() if k.isupper() and isinstance(v, str)]
    assert len(names) >= 20
    for name in names:
        validate_name(name)
    for node in topics.UTU_NODES:
        validate_name(topics.ready_service(node))
        validate_name(topics.node_token(node))
    assert topics.operator_service("pause") == topics.PAUSE


def test_no_module_spells_a_catalogued_utu_name_literally() -> None:
    catalogued = {
        v for k, v in vars(topics).items() if k.isupper() and isinstance(v, str) and "/" in v
    }
    offenders = []
    for path in SRC.rglob("*.py"):
        if path.name == "topics.py":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        docstrings = {
            id(node.value)
            for node in ast.walk(tree)
            if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
        }
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Constant)
                and isinstance(node.value, str)
                and id(node) not in docstrings
                and node.value in catalogued
            ):
                offenders.append(f"{path.relative_to(SRC)}:{node.lineno}: {node.value}")
    assert offenders == []


def test_no_module_keeps_an_alias_of_a_catalogued_name() -> None:
    """Every name is defined once: users write ``topics.GROUND_TRUTH``, not a copy of it."""
    catalogued = {v for k, v in vars(topics).items() if k.isupper() and isinstance(v, str)}
    offenders = []
    for path in SRC.rglob("*.py"):
        if path.name == "topics.py":
            continue
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            value = node.value if isinstance(node, ast.Assign | ast.AnnAssign) else None
            aliased = (
                isinstance(value, ast.Attribute)
                and isinstance(value.value, ast.Name)
                and value.value.id == "topics"
            ) or (isinstance(value, ast.Constant) and value.value in catalogued)
            if aliased:
                offenders.append(f"{path.relative_to(SRC)}:{node.lineno}: {ast.unparse(node)}")
    assert offenders == []
