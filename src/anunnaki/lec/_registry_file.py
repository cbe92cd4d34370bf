"""Reading and checking a model registry file (``anunnaki: models/1``).

A registry file::

    anunnaki: models/1
    lec: detector
    models:
      - id: detector-default
        domain: default
        file: models/detector-default.safetensors   # relative to this file
        sha256: 9f2c…                                # of that file; checked before loading
      - id: detector-fog
        domain: fog
        file: models/detector-fog.safetensors
        sha256: 41ab…
        metrics: {f1: 0.91}                          # optional; merged over the sidecar's
      - id: detector-onnx                            # a model in another format:
        domain: low_light
        loader: my_onnx                              # a detector architecture plugin
        file: models/yolo.onnx
        options: {labels: labels.txt}                # given to the plugin's load()
        sha256: {models/yolo.onnx: 77c1…, models/labels.txt: 0d9e…}   # every file it reads

:func:`load_registry` reads one (safe YAML: no aliases, bounded size and depth) into a
:class:`~anunnaki.lec.ModelRegistry`: every model file must lie inside the registry's folder
and be pinned by a sha256. Errors about the file name the file and the line.
:func:`resolve_model` names one model as the commands do: a model file, or a registry and an id.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from anunnaki._safeyaml import LineMap, load_yaml, validation_error
from anunnaki.errors import AnunnakiError, ModelFileError, validation_message
from anunnaki.lec._detector import (
    ARCHITECTURES,
    Detector,
    architecture_files,
    checked_weights,
    read_card,
    sha256_file,
)
from anunnaki.lec._registry import (
    DEFAULT_DOMAIN,
    REGISTRY_FORMAT,
    Loader,
    ModelRegistry,
    ModelRegistryError,
    ModelSpec,
    OracleRef,
    _default_loader,
    _entry_error,
)

__all__ = [
    "REGISTRY_SUFFIXES",
    "ResolvedModel",
    "load_registry",
    "parse_registry",
    "resolve_model",
]

log = logging.getLogger("anunnaki.lec")


class _OracleEntry(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    file: Annotated[str, Field(min_length=1)]
    sha256: str | None = None


class _EntryFile(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    id: str | None = None
    domain: str | None = None
    loader: str | None = None
    file: Annotated[str, Field(min_length=1)]
    options: dict[str, Any] = Field(default_factory=dict)
    sha256: str | dict[str, str] | None = None
    metrics: dict[str, Any] = Field(default_factory=dict)
    description: str = ""
    oracle: _OracleEntry | None = None


class _RegistryFile(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    anunnaki: Literal["models/1"]
    lec: str = "detector"
    description: str = ""
    models: Annotated[list[_EntryFile], Field(min_length=1)]


def _read_sidecar(file: Path) -> dict[str, Any] | None:
    """The sidecar of an anunnaki model file as a dict, or ``None`` when there is none."""
    candidates = [file.with_suffix(".json")] if file.suffix != ".json" else [file]
    sidecar = next((c for c in candidates if c.is_file()), None)
    if sidecar is None:
        return None
    card = read_card(file)
    return card.model_dump(mode="json")


def _build(  # noqa: C901
    data: Any, lines: LineMap | None, source: str, base: Path, loader: Loader | None
) -> ModelRegistry:
    if not isinstance(data, dict) or data.get("anunnaki") != REGISTRY_FORMAT:
        raise ModelFileError(
            "not a model registry",
            path=source,
            line=1,
            hint=f"start the file with 'anunnaki: {REGISTRY_FORMAT}'",
        )
    try:
        parsed = _RegistryFile.model_validate(data)
    except ValidationError as exc:
        raise validation_error(exc, data, lines, source) from None
    registry = ModelRegistry(lec=parsed.lec, loader=loader, source=source)
    registry._lines = lines
    seen: dict[str, int] = {}
    domains: dict[str, tuple[int, str]] = {}  # domain -> (index, id) of the entry serving it
    for i, entry in enumerate(parsed.models):

        def fail(message: str, field: str | None, hint: str, i: int = i) -> ModelFileError:
            return _entry_error(message, lines=lines, path=source, index=i, field=field, hint=hint)

        file = _entry_file(entry, base, fail)
        card: dict[str, Any] | None = None
        if entry.loader is None:
            if entry.options:
                raise fail(
                    f"options {sorted(entry.options)} are for a loader plugin, and the entry "
                    "names none",
                    "options",
                    "name the plugin that reads the file (loader: NAME), or drop 'options'",
                )
            try:
                card = _read_sidecar(file)
            except AnunnakiError as exc:
                if loader is None:
                    raise fail(
                        f"the model's sidecar is unreadable: {exc}",
                        "file",
                        "copy the model again, or re-save it; a model in another format "
                        "needs 'loader: NAME' (a detector architecture plugin)",
                    ) from None
                # A loader given in code may read its own kind of .json.
                log.debug("model file %s: no anunnaki sidecar (%s)", file, exc)
        sha256, pins = _entry_pins(entry, file, base, fail, loader is not None)
        model_id = entry.id or (card or {}).get("model_id")
        domain = entry.domain or (card or {}).get("domain")
        if not model_id:
            raise fail("missing required field 'id'", None, "e.g. id: detector-fog")
        if not domain:
            raise fail(
                "missing required field 'domain' (the model has no sidecar that names it)",
                None,
                "e.g. domain: fog",
            )
        metrics = dict((card or {}).get("metrics") or {})
        metrics.update(entry.metrics)
        try:
            spec = ModelSpec(
                id=model_id,
                domain=domain,
                file=file,
                sha256=sha256,
                metrics=metrics,
                description=entry.description,
                loader=entry.loader,
                options=entry.options,
                pins=pins,
                oracle=_entry_oracle(entry, base, fail),
            )
        except ValidationError as exc:
            first = exc.errors(include_url=False)[0]
            field = str(first["loc"][0]) if first["loc"] else None
            raise _entry_error(
                validation_message(first),
                lines=lines,
                path=source,
                index=i,
                field=field,
                hint="see the registry format in docs/model-manager.md",
            ) from None
        if spec.id in seen:
            raise _entry_error(
                f"model id {spec.id!r} is used twice, by models[{seen[spec.id]}] and models[{i}]",
                lines=lines,
                path=source,
                index=i,
                field="id",
                hint="give each model its own id",
            )
        if spec.domain in domains:
            j, other = domains[spec.domain]
            raise _entry_error(
                f"models[{j}] ({other!r}) and models[{i}] ({spec.id!r}) both serve domain "
                f"{spec.domain!r}",
                lines=lines,
                path=source,
                index=i,
                field="domain",
                hint="a swap names a domain and gets its one model: remove the entry of the "
                "model that no longer serves it, or give one of them its own domain",
            )
        seen[spec.id] = i
        domains[spec.domain] = (i, spec.id)
        registry.add(spec)
        registry._where[spec.id] = i
    if DEFAULT_DOMAIN not in registry.domains():
        raise ModelFileError(
            f"no model for the domain {DEFAULT_DOMAIN!r}",
            path=source,
            line=lines.line(("models",)) if lines is not None else None,
            element="models",
            hint="the model manager starts with the default model and swaps back to it; "
            "add one with 'domain: default'",
        )
    return registry


def _entry_file(
    entry: _EntryFile, base: Path, fail: Callable[[str, str | None, str], ModelFileError]
) -> Path:
    """The entry's model file: it exists and, symlinks resolved, lies in the registry's folder."""
    file = Path(entry.file)
    file = file if file.is_absolute() else (base / file)
    if not file.is_file():
        raise fail(
            f"model file {entry.file!r} not found (looked at {file})",
            "file",
            "paths are relative to the registry file; copy the model there",
        )
    _inside(file, base, entry.file, fail, "file")
    return file


def _inside(
    path: Path,
    base: Path,
    named: str,
    fail: Callable[[str, str | None, str], ModelFileError],
    field: str,
) -> None:
    """Refuse a file that, symlinks resolved, lies outside the registry's folder."""
    real, root = path.resolve(), base.resolve()
    if not real.is_relative_to(root):
        raise fail(
            f"{named!r} is outside the registry's folder {root} (it resolves to {real})",
            field,
            "keep a registry's models in its own folder (no '..', absolute paths or symlinks "
            "out of it); copy the model there",
        )


