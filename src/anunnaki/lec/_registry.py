"""The model registry: which models an LEC has, per operating domain, and how to trust them.

The learning model manager (paper §3.3, ``/lm_manager``) swaps an LEC's model for one
robustified to the perceived condition — fog, low light, raindrops on the lens — and back to
the default model when the condition has passed. The registry is what it picks from: one
entry per model with its id, its domain, its file, the file's sha256 and the figures measured
after training (``metrics``; the clean F1 is what behavior assessments compare against).

Why the registry states a hash of its own
    The model file's sidecar already carries the weights' sha256, and ``load_detector``
    refuses weights that do not match it. But the sidecar travels with the weights: whoever
    can swap one can swap both. The registry is written by whoever deploys the system, so a
    hash stated there pins *the* file that was validated; :meth:`ModelRegistry.load` checks it
    before a single byte reaches the loader.

Build one in code with :class:`ModelRegistry` and :meth:`ModelRegistry.add`, or load a file
with :func:`~anunnaki.lec.load_registry` (``_registry_file``: reading and checking a registry
file); ``_registry_reload`` re-reads a file to replace a registry that is serving.
"""

from __future__ import annotations

import logging
import math
import re
import threading
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from anunnaki._names import check_domain, check_name
from anunnaki._safeyaml import LineMap
from anunnaki.errors import AnunnakiError, MissingExtraError, ModelFileError, validation_message
from anunnaki.lec._detector import (
    ARCHITECTURES,
    Detector,
    architecture_files,
    sha256_file,
)

__all__ = [
    "DEFAULT_DOMAIN",
    "REGISTRY_FORMAT",
    "ModelIntegrityError",
    "ModelLoadError",
    "ModelRegistry",
    "ModelRegistryError",
    "ModelSpec",
    "OracleRef",
    "UnknownModelError",
]

log = logging.getLogger("anunnaki.lec")

#: The format tag of a registry file.
REGISTRY_FORMAT = "models/1"
#: The domain of the model that runs when no adverse condition is perceived.
DEFAULT_DOMAIN = "default"

_SHA_RE = re.compile(r"^[0-9a-f]{64}$")


class ModelRegistryError(AnunnakiError):
    """A registry lookup or a registry built in code is wrong (unknown model, bad entry)."""


class UnknownModelError(ModelRegistryError, LookupError):
    """No model has that id, or no model serves that domain; the message lists what exists."""


class ModelIntegrityError(ModelRegistryError):
    """A model file is missing, unreadable, or its sha256 differs from the registry's."""


class ModelLoadError(ModelRegistryError):
    """The loader refused a model file (corrupt weights, a bad sidecar, a wrong shape)."""


#: Turns a model file into a loaded model (default: ``anunnaki.lec.load_detector``).
Loader = Callable[[Path], Detector]


def _digest(value: str) -> str:
    digest = value.strip().lower()
    if not _SHA_RE.match(digest):
        raise ValueError("sha256 must be 64 hexadecimal digits")
    return digest


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    f = float(value)
    return f if math.isfinite(f) else None


