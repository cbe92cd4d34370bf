"""The detector interface every LEC implements, and safe model files.

Why a ``Protocol`` and not a base class: any model — our CenterNet, a YOLO wrapper, an ONNX
session — becomes an LEC by having four attributes and one method; nothing has to inherit
from Anunnaki. The LEC node, the model manager and the assessors only ever see this face.

Model files are two files side by side: ``NAME.safetensors`` (the weights; safetensors holds
plain tensors and cannot run code when loaded) and ``NAME.json`` (the sidecar: architecture,
classes, input size, score threshold, domain, metrics and the weights' sha256). Pickle is
never used, so a model file from a stranger cannot execute anything; a changed or corrupt
weights file is refused before any tensor is read.
"""

from __future__ import annotations

import hashlib
import json
import os
import uuid
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from anunnaki._names import close_file
from anunnaki.errors import AnunnakiError, ModelFileError, validation_message
from anunnaki.plugins import Registry

__all__ = [
    "ARCHITECTURES",
    "SIDECAR_FORMAT",
    "BuildsFromCard",
    "DetectionResult",
    "Detector",
    "DetectorArchitecture",
    "DetectorError",
    "DetectorLoadError",
    "ImageBatch",
    "ModelCard",
    "ReadsFiles",
    "architecture_files",
    "as_image_list",
    "load_detector",
    "read_card",
    "save_detector",
    "sha256_file",
    "sidecar_path",
    "update_metrics",
    "weights_path",
]

#: Value of ``format`` in every sidecar this module writes.
SIDECAR_FORMAT = "anunnaki-detector"
_FORMAT_VERSION = 1
_MAX_SIDECAR_BYTES = 1 << 20

#: What :meth:`Detector.detect` accepts: one ``(H, W, 3)`` image, a ``(B, H, W, 3)`` batch,
#: or a sequence of ``(H, W, 3)`` images (sizes may differ), all ``uint8`` RGB.
ImageBatch = npt.NDArray[np.uint8] | Sequence[npt.NDArray[np.uint8]]


class DetectorError(AnunnakiError, ValueError):
    """A detector was used wrongly (bad images, bad arguments, an object that cannot be saved)."""


class DetectorLoadError(ModelFileError):
    """A model file (weights or sidecar) is missing, corrupt, changed or of an unknown kind.

    Renders as ``file: element: message (hint: …)`` like every other user-file error.
    """


@dataclass(frozen=True)
class DetectionResult:
    """The detections in one image.

    Attributes:
        boxes: ``[N, 4]`` ``float32`` boxes ``x1, y1, x2, y2`` in pixels of the input image
            (``x2 > x1``; ``x`` grows to the right, ``y`` downwards).
        labels: ``[N]`` ``int64`` class indices into the detector's ``classes``.
        scores: ``[N]`` ``float32`` confidences in ``[0, 1]``.

    Arrays are converted to those dtypes on construction; mismatched lengths raise
    :class:`DetectorError`.

    """

    boxes: npt.NDArray[np.float32]
    labels: npt.NDArray[np.int64]
    scores: npt.NDArray[np.float32]

    def __post_init__(self) -> None:
        boxes = np.asarray(self.boxes, dtype=np.float32).reshape(-1, 4)
        labels = np.asarray(self.labels, dtype=np.int64).reshape(-1)
        scores = np.asarray(self.scores, dtype=np.float32).reshape(-1)
        if not len(boxes) == len(labels) == len(scores):
            raise DetectorError(
                f"DetectionResult: {len(boxes)} boxes, {len(labels)} labels and "
                f"{len(scores)} scores; give one label and one score per box"
            )
        object.__setattr__(self, "boxes", boxes)
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "scores", scores)

    def __len__(self) -> int:
        return len(self.labels)

    @classmethod
    def empty(cls) -> DetectionResult:
        """A result with no detections."""
        return cls(np.zeros((0, 4), np.float32), np.zeros(0, np.int64), np.zeros(0, np.float32))

    def above(self, score_threshold: float) -> DetectionResult:
        """The detections whose score is at least *score_threshold*."""
        keep = self.scores >= score_threshold
        return DetectionResult(self.boxes[keep], self.labels[keep], self.scores[keep])