def _entry_oracle(
    entry: _EntryFile, base: Path, fail: Callable[[str, str | None, str], ModelFileError]
) -> OracleRef | None:
    """The entry's ``oracle:`` with its file resolved against the registry's folder."""
    if entry.oracle is None:
        return None
    file = Path(entry.oracle.file)
    file = file if file.is_absolute() else (base / file)
    if not file.is_file():
        raise fail(
            f"oracle file {entry.oracle.file!r} not found (looked at {file})",
            "oracle",
            "paths are relative to the registry file; copy the oracle (NAME.safetensors and "
            "NAME.json) there, or train it (anunnaki oracle train)",
        )
    _inside(file, base, entry.oracle.file, fail, "oracle")
    try:
        return OracleRef(file=file, sha256=entry.oracle.sha256)
    except ValidationError:
        raise fail(
            "the oracle's sha256 must be 64 hexadecimal digits",
            "oracle",
            "copy the digest printed by anunnaki oracle train (or sha256sum FILE)",
        ) from None


def _entry_pins(  # noqa: C901
    entry: _EntryFile,
    file: Path,
    base: Path,
    fail: Callable[[str, str | None, str], ModelFileError],
    python_loader: bool,
) -> tuple[str | None, dict[Path, str]]:
    """The entry's loader checked, and its ``sha256`` as (the file's, the other files')."""
    reads = [file]
    if entry.loader is not None:
        if entry.loader not in ARCHITECTURES:
            raise fail(
                str(ARCHITECTURES.unknown(entry.loader)),
                "loader",
                "install the package that provides it (entry-point group anunnaki.detectors), "
                "or fix the name",
            )
        try:
            architecture = ARCHITECTURES.create(entry.loader)
            if not python_loader:
                reads = architecture_files(architecture, file, entry.options)
        except AnunnakiError as exc:
            raise fail(str(exc), "loader", "see the plugin's documentation") from None
        except Exception as exc:
            raise fail(
                f"loader {entry.loader!r} cannot say which files it reads: "
                f"{type(exc).__name__}: {exc}",
                "options",
                "see the plugin's documentation for its options",
            ) from None
        for path in reads:
            if not path.is_file():
                raise fail(
                    f"loader {entry.loader!r} reads {path}, which does not exist",
                    "options",
                    "copy the file there, or fix the options",
                )
    if entry.sha256 is None and not python_loader:
        digest = sha256_file(file)
        raise fail(
            "missing sha256: a registry pins every model file it loads",
            "sha256",
            f"add 'sha256: {digest}' (this file's digest now; check it is the file you trust)",
        )
    for path in reads:
        _inside(path, base, _relative(path, base), fail, "options")
    if entry.sha256 is None or isinstance(entry.sha256, str):
        if entry.sha256 is not None and len(reads) > 1:
            names = ", ".join(_relative(p, base) for p in reads)
            raise fail(
                f"loader {entry.loader!r} reads {len(reads)} files ({names}); one sha256 "
                "pins only the first",
                "sha256",
                "give sha256 as a mapping, one hex digest per file: {" + names + ": …}",
            )
        return entry.sha256, {}
    given = {(p if (p := Path(k)).is_absolute() else base / p).resolve(): (k, v)
             for k, v in entry.sha256.items()}  # fmt: skip
    pins: dict[Path, str] = {}
    for path in reads:
        found = given.pop(path.resolve(), None)
        if found is None:
            raise fail(
                f"no sha256 for {_relative(path, base)}, which loader {entry.loader!r} reads",
                "sha256",
                f"add '{_relative(path, base)}: <hex sha256>' (paths relative to the registry)",
            )
        pins[path] = found[1]
    if given:
        extra = ", ".join(k for k, _ in given.values())
        raise fail(
            f"sha256 pins {extra}, which the loader does not read",
            "sha256",
            "pin the files the loader reads: " + ", ".join(_relative(p, base) for p in reads),
        )
    return pins.pop(file, None), pins


