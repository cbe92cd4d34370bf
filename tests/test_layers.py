"""The layers of the house hold: import-linter's contracts, and no package reaches into another's
private modules (``anunnaki.<package>._<module>``); each package's ``__init__`` is its face."""

from __future__ import annotations

import ast
import importlib
import pkgutil
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

import pytest

from anunnaki.errors import AnunnakiError
from anunnaki.plugins import NAME_RULE, Registry, check_name

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


def _module_cycle(package: str) -> list[str]:
    """A cycle among ``package``'s modules, counting every import (in a function or under
    ``TYPE_CHECKING`` too: such an import only hides a cycle), or ``[]``."""
    folder = SRC / package
    graph: dict[str, set[str]] = {}
    for path in sorted(folder.rglob("*.py")):
        name = ".".join(path.relative_to(folder).with_suffix("").parts)
        deps = graph.setdefault(name, set())
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module:
                target = node.module.removeprefix(f"anunnaki.{package}.")
                if target != node.module and target != name:
                    deps.add(target)
    visiting: list[str] = []
    done: set[str] = set()

    def visit(name: str) -> list[str]:
        if name in visiting:
            return [*visiting[visiting.index(name) :], name]
        if name in done or name not in graph:
            return []
        visiting.append(name)
        for dep in sorted(graph[name]):
            if cycle := visit(dep):
                return cycle
        visiting.pop()
        done.add(name)
        return []

    return next((c for c in map(visit, sorted(graph)) if c), [])


@pytest.mark.parametrize("package", ["datasets", "sim"])
def test_no_cycle_between_a_packages_modules(package: str) -> None:
    """Issue 21 item 6: ``datasets`` ``_dataset↔_coco/_yolo`` and ``sim`` ``_layout↔_models``
    were cycles dodged by function-local and TYPE_CHECKING imports."""
    assert _module_cycle(package) == []


#: A whole string that names ``module:attribute`` (a lazy reference, an entry point).
_REF = re.compile(r"^anunnaki(\.\w+)+:\w+(\.\w+)*$")


def test_no_string_names_a_module_of_another_package() -> None:
    """A lazy ``"module:attr"`` names its own package only; import-linter cannot see strings.

    Plugins of a package above a slot (Enlil's oracle) register by an entry point in
    pyproject.toml instead (the next test).
    """
    offenders = []
    for path in sorted(SRC.rglob("*.py")):
        mine = _package_of(path) or path.stem
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            ref = node.value if isinstance(node, ast.Constant) else None
            if isinstance(ref, str) and _REF.match(ref) and ref.split(".")[1].split(":")[0] != mine:
                offenders.append(f"{path.relative_to(SRC)}:{node.lineno}: {ref!r}")
    assert offenders == []


def _public_names(module: str) -> set[str]:
    """``__all__`` of a module of this source tree, read without importing it."""
    parts = module.split(".")[1:]
    path = SRC.joinpath(*parts, "__init__.py")
    if not path.exists():
        path = SRC.joinpath(*parts[:-1], f"{parts[-1]}.py")
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
        ):
            return {e.value for e in node.value.elts if isinstance(e, ast.Constant)}  # type: ignore[attr-defined]
    return set()


def test_entry_points_name_public_names_of_the_package_above_the_slot() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    groups = project.get("entry-points", {})
    assert "enlil" in groups["anunnaki.oracles"]  # Enlil's oracle: here, not in oracles/
    for group, entries in groups.items():
        for name, ref in entries.items():
            assert check_name(name, what=group) == name
            module, _, attr = ref.partition(":")
            where = f"[project.entry-points.{group!r}] {name} = {ref!r}"
            assert module.startswith("anunnaki."), where
            assert not any(p.startswith("_") for p in module.split(".")), (
                f"{where} names a private module; export the name from the package"
            )
            assert attr in _public_names(module), f"{where}: {attr} is not in {module}.__all__"


def test_every_slot_is_a_registry_with_the_one_name_rule() -> None:
    """Every package's public slots (module-level registries) follow one form and one rule."""
    slots: dict[int, Registry[Any]] = {}
    for info in pkgutil.iter_modules([str(SRC)]):
        if info.name.startswith("_") or info.name == "__main__":
            continue
        module = importlib.import_module(f"anunnaki.{info.name}")
        for value in vars(module).values():
            if isinstance(value, Registry):
                slots[id(value)] = value
    whats = {slot.what for slot in slots.values()}
    assert {"message type", "bus kind", "phenomenon", "oracle", "managed system"} <= whats
    for slot in slots.values():
        for name in slot.names():
            assert check_name(name, what=slot.what) == name
        with pytest.raises(AnunnakiError, match=re.escape(NAME_RULE)):
            slot.register_lazy("not a name", "collections:OrderedDict")