@runtime_checkable
class Detector(Protocol):
    """Anything that finds objects in camera frames; implement this to make a model an LEC.

    Attributes:
        model_id: A name unique within a model registry (e.g. ``rover-default``).
        classes: Class names; ``DetectionResult.labels`` index into this tuple.
        domain: The operating domain the model is meant for: ``default``, ``fog``,
            ``low_light``, ``raindrop`` …; the model manager swaps models by domain.

    """

    model_id: str
    classes: tuple[str, ...]
    domain: str

    def detect(self, images: ImageBatch) -> list[DetectionResult]:
        """Detect objects in each image.

        Args:
            images: One ``(H, W, 3)`` ``uint8`` RGB image, a ``(B, H, W, 3)`` batch or a
                sequence of ``(H, W, 3)`` images.

        Returns:
            One :class:`DetectionResult` per image, in order (a single image gives a list
            of one). Boxes are in the pixels of the image given.

        """
        ...


def as_image_list(images: ImageBatch) -> list[npt.NDArray[np.uint8]]:
    """Normalise what :meth:`Detector.detect` accepts into a list of ``(H, W, 3)`` images.

    Raises:
        DetectorError: An image is not ``uint8`` with three channels; the message says how
            to convert.

    """
    if isinstance(images, np.ndarray):
        if images.ndim == 3:
            items: Sequence[Any] = [images]
        elif images.ndim == 4:
            items = list(images)
        else:
            raise DetectorError(
                f"expected an (H, W, 3) image or a (B, H, W, 3) batch, got shape {images.shape}"
            )
    else:
        items = list(images)
    out: list[npt.NDArray[np.uint8]] = []
    for i, image in enumerate(items):
        if not isinstance(image, np.ndarray):
            raise DetectorError(f"image {i}: expected a numpy array, got {type(image).__name__}")
        if image.ndim != 3 or image.shape[2] != 3 or image.shape[0] < 1 or image.shape[1] < 1:
            raise DetectorError(
                f"image {i}: expected shape (H, W, 3) RGB, got {image.shape}; convert grey "
                "images with np.repeat(img[..., None], 3, axis=2) and drop an alpha channel"
            )
        if image.dtype != np.uint8:
            raise DetectorError(
                f"image {i}: expected dtype uint8, got {image.dtype}; convert float images "
                "in [0, 1] with (img * 255).round().clip(0, 255).astype(np.uint8)"
            )
        out.append(image)
    return out


# -- model files -----------------------------------------------------------------------------