def _relative(path: Path, base: Path) -> str:
    try:
        return str(path.resolve().relative_to(base.resolve()))
    except ValueError:
        return str(path)


def parse_registry(
    text: str, *, source: str = "<registry>", base: Path | None = None, loader: Loader | None = None
) -> ModelRegistry:
    """Parse a registry from YAML text; model paths resolve against ``base`` (default cwd).

    Raises:
        ModelFileError: Bad YAML, an unknown field, a missing model file, a duplicate id or
            no default model, naming the line.

    """
    data, lines = load_yaml(source, text=text)
    return _build(data, lines, source, base or Path.cwd(), loader)


def load_registry(path: str | Path, *, loader: Loader | None = None) -> ModelRegistry:
    """Load a registry file (``anunnaki: models/1``); model paths are relative to it.

    Raises:
        ModelFileError: As :func:`parse_registry`, naming the file and the line.

    """
    data, lines = load_yaml(path)
    return _build(data, lines, str(path), Path(path).resolve().parent, loader)


# -- one model, named on a command line ------------------------------------------------------

#: The suffixes of a registry file; any other path is a model file.
REGISTRY_SUFFIXES = (".yaml", ".yml")


@dataclass(frozen=True)
class ResolvedModel:
    """One model named as a command line names it: a model file, or a registry and an id.

    Attributes:
        source: What was given (``NAME.safetensors``, ``NAME.json`` or ``REG.yaml``).
        model_id: The registry's id of the model, or the model file's own.
        domain: Its operating domain.
        file: The model file: the registry entry's ``file``, or the weights
            (``NAME.safetensors``) of a model file given as ``NAME.safetensors`` or
            ``NAME.json`` — the file :meth:`load` reads.
        sha256: Hex sha256 of ``file`` (checked against the registry's pins, if any): what
            a report states was measured.
        spec: The registry entry (``None`` for a model file).
        registry: The registry (``None`` for a model file).

    Nothing is loaded until :meth:`load`: an oracle trained from an archive needs the
    model's id and hash, not the model.

    """

    source: str
    model_id: str
    domain: str
    file: Path
    sha256: str
    spec: ModelSpec | None = None
    registry: ModelRegistry | None = None

    def load(self) -> Detector:
        """The detector: through the registry (its files verified again) or ``load_detector``.

        Raises:
            ModelIntegrityError: As :meth:`ModelRegistry.load`.
            ModelLoadError: As :meth:`ModelRegistry.load`.
            DetectorLoadError: A model file is not a valid anunnaki model.

        """
        if self.registry is not None and self.spec is not None:
            return self.registry.load(self.spec)
        return _default_loader(self.file)


