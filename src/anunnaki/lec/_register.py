"""Adding a model (and its oracle) to a model registry file, keeping the file as it is.

``anunnaki robustify --register REG.yaml`` and ``scripts/`` use :func:`register_model`: the
model's files (and the oracle's) are copied into the registry's folder when they are not
there already (a registry names files inside its folder only), the entry is appended to the
``models:`` list with the sha256 of each file, and the registry is loaded again — every hash
checked — before the function returns; if that fails, the file is put back as it was. Other
entries, comments and layout are untouched: the entry is inserted as text, never by
re-dumping the YAML.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

from anunnaki._names import NameRuleError, check_domain, check_name
from anunnaki.lec._detector import read_card, sha256_file, sidecar_path, weights_path
from anunnaki.lec._registry import REGISTRY_FORMAT, ModelRegistryError, ModelSpec
from anunnaki.lec._registry_file import load_registry

__all__ = ["check_registrable", "register_model"]

_MODELS = re.compile(r"^models:\s*(#.*)?$")


def _copy_in(file: Path, folder: Path, what: str) -> Path:
    """*file* and its ``.json`` sidecar inside *folder* (copied when elsewhere)."""
    if file.resolve().parent == folder.resolve():
        return file.resolve()
    for src in (file, sidecar_path(file)):
        dest = folder / src.name
        if dest.exists() and sha256_file(dest) != sha256_file(src):
            raise ModelRegistryError(
                f"{dest}: the registry's folder already holds another {what} file of this "
                f"name; rename {file.name} (another --id) or move the old file away"
            )
        if not dest.exists():
            shutil.copy2(src, dest)
    return (folder / file.name).resolve()


def _entry(spec: dict[str, str], oracle: tuple[str, str] | None, indent: str) -> list[str]:
    inner = indent + "  "
    lines = [f"{indent}- id: {spec['id']}", f"{inner}domain: {spec['domain']}"]
    lines.append(f"{inner}file: {json.dumps(spec['file'])}")
    lines.append(f"{inner}sha256: {spec['sha256']}")
    if spec.get("description"):
        lines.append(f"{inner}description: {json.dumps(spec['description'])}")
    if oracle is not None:
        lines.append(f"{inner}oracle: {{file: {json.dumps(oracle[0])}, sha256: {oracle[1]}}}")
    return lines


def _insert(text: str, entry: list[str] | None, registry: Path) -> tuple[list[str], str]:
    """The lines with the entry at the end of the ``models:`` block (and the entry indent)."""
    lines = text.splitlines()
    start = next((i for i, t in enumerate(lines) if _MODELS.match(t)), None)
    if start is None:
        if any(t.startswith("models:") for t in lines):
            raise ModelRegistryError(
                f"{registry}: its models: list is written inline; write it as a block list "
                "('models:' alone on its line, one '- id: …' entry per model) to add to it"
            )
        lines.append("models:")
        start = len(lines) - 1
    end = start + 1
    while end < len(lines) and (not lines[end].strip() or lines[end][0] in " \t-#"):
        end += 1
    while end > start + 1 and (not lines[end - 1].strip() or lines[end - 1].startswith("#")):
        end -= 1
    items = [m for t in lines[start + 1 : end] if (m := re.match(r"^(\s*)- ", t))]
    indent = items[0].group(1) if items else "  "
    if entry is not None:
        lines[end:end] = entry
    return lines, indent


def _write(path: Path, text: str) -> None:
    tmp = path.with_name(f".tmp-{path.name}")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def _check_names(model_id: str, domain: str) -> None:
    """The entry's id and domain follow the rule for names (before the file is touched)."""
    try:
        check_name(model_id, what="model id")
        check_domain(domain, what="domain")
    except NameRuleError as exc:
        raise ModelRegistryError(str(exc)) from None


