"""Reloading a model registry while it serves: re-read a file, check it, take it in one step.

The LEC node's reload service (``/lm_manager/reload``) calls :func:`reread` (nothing changes
yet: the new file is read and every model and oracle checked as at a start) and then
:func:`replace` (every holder of the registry sees the new models from then on).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from anunnaki.errors import AnunnakiError, MissingExtraError
from anunnaki.lec._detector import sha256_file
from anunnaki.lec._registry import (
    ModelIntegrityError,
    ModelRegistry,
    ModelRegistryError,
    ModelSpec,
)
from anunnaki.lec._registry_file import load_registry

__all__ = ["RegistryChange", "replace", "reread"]


@dataclass(frozen=True)
class RegistryChange:
    """A registry file read and checked to replace a running one (:func:`reread`).

    Attributes:
        registry: The new registry (apply it with :func:`replace`).
        source: The file it was read from.
        added: Ids of the models it adds.
        changed: Ids of the models whose entry changed (files, hashes, metrics, oracle …).
        removed: Ids of the models it no longer lists.

    """

    registry: ModelRegistry
    source: str
    added: tuple[str, ...]
    changed: tuple[str, ...]
    removed: tuple[str, ...]


def _loads_same(a: ModelSpec, b: ModelSpec) -> bool:
    """Whether loading ``b`` gives what loading ``a`` gives.

    The same loader and options, and the same bytes (equal sha256 pins; without pins, the
    same file).
    """
    if (a.loader, a.options) != (b.loader, b.options):
        return False
    if sorted(a.pins.values()) != sorted(b.pins.values()):
        return False
    if a.sha256 is not None or b.sha256 is not None:
        return a.sha256 == b.sha256
    return a.file.resolve() == b.file.resolve()


_SWAP_FIRST = (
    "a reload never drops or replaces the model in use: swap to another model first "
    "(/lm_manager/swap), then reload"
)


def _check_kept(new: ModelRegistry, old: ModelSpec | None, keep: str) -> None:
    """Refuse a registry that drops the model in use, or changes what it loads."""
    if keep not in new:
        raise new._file_error(
            "models",
            f"the model in use, {keep!r}, is not listed (listed: {', '.join(new.ids())})",
            f"keep its entry; {_SWAP_FIRST}",
        )
    if old is not None and not _loads_same(old, new.get(keep)):
        raise new._entry_error(
            keep,
            f"the entry of the model in use, {keep!r}, changes its file, sha256, loader or options",
            "file",
            f"keep those as they are (metrics, description and oracle may change); {_SWAP_FIRST}",
        )


def _check_entry(new: ModelRegistry, spec: ModelSpec, *, load: bool) -> None:
    """Hash one entry's model files and oracle; with ``load``, load the model once."""
    try:
        if load:
            new.load(spec)  # verifies the hashes first
        else:
            new.verify(spec)
    except ModelIntegrityError as exc:
        raise new._entry_error(
            spec.id,
            str(exc),
            "sha256",
            "copy the model again; if the file changed on purpose, put its new digest in the "
            "entry's sha256 (sha256sum FILE)",
        ) from None
    except MissingExtraError:
        raise
    except Exception as exc:  # ModelLoadError, or a loader's own bug
        said = str(exc) if isinstance(exc, AnunnakiError) else f"{type(exc).__name__}: {exc}"
        raise new._entry_error(
            spec.id,
            said,
            "file",
            ""  # the loader's error says what to do
            if "(hint: " in said
            else "the file must be a model its loader accepts (an anunnaki model: "
            "NAME.safetensors with its NAME.json); copy it again",
        ) from None
    oracle = spec.oracle
    if oracle is None or oracle.sha256 is None:
        return  # an oracle without a pin is checked against its sidecar when it is loaded
    try:
        digest = sha256_file(oracle.file)
    except OSError as exc:
        raise new._entry_error(
            spec.id,
            f"cannot read the oracle {oracle.file}: {exc.strerror or exc}",
            "oracle",
            "copy the oracle (NAME.safetensors and NAME.json) next to the registry",
        ) from None
    if digest != oracle.sha256:
        raise new._entry_error(
            spec.id,
            f"model {spec.id!r}: sha256 mismatch for its oracle {oracle.file}: the registry says "
            f"{oracle.sha256[:12]}…, the file is {digest[:12]}…",
            "oracle",
            "copy the oracle again; if it was retrained on purpose, put the digest anunnaki "
            "oracle train printed in oracle.sha256",
        )


def reread(registry: ModelRegistry, path: str | Path, *, keep: str | None = None) -> RegistryChange:
    """Read a registry file to replace *registry*, checked as thoroughly as a start.

    Nothing changes in *registry* (:func:`replace` applies the result). The file is read as
    :func:`load_registry` reads one (safe YAML: no aliases, bounded size and depth;
    model files inside its folder, each pinned), with *registry*'s loader; then
    every model's files are hashed against the entry's ``sha256`` and every oracle with
    a ``sha256`` against it; every model that is new or whose files changed is loaded
    once (a file that is not a model the loader accepts — not safetensors, a shape
    that does not fit its network — is refused now, not at the swap that needs it).

    Args:
        registry: The registry that serves now.
        path: The registry file.
        keep: The id of the model in use: the new registry must list it with the same
            files, ``sha256``, loader and options (a reload never drops it or replaces
            it under the frames it is serving).

    Raises:
        ModelFileError: The file, a model or an oracle is refused, naming the file, the
            line and the entry, and saying what to do.

    """
    source = str(path)
    new = load_registry(path, loader=registry._loader)
    if new.lec != registry.lec:
        raise new._file_error(
            "lec",
            f"the registry is for lec {new.lec!r}; this model manager serves {registry.lec!r}",
            f"give the registry of lec {registry.lec!r} (lec: {registry.lec})",
        )
    old = {spec.id: spec for spec in registry.models}
    if keep is not None:
        _check_kept(new, old.get(keep), keep)
    for spec in new:
        if spec.id in old and _loads_same(old[spec.id], spec):
            _check_entry(new, spec, load=False)
        else:
            _check_entry(new, spec, load=True)
    return RegistryChange(
        registry=new,
        source=source,
        added=tuple(i for i in new.ids() if i not in old),
        changed=tuple(i for i in new.ids() if i in old and old[i] != new.get(i)),
        removed=tuple(i for i in old if i not in new),
    )


def replace(registry: ModelRegistry, change: RegistryChange) -> None:
    """Give *registry* the models of a checked :func:`reread` in one step (for every holder).

    Whoever holds *registry* (the LEC node, an oracle that reads clean F1 or the
    models' oracles from it) sees the new models from now on.

    Raises:
        ModelRegistryError: The change is for another lec.

    """
    new = change.registry
    if new.lec != registry.lec:
        raise ModelRegistryError(f"a registry of lec {new.lec!r} cannot replace {registry.lec!r}")
    with registry._lock:
        registry._models = dict(new._models)
        registry._where = dict(new._where)
        registry._lines = new._lines
        registry.source = change.source