class OracleRef(BaseModel):
    """The behavior oracle of a model (``oracle: {file, sha256}`` in a registry entry).

    Attributes:
        file: The oracle file (``NAME.safetensors``, its ``NAME.json`` sidecar next to it).
        sha256: Hex sha256 of ``file``, checked before it is loaded; ``None`` trusts the
            sidecar's own hash.

    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    file: Path
    sha256: str | None = None

    @field_validator("sha256")
    @classmethod
    def _check_sha(cls, value: str | None) -> str | None:
        return None if value is None else _digest(value)


class ModelSpec(BaseModel):
    """One model of the registry.

    Attributes:
        id: The model id tactics and messages use, e.g. ``detector-fog``.
        domain: The operating domain it is robustified for (``default``, ``fog``,
            ``low_light``, ``raindrop`` …).
        file: The model file (``NAME.safetensors``, its sidecar next to it; or the file
            the ``loader`` reads).
        sha256: Hex sha256 of ``file``, checked before every load; ``None`` skips the check
            (the loader still checks the sidecar's hash).
        metrics: Figures measured after training (from the sidecar, overridden by the
            registry); see :attr:`clean_f1`.
        description: Free text.
        loader: The detector architecture plugin (:data:`~anunnaki.lec.ARCHITECTURES`)
            that loads ``file``; ``None``: an anunnaki model file (``load_detector``).
        options: Given to the loader's ``load(file, options)``.
        pins: Hex sha256 of the other files the loader reads (its ``files()``), by path;
            with ``sha256`` set, every file it reads must be pinned.
        oracle: The model's behavior oracle (``anunnaki.enlil``), when it has one.

    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    id: str
    domain: str
    file: Path
    sha256: str | None = None
    metrics: dict[str, Any] = Field(default_factory=dict)
    description: str = ""
    loader: str | None = None
    options: dict[str, Any] = Field(default_factory=dict)
    pins: dict[Path, str] = Field(default_factory=dict)
    oracle: OracleRef | None = None

    @field_validator("id")
    @classmethod
    def _check_id(cls, value: str) -> str:
        return check_name(value, what="model id")

    @field_validator("domain")
    @classmethod
    def _check_domain(cls, value: str) -> str:
        return check_domain(value, what="domain")

    @field_validator("sha256")
    @classmethod
    def _check_sha(cls, value: str | None) -> str | None:
        if value is None:
            return None
        return _digest(value)

    @field_validator("pins")
    @classmethod
    def _check_pins(cls, value: dict[Path, str]) -> dict[Path, str]:
        return {path: _digest(digest) for path, digest in value.items()}

    @property
    def clean_f1(self) -> float | None:
        """The model's F1 on clean data, the reference of behavior categories.

        Looked up in ``metrics`` in this order: ``f1``, ``clean.f1``, ``test.f1``,
        ``val.f1``; ``None`` when none is a finite number.
        """
        direct = _number(self.metrics.get("f1"))
        if direct is not None:
            return direct
        for split in ("clean", "test", "val"):
            section = self.metrics.get(split)
            if isinstance(section, Mapping):
                value = _number(section.get("f1"))
                if value is not None:
                    return value
        return None


class ModelRegistry:
    """The models of one LEC, by id and by domain.

    Args:
        models: Initial entries (:class:`ModelSpec` or mappings of its fields).
        lec: The name of the LEC these models serve (``detector``).
        loader: Turns a file into a loaded model; default ``anunnaki.lec.load_detector``
            (imported when first used). Tests and third-party models pass their own.
        source: Where the registry came from, for messages.

    Thread-safe: the model manager resolves and loads from its service thread while other
    threads read metrics.

    """

    def __init__(
        self,
        models: Iterable[ModelSpec | Mapping[str, Any]] = (),
        *,
        lec: str = "detector",
        loader: Loader | None = None,
        source: str | None = None,
    ) -> None:
        self.lec = lec
        self.source = source
        self._loader = loader
        self._models: dict[str, ModelSpec] = {}
        #: A registry file's entries by id, ``id -> index``, and its lines (for errors).
        self._where: dict[str, int] = {}
        self._lines: LineMap | None = None
        self._lock = threading.RLock()
        for spec in models:
            self.add(spec)

    def __repr__(self) -> str:
        return f"ModelRegistry(lec={self.lec!r}, models={self.ids()})"

    # -- contents --------------------------------------------------------------------------
    def add(self, spec: ModelSpec | Mapping[str, Any] | None = None, **fields: Any) -> ModelSpec:
        """Add one model: a :class:`ModelSpec`, a mapping, or its fields as keywords.

        Raises:
            ModelRegistryError: Invalid fields (naming the field), the id is taken, or another
                model serves the domain already.

        """
        if spec is None:
            spec = fields
        elif fields:
            raise ModelRegistryError("give a ModelSpec/mapping or keyword fields, not both")
        if not isinstance(spec, ModelSpec):
            try:
                spec = ModelSpec.model_validate(dict(spec))
            except ValidationError as exc:
                first = exc.errors(include_url=False)[0]
                where = ".".join(str(p) for p in first["loc"]) or "model"
                raise ModelRegistryError(
                    f"model entry {where}: {validation_message(first)}"
                ) from None
        if spec.loader is not None and spec.loader not in ARCHITECTURES:
            raise ModelRegistryError(
                f"model {spec.id!r}: {ARCHITECTURES.unknown(spec.loader)}; install the "
                "package that provides it (entry-point group anunnaki.detectors)"
            )
        if spec.options and spec.loader is None:
            raise ModelRegistryError(
                f"model {spec.id!r}: options {sorted(spec.options)} are for a loader; name one "
                "(loader: NAME)"
            )
        with self._lock:
            if spec.id in self._models:
                raise ModelRegistryError(
                    f"model id {spec.id!r} is registered twice; give each model its own id"
                )
            other = next((m for m in self._models.values() if m.domain == spec.domain), None)
            if other is not None:
                raise ModelRegistryError(
                    f"models {other.id!r} and {spec.id!r} both serve domain {spec.domain!r}; "
                    "a swap names a domain and gets its one model: keep one of them, or give "
                    "the other its own domain"
                )
            self._models[spec.id] = spec
        return spec

    def __iter__(self) -> Iterator[ModelSpec]:
        with self._lock:
            return iter(tuple(self._models.values()))

    def __len__(self) -> int:
        return len(self._models)

    def __contains__(self, model_id: object) -> bool:
        return model_id in self._models

    @property
    def models(self) -> tuple[ModelSpec, ...]:
        """Every model, in the order added."""
        with self._lock:
            return tuple(self._models.values())

    def ids(self) -> list[str]:
        """The model ids, in the order added."""
        with self._lock:
            return list(self._models)

    def domains(self) -> list[str]:
        """The domains that have a model, sorted."""
        with self._lock:
            return sorted({m.domain for m in self._models.values()})

    def _catalogue(self) -> str:
        with self._lock:
            if not self._models:
                return "the registry is empty"
            return "registered models: " + ", ".join(
                f"{m.id} ({m.domain})" for m in self._models.values()
            )

    def get(self, model_id: str) -> ModelSpec:
        """Return the model with this id.

        Raises:
            UnknownModelError: No such id; the message lists the registered models.

        """
        with self._lock:
            spec = self._models.get(model_id)
        if spec is None:
            raise UnknownModelError(
                f"unknown model {model_id!r} for lec {self.lec!r}; {self._catalogue()}"
            )
        return spec

    def for_domain(self, domain: str) -> ModelSpec:
        """Return the model of a domain (one serves each: :meth:`add` refuses a second).

        Raises:
            UnknownModelError: No model serves the domain; the message lists the domains.

        """
        with self._lock:
            spec = next((m for m in self._models.values() if m.domain == domain), None)
        if spec is None:
            known = ", ".join(self.domains()) or "none"
            raise UnknownModelError(
                f"no model for domain {domain!r} in lec {self.lec!r}; domains with a model: {known}"
            )
        return spec

    @property
    def default(self) -> ModelSpec:
        """The model of the ``default`` domain: what runs when nothing adverse is perceived."""
        return self.for_domain(DEFAULT_DOMAIN)

    def resolve(self, model_id: str | None = None, domain: str | None = None) -> ModelSpec:
        """Return the model a swap request names: by id, by domain, or the default.

        With both, the model must be of that domain. With neither, the default model.

        Raises:
            UnknownModelError: Unknown id or a domain without a model (listing what exists).
            ModelRegistryError: The id's model is of another domain.

        """
        if model_id is not None:
            spec = self.get(model_id)
            if domain is not None and spec.domain != domain:
                raise ModelRegistryError(
                    f"model {model_id!r} is for domain {spec.domain!r}, not {domain!r}; "
                    "give the model or the domain, or a matching pair"
                )
            return spec
        return self.for_domain(domain if domain is not None else DEFAULT_DOMAIN)

    def clean_f1(self, model_id: str) -> float | None:
        """The clean F1 of a model (``None`` if unknown or not registered)."""
        with self._lock:
            spec = self._models.get(model_id)
        return None if spec is None else spec.clean_f1

    # -- trust and loading -----------------------------------------------------------------
    def files(self, model: str | ModelSpec) -> list[Path]:
        """The files loading a model reads: its ``file`` and what its loader's ``files()`` adds.

        Raises:
            UnknownModelError: An unknown id.
            ModelRegistryError: The loader's ``files()`` failed.

        """
        spec = model if isinstance(model, ModelSpec) else self.get(model)
        if self._loader is not None or spec.loader is None:
            return [spec.file]
        try:
            return architecture_files(ARCHITECTURES.create(spec.loader), spec.file, spec.options)
        except Exception as exc:
            raise ModelRegistryError(
                f"model {spec.id!r}: loader {spec.loader!r} cannot say which files it reads: "
                f"{type(exc).__name__}: {exc}"
            ) from exc

    def verify(self, model: str | ModelSpec) -> str:
        """Check every file the model's loader reads against the registry's sha256.

        Returns:
            The digest of the model's ``file``.

        Raises:
            ModelIntegrityError: A file is missing or unreadable, its hash differs, or the
                registry pins some files and not one the loader reads.
            UnknownModelError: An unknown id.

        """
        spec = model if isinstance(model, ModelSpec) else self.get(model)
        pinned = spec.sha256 is not None or bool(spec.pins)
        pins: dict[Path, str | None] = {p.resolve(): digest for p, digest in spec.pins.items()}
        pins[spec.file.resolve()] = spec.sha256
        digests: dict[Path, str] = {}
        for path in self.files(spec):
            expected = pins.get(path.resolve())
            try:
                digests[path] = digest = sha256_file(path)
            except OSError as exc:
                raise ModelIntegrityError(
                    f"model {spec.id!r}: cannot read {path}: {exc.strerror or exc}"
                ) from exc
            if expected is None and pinned:
                raise ModelIntegrityError(
                    f"model {spec.id!r}: its loader {spec.loader!r} reads {path}, which the "
                    f"registry does not pin; add its sha256 ({digest}) to the entry's sha256"
                )
            if expected is not None and digest != expected:
                raise ModelIntegrityError(
                    f"model {spec.id!r}: sha256 mismatch for {path}: the registry says "
                    f"{expected[:12]}…, the file is {digest[:12]}… (a corrupt copy or a "
                    "changed file; copy the model again, or update the registry if the change "
                    "is intended)"
                )
        return digests.get(spec.file) or sha256_file(spec.file)

    def load(self, model: str | ModelSpec) -> Detector:
        """Verify a model's files, then load it with its loader.

        The loader is the registry's ``loader`` callable when one was given in code, else
        the entry's ``loader`` plugin (``load(file, options)``), else ``load_detector``.

        Raises:
            ModelIntegrityError: A missing file or a sha256 mismatch (nothing was loaded).
            ModelLoadError: The loader refused the file (corrupt weights, bad sidecar …) or
                returned something that is not a :class:`~anunnaki.lec.Detector`.
            MissingExtraError: The loader needs an extra (``anunnaki[vision]``).

        """
        spec = model if isinstance(model, ModelSpec) else self.get(model)
        self.verify(spec)
        try:
            if self._loader is not None:
                detector: object = self._loader(spec.file)
            elif spec.loader is not None:
                detector = ARCHITECTURES.create(spec.loader).load(spec.file, dict(spec.options))
            else:
                detector = _default_loader(spec.file)
        except MissingExtraError:
            raise
        except Exception as exc:
            raise ModelLoadError(
                f"model {spec.id!r}: the loader refused {spec.file}: {type(exc).__name__}: {exc}"
            ) from exc
        if not isinstance(detector, Detector):
            missing = [a for a in ("model_id", "classes", "domain") if not hasattr(detector, a)]
            if not callable(getattr(detector, "detect", None)):
                missing.append("detect()")
            raise ModelLoadError(
                f"model {spec.id!r}: the loader returned {type(detector).__name__}, which is "
                f"not a Detector: it has no {', no '.join(missing)}"
            )
        if detector.model_id != spec.id:
            log.info(
                "model %r: its file calls itself %r; the registry's id is what is published",
                spec.id,
                detector.model_id,
            )
        return detector

    def _file_error(self, key: str, message: str, hint: str) -> ModelFileError:
        """An error about the top-level ``key`` of the registry file, at its line."""
        line = self._lines.line((key,)) if self._lines is not None else None
        return ModelFileError(
            message, path=self.source or "<registry>", line=line, element=key, hint=hint
        )

    def _entry_error(
        self, model_id: str, message: str, field: str | None, hint: str
    ) -> ModelFileError:
        index = self._where.get(model_id, 0)
        return _entry_error(
            message, lines=self._lines, path=self.source or "<registry>", index=index,
            field=field, hint=hint,
        )  # fmt: skip


def _default_loader(path: Path) -> Detector:
    try:
        from anunnaki.lec._detector import load_detector
    except ImportError as exc:  # pragma: no cover - numpy/pydantic are core dependencies
        raise MissingExtraError("the detector", "vision") from exc
    detector: Detector = load_detector(path)
    return detector


def _entry_error(
    message: str, *, lines: LineMap | None, path: str, index: int, field: str | None, hint: str
) -> ModelFileError:
    loc: tuple[str | int, ...] = ("models", index) + ((field,) if field else ())
    element = f"models[{index}]" + (f".{field}" if field else "")
    return ModelFileError(
        message,
        path=path,
        line=lines.line(loc) if lines is not None else None,
        element=element,
        hint=hint,
    )