class ModelCard(BaseModel):
    """The JSON sidecar of a model file (``NAME.json`` next to ``NAME.safetensors``).

    Attributes:
        format: Always ``anunnaki-detector``.
        format_version: Version of this schema (1).
        model_id: See :class:`Detector`.
        architecture: Which code builds the network (``centernet``).
        arch: Architecture hyper-parameters (channel widths …), passed to the builder.
        classes: Class names, in label order.
        input_size: ``[width, height]`` the network runs at; other sizes are resized to it
            and boxes scaled back.
        score_threshold: Detections below it are dropped by ``detect`` (chosen on the
            validation split to maximise F1).
        domain: See :class:`Detector`.
        metrics: Figures measured after training (``val``/``test`` precision, recall, F1 …).
        training: How the model was made (data, epochs, seed, augmentation, seconds).
        weights: File name of the weights, relative to the sidecar.
        sha256: Hex sha256 of the weights file; checked on every load.

    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    format: str = SIDECAR_FORMAT
    format_version: int = _FORMAT_VERSION
    model_id: str = Field(min_length=1)
    architecture: str = Field(min_length=1)
    arch: dict[str, Any] = Field(default_factory=dict)
    classes: tuple[str, ...] = Field(min_length=1)
    input_size: tuple[int, int]
    score_threshold: float = Field(ge=0.0, le=1.0)
    domain: str = Field(default="default", min_length=1)
    metrics: dict[str, Any] = Field(default_factory=dict)
    training: dict[str, Any] = Field(default_factory=dict)
    weights: str = Field(min_length=1)
    sha256: str = Field(pattern=r"^[0-9a-f]{64}$")


def weights_path(path: str | Path) -> Path:
    """``NAME.safetensors`` for ``NAME.safetensors``, ``NAME.json`` or ``NAME``."""
    p = Path(path)
    return p if p.suffix == ".safetensors" else p.with_suffix(".safetensors")


def sidecar_path(path: str | Path) -> Path:
    """``NAME.json`` for ``NAME.safetensors``, ``NAME.json`` or ``NAME``."""
    return weights_path(path).with_suffix(".json")


def sha256_file(path: str | Path) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _atomic_write(path: Path, write: Callable[[Path], object]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    # A model file gets the usual permissions (0666 less the umask), not the private 0600
    # of mkstemp, which safetensors' writer also uses.
    tmp = path.parent / f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp"
    try:
        write(Path(tmp))
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


# -- the plugin slot: detector architectures ----------------------------------------------


@runtime_checkable
class DetectorArchitecture(Protocol):
    """A detector plugin (slot ``anunnaki.detectors``): turns model files into a :class:`Detector`.

    A registry entry names it (``loader: NAME``), so a model that is not an anunnaki
    safetensors file — an ONNX or TensorFlow model wrapped by a third-party package — is
    deployed from a registry YAML. The class is instantiated without arguments.

    Attributes:
        name: The plugin's name (an identifier, e.g. ``centernet``, ``my_onnx``).

    Optional hooks, each a Protocol of its own checked with ``isinstance``:
    :class:`ReadsFiles` (which files ``load`` reads, so the registry pins each by sha256)
    and :class:`BuildsFromCard` (the architecture of anunnaki model files whose sidecar
    names it in ``architecture``).

    """

    name: str

    def load(self, file: Path, options: Mapping[str, Any]) -> Detector:
        """Load the model in ``file`` (absolute), configured by the entry's ``options``.

        Called by :meth:`ModelRegistry.load <anunnaki.lec.ModelRegistry.load>` after every
        file of :meth:`ReadsFiles.files` matched the registry's sha256 (when it states one),
        on the model manager's service thread. Raise an exception (any) to refuse the file;
        the registry reports it as a ``ModelLoadError`` naming the model.
        """
        ...


@runtime_checkable
class ReadsFiles(Protocol):
    """Optional hook: the files :meth:`DetectorArchitecture.load` reads (default: ``file``)."""

    def files(self, file: Path, options: Mapping[str, Any]) -> Sequence[Path]:
        """Every file ``load(file, options)`` will read, ``file`` included, as absolute paths.

        Resolve relative paths in ``options`` against ``file.parent``. The registry checks
        that each exists when the registry file is loaded, and that each matches its sha256
        before every load.
        """
        ...


@runtime_checkable
class BuildsFromCard(Protocol):
    """Optional hook: build from an anunnaki model file (safetensors + sidecar).

    :func:`load_detector` calls it for a sidecar whose ``architecture`` is the plugin's
    name, after checking the weights' sha256 and reading them as plain arrays.
    """

    def from_card(
        self, card: ModelCard, tensors: Mapping[str, npt.NDArray[Any]], weights: Path
    ) -> Detector:
        """Build the detector from its validated sidecar and its weights' arrays."""
        ...


def _check_architecture(cls: object) -> object:
    """Return ``cls`` if it can be a detector architecture plugin, else raise."""
    if not isinstance(cls, type):
        raise DetectorError(
            f"{cls!r} is not a class; register a detector architecture class (with a name "
            "and load(file, options))"
        )
    if not callable(getattr(cls, "load", None)):
        raise DetectorError(
            f"{cls.__name__} is not a detector architecture: it has no load(file, options) method"
        )
    return cls