def resolve_model(source: str | Path, model_id: str | None = None) -> ResolvedModel:
    """The model *source* names: a model file, or registry *source*'s model *model_id*.

    This is how every command that measures a model (``assess``, ``evaluate-detector``,
    ``oracle train``, ``oracle evaluate``) reads ``MODEL`` and ``--model ID``, so a model
    served by a loader plugin (``loader: NAME`` in its registry entry) is measured like a
    native one.

    Args:
        source: ``NAME.safetensors`` / ``NAME.json``, or a registry ``REG.yaml``.
        model_id: With a registry: which model (default: its ``default``-domain model).

    Raises:
        ModelFileError: A bad registry file (naming the line).
        UnknownModelError: No model has that id (listing those that exist).
        ModelIntegrityError: A file's sha256 differs from the registry's.
        ModelRegistryError: *model_id* given with a model file.
        DetectorLoadError: A model file's sidecar is missing or invalid.

    """
    path = Path(source)
    if path.suffix.lower() in REGISTRY_SUFFIXES:
        registry = load_registry(path)
        spec = registry.resolve(model_id=model_id)
        digest = registry.verify(spec)
        return ResolvedModel(str(source), spec.id, spec.domain, spec.file, digest, spec, registry)
    if model_id is not None:
        raise ModelRegistryError(
            f"--model {model_id} picks a model of a registry (REG.yaml), and {source} is a "
            "model file; drop --model, or name the registry"
        )
    card = read_card(path)
    weights = checked_weights(path, card)  # the file given is the file loaded
    return ResolvedModel(str(source), card.model_id, card.domain, weights, sha256_file(weights))