def check_registrable(registry: str | Path, model_id: str, domain: str) -> None:
    """Refuse what :func:`register_model` would refuse in an existing *registry*, up front.

    Raises:
        ModelRegistryError: A model with *model_id* is registered already (naming its line),
            another model serves *domain* (one model per domain: a swap names a domain), or
            the id or the domain is no name (``anunnaki._names``).
        ModelFileError: The registry is malformed (naming the line).

    """
    reg = Path(registry)
    _check_names(model_id, domain)
    existing = load_registry(reg)
    if model_id in existing:
        entry_re = re.compile(rf"\s*- id: {re.escape(model_id)}\s*")
        lines = reg.read_text(encoding="utf-8").splitlines()
        line = next((n for n, t in enumerate(lines, 1) if entry_re.fullmatch(t)), "?")
        raise ModelRegistryError(
            f"{reg}:{line}: a model with id {model_id!r} is registered already; give the "
            "new model another id (robustify --id NAME) or remove that entry first"
        )
    serving = next((m for m in existing if m.domain == domain), None)
    if serving is not None:
        raise ModelRegistryError(
            f"{reg}: {serving.id!r} serves domain {domain!r} already (one model per domain: a "
            f"swap names a domain); remove that entry first to register {model_id!r} in its "
            "place, or give the new model another domain"
        )


def register_model(
    registry: str | Path,
    model: str | Path,
    *,
    oracle: str | Path | None = None,
    model_id: str | None = None,
    domain: str | None = None,
    description: str = "",
    create: bool = False,
) -> ModelSpec:
    """Add *model* (and its *oracle*) to *registry* with their sha256; return the new entry.

    Args:
        registry: A ``models/1`` registry file.
        model: The model file (``NAME.safetensors`` with its ``NAME.json``).
        oracle: Its behavior oracle file (``NAME.safetensors`` with its ``NAME.json``).
        model_id: The entry's id (default: the model's own).
        domain: The entry's domain (default: the model's own).
        description: Free text for the entry.
        create: Write a new registry when *registry* does not exist (the model must then be
            of the ``default`` domain: a registry starts from its default model).

    Raises:
        ModelRegistryError: The id is registered already, another model serves the domain,
            the id or the domain is no name (``anunnaki._names``), the registry is missing
            (without *create*) or cannot be added to, or a file of the same name is in the way.
        ModelFileError: The registry is malformed (naming the line) or the result does not
            load (the file is then restored).

    """
    reg = Path(registry)
    existed = reg.is_file()
    weights = weights_path(model)
    card = read_card(weights)
    model_id = model_id or card.model_id
    domain = domain or card.domain
    _check_names(model_id, domain)
    if reg.is_file():
        text = reg.read_text(encoding="utf-8")
        check_registrable(reg, model_id, domain)
    elif create:
        text = f"anunnaki: {REGISTRY_FORMAT}\nlec: detector\nmodels:\n"
    else:
        raise ModelRegistryError(
            f"{reg}: no model registry there; give an existing one (e.g. a copy of "
            "examples/models/rover.yaml) — it needs the default model the manager starts with"
        )
    _, indent = _insert(text, None, reg)  # a registry that cannot be added to fails first
    folder = reg.resolve().parent
    folder.mkdir(parents=True, exist_ok=True)
    model_file = _copy_in(weights, folder, "model")
    fields = {"id": model_id, "domain": domain, "file": model_file.name,
              "sha256": sha256_file(model_file), "description": description}  # fmt: skip
    pin = None
    if oracle is not None:
        oracle_file = _copy_in(weights_path(oracle), folder, "oracle")
        pin = (oracle_file.name, sha256_file(oracle_file))
    lines, _ = _insert(text, _entry(fields, pin, indent), reg)
    _write(reg, "\n".join(lines) + "\n")
    try:
        loaded = load_registry(reg)
        loaded.verify(model_id)
    except Exception:
        if existed:
            _write(reg, text)  # the registry as it was
        else:
            reg.unlink()
        raise
    return loaded.get(model_id)