#: Detector architectures (plugin slot ``anunnaki.detectors``): what a registry entry's
#: ``loader`` and a sidecar's ``architecture`` name. Built-in ``centernet`` is imported on
#: first use (torch); third parties register a class under the entry-point group.
ARCHITECTURES: Registry[DetectorArchitecture] = Registry(
    "detector architecture",
    group="anunnaki.detectors",
    kind=DetectorArchitecture,
    check=_check_architecture,
    error=DetectorError,
    logger="anunnaki.lec",
)
ARCHITECTURES.register_lazy("centernet", "anunnaki.lec._centernet:CenterNetArchitecture")


def architecture_files(
    architecture: DetectorArchitecture, file: Path, options: Mapping[str, Any]
) -> list[Path]:
    """The files ``architecture.load(file, options)`` reads: its :class:`ReadsFiles` hook.

    Without the hook, ``[file]``. Raises :class:`DetectorError` when the hook returns
    something other than paths.
    """
    if not isinstance(architecture, ReadsFiles):
        return [file]
    try:
        found = [Path(f) for f in architecture.files(file, options)]
    except TypeError as exc:
        raise DetectorError(
            f"detector architecture {architecture.name!r}: files() must return paths: {exc}"
        ) from None
    return [f if f.is_absolute() else file.parent / f for f in found]


def save_detector(det: Detector, path: str | Path) -> str:
    """Write *det* as ``NAME.safetensors`` + ``NAME.json``; return the weights' sha256.

    Both files are written atomically (a temporary file renamed into place), weights first,
    so a reader never sees a sidecar whose hash does not match.

    Args:
        det: A detector that can export itself (our :class:`CenterNetDetector`).
        path: ``NAME.safetensors`` (or ``NAME``/``NAME.json``; the suffixes are fixed).

    Raises:
        DetectorError: *det* cannot be saved (a third-party detector has its own format).

    """
    exporter = getattr(det, "export_state", None)
    if not callable(exporter):
        raise DetectorError(
            f"{type(det).__name__} cannot be saved by anunnaki: it has no export_state(); "
            "save it in its own format and wrap it with a Detector adapter"
        )
    card_fields, tensors = exporter()
    from safetensors.numpy import save_file

    wpath = weights_path(path)
    _atomic_write(wpath, lambda tmp: save_file(tensors, str(tmp)))
    digest = sha256_file(wpath)
    card = ModelCard(**{**card_fields, "weights": wpath.name, "sha256": digest})
    text = json.dumps(card.model_dump(mode="json"), indent=2, sort_keys=False) + "\n"
    _atomic_write(sidecar_path(path), lambda tmp: tmp.write_text(text, encoding="utf-8"))
    return digest


def update_metrics(path: str | Path, metrics: Mapping[str, Any]) -> ModelCard:
    """Replace the ``metrics`` of a model file's sidecar; the weights are not touched.

    For re-measuring a model (new data, a changed F1 rule) without retraining it. The
    weights' hash is checked first, so the figures are only ever written next to the
    weights they were measured on.

    Returns:
        The new card.

    Raises:
        DetectorLoadError: The sidecar is invalid or the weights do not match its hash.

    """
    card = read_card(path)
    wpath = checked_weights(path, card)
    if sha256_file(wpath) != card.sha256:
        raise DetectorLoadError(
            "the weights are missing or do not match the sidecar's sha256; metrics not updated",
            path=wpath,
            hint="re-save the model with anunnaki.lec.save_detector",
        )
    new = card.model_copy(update={"metrics": dict(metrics)})
    text = json.dumps(new.model_dump(mode="json"), indent=2, sort_keys=False) + "\n"
    _atomic_write(sidecar_path(path), lambda tmp: tmp.write_text(text, encoding="utf-8"))
    return new


_MAX_SIDECAR_DEPTH = 32


def _depth(value: Any) -> int:
    """How deeply JSON containers nest in ``value`` (iterative: no recursion limit)."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if not isinstance(item, dict | list):
            continue
        children = item.values() if isinstance(item, dict) else item
        deepest = max(deepest, depth)
        stack.extend((child, depth + 1) for child in children)
    return deepest


def read_card(path: str | Path) -> ModelCard:
    """Read and validate the sidecar of a model file (no weights are read).

    Raises:
        DetectorLoadError: The sidecar is missing, not JSON or not a valid model card.

    """
    spath = sidecar_path(path)
    if not spath.is_file():
        given = Path(path) if Path(path).suffix in (".safetensors", ".json") else weights_path(path)
        if not given.exists():  # the file named is missing, not only its sidecar
            raise model_not_found(given)
        raise DetectorLoadError(
            "model sidecar not found",
            path=spath,
            hint=f"a model is two files, {weights_path(path).name} and {spath.name}; "
            "copy both, or re-save with anunnaki.lec.save_detector; a model in another "
            "format is loaded by the plugin a model registry entry names (loader: NAME, "
            "docs/detector.md)",
        )
    raw = spath.read_bytes()
    if len(raw) > _MAX_SIDECAR_BYTES:
        raise DetectorLoadError(
            f"sidecar is {len(raw)} bytes, more than the {_MAX_SIDECAR_BYTES} allowed",
            path=spath,
            hint="a model sidecar is a small JSON file; this is not one",
        )
    try:
        data = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        line = getattr(exc, "lineno", None)
        raise DetectorLoadError(
            f"sidecar is not valid JSON: {exc}", path=spath, line=line, hint="re-save the model"
        ) from None
    except RecursionError:
        raise DetectorLoadError(
            "sidecar is nested too deeply to be a model card",
            path=spath,
            hint="a model sidecar is a small, flat JSON file; re-save the model",
        ) from None
    if _depth(data) > _MAX_SIDECAR_DEPTH:
        raise DetectorLoadError(
            f"sidecar is nested more than {_MAX_SIDECAR_DEPTH} levels deep",
            path=spath,
            hint="a model sidecar is a small, flat JSON file; re-save the model",
        )
    if not isinstance(data, dict) or data.get("format") != SIDECAR_FORMAT:
        raise DetectorLoadError(
            f"not an anunnaki detector sidecar (format is not {SIDECAR_FORMAT!r})",
            path=spath,
            element="format",
            hint="a model in another format is loaded by the plugin a model registry entry "
            "names (loader: NAME, docs/detector.md)",
        )
    if data.get("format_version") != _FORMAT_VERSION:
        raise DetectorLoadError(
            f"sidecar format_version {data.get('format_version')!r} is not supported "
            f"(this anunnaki reads {_FORMAT_VERSION})",
            path=spath,
            element="format_version",
            hint="upgrade anunnaki or re-save the model",
        )
    try:
        return ModelCard.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        where = ".".join(str(p) for p in err["loc"])
        raise DetectorLoadError(
            validation_message(err),
            path=spath,
            element=where,
            hint="fix the field or re-save the model",
        ) from None


def model_not_found(path: Path, what: str = "model file") -> DetectorLoadError:
    """The error for a model file that is not there, with a close name in its folder."""
    close = close_file(path)
    if close is not None:
        hint = f"did you mean {close}?"
    elif not path.parent.is_dir():
        hint = f"there is no folder {path.parent}"
    else:
        hint = "check the path; a model is NAME.safetensors with its sidecar NAME.json"
    return DetectorLoadError(f"{what} not found", path=path, hint=hint)


def checked_weights(path: str | Path, card: ModelCard) -> Path:
    """The weights file of the model *path* names: ``NAME.safetensors``, and no other.

    A sidecar describes the weights file of its own name (``NAME.json`` ↔
    ``NAME.safetensors``, as :func:`save_detector` writes them). One whose ``weights``
    names another file is a copied sidecar: loading what it names would measure another
    model than the file given, so it is refused.

    Raises:
        DetectorLoadError: The sidecar names another file, or the weights are missing.

    """
    spath = sidecar_path(path)
    wpath = weights_path(path)
    if Path(card.weights).name != card.weights:
        raise DetectorLoadError(
            f"weights {card.weights!r} must be a bare file name next to the sidecar",
            path=spath,
            element="weights",
            hint="models are self-contained folders; move the weights next to the sidecar",
        )
    if card.weights != wpath.name:
        raise DetectorLoadError(
            f"the sidecar names the weights {card.weights!r}, not {wpath.name!r}: it is "
            "another model's sidecar, copied or renamed; nothing was loaded",
            path=spath,
            element="weights",
            hint=f"a model is NAME.safetensors with its own NAME.json; give {card.weights} "
            f"for the model this sidecar describes, or re-save the model of {wpath.name} "
            "with anunnaki.lec.save_detector",
        )
    if not wpath.is_file():
        raise model_not_found(wpath, "model weights")
    return wpath


def load_detector(path: str | Path) -> Detector:
    """Load a model file safely: sidecar checked, weights hash checked, then safetensors.

    Args:
        path: ``NAME.safetensors`` or ``NAME.json`` (the other file must sit next to it).
            The weights read are ``NAME.safetensors``, always: a sidecar whose ``weights``
            names another file is refused (a copied sidecar would load another model).

    Returns:
        A ready :class:`Detector` in inference mode (our :class:`CenterNetDetector` for the
        ``centernet`` architecture).

    Raises:
        DetectorLoadError: A file is missing, the sidecar is invalid or names other weights,
            the weights' sha256 differs from the sidecar's, the weights are not valid
            safetensors, or they do not fit the architecture. The message names the file.

    """
    card = read_card(path)
    spath = sidecar_path(path)
    wpath = checked_weights(path, card)
    digest = sha256_file(wpath)
    if digest != card.sha256:
        raise DetectorLoadError(
            f"sha256 mismatch: the sidecar says {card.sha256[:12]}…, the file is {digest[:12]}…",
            path=wpath,
            element="sha256",
            hint="the weights changed after the model was saved (corrupt copy or tampering); "
            "copy the model again or re-save it",
        )
    if card.architecture not in ARCHITECTURES:
        raise DetectorLoadError(
            f"unknown architecture {card.architecture!r}; known: "
            f"{', '.join(ARCHITECTURES.names())}",
            path=spath,
            element="architecture",
            hint="install the package that provides it (entry-point group anunnaki.detectors), "
            "or wrap the model in your own Detector",
        )
    architecture = ARCHITECTURES.create(card.architecture)
    if not isinstance(architecture, BuildsFromCard):
        raise DetectorLoadError(
            f"the detector architecture {card.architecture!r} does not build from anunnaki "
            "model files (it has no from_card)",
            path=spath,
            element="architecture",
            hint=f"name it as the entry's loader in the model registry (loader: "
            f"{card.architecture}) and give its own model file",
        )
    from safetensors import SafetensorError
    from safetensors.numpy import load_file

    try:
        tensors = load_file(str(wpath))
    except (SafetensorError, OSError, ValueError) as exc:
        raise DetectorLoadError(
            f"not a valid safetensors file: {exc}", path=wpath, hint="copy the model again"
        ) from None
    for name, tensor in tensors.items():
        if tensor.dtype.kind in "fc" and not np.isfinite(tensor).all():
            raise DetectorLoadError(
                f"tensor {name!r} holds non-finite values (NaN or infinity)",
                path=wpath,
                element=name,
                hint="the training diverged or the file was tampered with; retrain or copy "
                "the model again",
            )
    return architecture.from_card(card, tensors, wpath)
