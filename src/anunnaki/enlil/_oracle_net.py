"""The behavior oracle's network and its model file (safetensors + JSON sidecar).

The oracle reads one camera frame and answers three questions (paper §3.2): which behavior
category the assessed model is in (0, 1, 2), what context it perceives (the phenomenon's
parameters normalised to ``[0, 1]^d``) and, when one oracle covers several phenomena, which
one. The network is small on purpose (about 60 k parameters, under 3 ms per 128 × 128 frame
on one thread): four strided convolutions, global mean and standard-deviation pooling (fog,
brightness and colour shifts are global statistics), plus the frame's per-channel mean and
standard deviation and one fully connected layer feeding three heads.

Architectures are a plugin slot (:data:`ORACLE_ARCHITECTURES`); a model file names its
architecture and options in the sidecar, so a file written by another architecture loads
through the same code. Files are loaded without pickle: the sidecar is JSON validated by
pydantic, the weights are safetensors whose sha256 the sidecar pins. torch is imported only
when a network is built (the ``vision`` extra).
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from anunnaki.enlil._context import EnlilError
from anunnaki.enlil._oracle_lookup import (
    LOOKUP_PREFIX,
    ContextLookup,
    LookupSpec,
    boosted,
    lookup_probabilities,
    mixed_probabilities,
)
from anunnaki.errors import MissingExtraError, ModelFileError
from anunnaki.lec import sha256_file
from anunnaki.plugins import Registry

__all__ = [
    "CLEAR",
    "ORACLE_ARCHITECTURES",
    "ORACLE_FORMAT",
    "OracleCard",
    "OracleModel",
    "OraclePrediction",
    "PhenomenonSpec",
    "load_oracle",
    "oracle_paths",
]

ORACLE_FORMAT = "anunnaki-oracle/1"
#: The format of an oracle whose file also holds a context lookup (:class:`LookupSpec`).
ORACLE_FORMAT_LOOKUP = "anunnaki-oracle/2"
#: The phenomenon head's name for an unperturbed frame.
CLEAR = "clear"

#: Oracle network architectures: name → ``build(n_params, n_phenomena, **options) -> nn.Module``
#: whose ``forward(x)`` returns ``(category_logits [B, 3], params [B, d], phenomenon_logits
#: [B, P])`` for ``x`` ``[B, 3, H, W]`` float in ``[0, 1]``.
ORACLE_ARCHITECTURES: Registry[Any] = Registry(
    "oracle architecture", group="anunnaki.oracle_architectures", error=EnlilError
)
ORACLE_ARCHITECTURES.register_lazy("small_cnn", "anunnaki.enlil._oracle_net:build_small_cnn")


def _torch() -> Any:
    try:
        import torch
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise MissingExtraError("the behavior oracle's network (torch)", "vision") from exc
    return torch


def build_small_cnn(n_params: int, n_phenomena: int, *, width: int = 16, hidden: int = 64) -> Any:
    """The default oracle network (see the module's docstring)."""
    torch = _torch()
    nn = torch.nn

    def block(cin: int, cout: int) -> Any:
        return nn.Sequential(
            nn.Conv2d(cin, cout, 3, stride=2, padding=1, bias=False),
            nn.BatchNorm2d(cout),
            nn.ReLU(inplace=True),
        )

    class SmallOracleCNN(nn.Module):  # type: ignore[misc,name-defined]
        def __init__(self) -> None:
            super().__init__()
            w = width
            self.features = nn.Sequential(
                block(3, w), block(w, 2 * w), block(2 * w, 3 * w), block(3 * w, 4 * w)
            )
            feats = 2 * 4 * w + 6
            self.trunk = nn.Sequential(nn.Linear(feats, hidden), nn.ReLU(inplace=True))
            self.category = nn.Linear(hidden, 3)
            self.params = nn.Linear(hidden, max(n_params, 1))
            self.phenomenon = nn.Linear(hidden, max(n_phenomena, 1))

        def forward(self, x: Any) -> tuple[Any, Any, Any]:
            stats = torch.cat(_mean_std(x), dim=1)
            f = self.features(x)
            pooled = torch.cat([*_mean_std(f), stats], dim=1)
            h = self.trunk(pooled)
            return self.category(h), torch.sigmoid(self.params(h)), self.phenomenon(h)

    return SmallOracleCNN()


def _mean_std(x: Any) -> tuple[Any, Any]:
    """Per channel ``(mean, std)`` of ``x`` ``[B, C, H, W]`` (unbiased std, as ``Tensor.std``).

    Two passes (the mean, then the squared deviations): the same figures as
    ``x.mean(dim=(2, 3)), x.std(dim=(2, 3))`` to float rounding, in a sixth of the time
    for one frame (torch's ``std`` kernel took 0.37 ms of a 128 x 128 frame's 1.8 ms).
    """
    mean = x.mean(dim=(2, 3), keepdim=True)
    d = x - mean
    n = x.shape[2] * x.shape[3]
    std = (d * d).sum(dim=(2, 3)).div_(max(n - 1, 1)).sqrt_()
    return mean.flatten(1), std


class PhenomenonSpec(BaseModel):
    """One phenomenon an oracle covers: its name and parameter names (vector order)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str
    param_names: list[str]


class OracleCard(BaseModel):
    """The JSON sidecar of an oracle file (``NAME.json`` next to ``NAME.safetensors``).

    Attributes:
        format: ``anunnaki-oracle/1``; ``anunnaki-oracle/2`` when it has a ``lookup``.
        model_id: The id of the model whose behavior the oracle predicts.
        model_sha256: That model's weights sha256 (empty when unknown).
        phenomena: The phenomena covered; the phenomenon head's classes are ``clear`` then
            these names, in order.
        classes: The behavior categories (``[0, 1, 2]``).
        thresholds: The relative F1 drops of categories 1 and 2 the labels were made with.
        architecture: The :data:`ORACLE_ARCHITECTURES` name; ``options`` its options.
        input_size: Frames are resized to this ``[H, W]`` before the network.
        temperature: Temperature of the category logits (fitted on val; 1 = none).
        weights_sha256: sha256 of the safetensors file, checked before it is read.
        metrics: Figures measured after training (val accuracy, macro-F1, ECE …).
        training: How it was trained (contexts source, frames, epochs, seed …).
        lookup: The perceived context → category lookup mixed with the category head
            (:mod:`anunnaki.enlil._oracle_lookup`), or ``None`` (the head alone; every
            ``anunnaki-oracle/1`` file).

    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    format: Literal["anunnaki-oracle/1", "anunnaki-oracle/2"] = "anunnaki-oracle/1"
    model_id: str
    model_sha256: str = ""
    phenomena: list[PhenomenonSpec] = Field(min_length=1)
    classes: list[int] = Field(default_factory=lambda: [0, 1, 2])
    thresholds: tuple[float, float] = (0.05, 0.10)
    architecture: str = "small_cnn"
    options: dict[str, int | float | str | bool] = Field(default_factory=dict)
    input_size: tuple[int, int] = (128, 128)
    temperature: float = Field(default=1.0, gt=0.0)
    weights_sha256: str = ""
    metrics: dict[str, Any] = Field(default_factory=dict)
    training: dict[str, Any] = Field(default_factory=dict)
    lookup: LookupSpec | None = None

    @property
    def max_params(self) -> int:
        """Width of the regression head: the largest parameter count of the phenomena."""
        return max(len(p.param_names) for p in self.phenomena)

    @property
    def phenomenon_classes(self) -> list[str]:
        """The phenomenon head's classes: ``clear`` then the phenomena."""
        return [CLEAR, *(p.name for p in self.phenomena)]

    @property
    def phenomenon_head(self) -> bool:
        """Whether the phenomenon head was trained (several phenomena, or clear vs one).

        Oracles trained before the head was trained for one phenomenon say it through
        ``training.phenomenon_head``; without the head the phenomenon is guessed from the
        category and the regressed context.
        """
        return len(self.phenomena) > 1 or bool(self.training.get("phenomenon_head"))


@dataclass(frozen=True)
class OraclePrediction:
    """What the oracle says about one frame.

    Attributes:
        category: The most probable behavior category.
        confidence: Its calibrated probability.
        probs: Calibrated probabilities of categories 0, 1, 2.
        phenomenon: The perceived phenomenon (``clear`` when none).
        params: The perceived context of that phenomenon, normalised, by parameter name.

    """

    category: int
    confidence: float
    probs: tuple[float, float, float]
    phenomenon: str
    params: dict[str, float]


def oracle_paths(path: str | Path) -> tuple[Path, Path]:
    """``(NAME.safetensors, NAME.json)`` for ``NAME``, ``NAME.safetensors`` or ``NAME.json``."""
    p = Path(path)
    base = p.with_suffix("") if p.suffix in (".safetensors", ".json") else p
    # appended, not with_suffix: NAME may hold a dot ('rover-default.oracle' must not
    # become 'rover-default.safetensors', the detector's own file)
    return base.with_name(base.name + ".safetensors"), base.with_name(base.name + ".json")


def frames_to_tensor(frames: Sequence[npt.NDArray[np.uint8]], size: tuple[int, int]) -> Any:
    """``[B, 3, H, W]`` float32 tensor in ``[0, 1]``, each frame resized to *size* if needed."""
    return frames_to_uint8(frames, size).float() / 255.0


def frames_to_uint8(
    frames: Sequence[npt.NDArray[np.uint8]], size: tuple[int, int], *, channels_last: bool = False
) -> Any:
    """``[B, 3, H, W]`` ``uint8`` tensor, each frame resized to *size* if needed.

    A quarter of the memory of :func:`frames_to_tensor` (training holds thousands of
    frames); ``frames_to_uint8(f, s).float() / 255.0`` is :func:`frames_to_tensor` exactly.
    *channels_last*: in that memory layout (the frames' own, so no copy), else contiguous.
    """
    torch = _torch()
    out = np.empty((len(frames), size[0], size[1], 3), np.uint8)
    for i, frame in enumerate(frames):
        image: np.ndarray = np.asarray(frame)
        if image.ndim != 3 or image.shape[2] != 3:
            raise EnlilError(f"an oracle frame must be (H, W, 3) RGB, got shape {image.shape}")
        if image.shape[:2] != tuple(size):
            import cv2

            image = cv2.resize(image, (size[1], size[0]), interpolation=cv2.INTER_AREA)
        out[i] = image
    nchw = torch.from_numpy(out).permute(0, 3, 1, 2)
    return nchw if channels_last else nchw.contiguous()


def _softmax(z: np.ndarray) -> np.ndarray:
    """Softmax over the last axis of float logits *z*."""
    e = np.exp(z - z.max(axis=-1, keepdims=True))
    out: np.ndarray = e / e.sum(axis=-1, keepdims=True)
    return out


class OracleModel:
    """A loaded (or freshly trained) behavior oracle: a network and its card.

    Args:
        card: The sidecar.
        net: The network (``torch.nn.Module``), in eval mode after construction.
        lookup: The measured contexts the category is looked up in (used when the card
            has a ``lookup``; see :meth:`category_probabilities`).

    """

    def __init__(self, card: OracleCard, net: Any, lookup: ContextLookup | None = None) -> None:
        self.card = card
        self.net = net
        self.lookup = lookup
        self.net.eval()
        # one frame at a time runs about a tenth faster channels-last (same figures to float
        # rounding); the frames are in that layout already (H, W, 3)
        self.net.to(memory_format=_torch().channels_last)

    def __repr__(self) -> str:
        names = "+".join(p.name for p in self.card.phenomena)
        return f"OracleModel(model_id={self.card.model_id!r}, phenomena={names!r})"

    @property
    def model_id(self) -> str:
        """The assessed model's id."""
        return self.card.model_id

    def logits(
        self, frames: Sequence[npt.NDArray[np.uint8]]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Raw outputs for *frames*: category logits (untempered), params, phenomenon logits."""
        torch = _torch()
        x = frames_to_uint8(frames, self.card.input_size, channels_last=True).float() / 255.0
        with torch.inference_mode():
            cat, params, phen = self.net(x)
        return cat.numpy(), params.numpy(), phen.numpy()

    def probabilities(self, category_logits: np.ndarray) -> np.ndarray:
        """Calibrated category probabilities (softmax of the logits over the temperature)."""
        return _softmax(np.asarray(category_logits, np.float64) / self.card.temperature)

    def category_probabilities(
        self, category_logits: np.ndarray, params: np.ndarray, phenomenon_logits: np.ndarray
    ) -> np.ndarray:
        """``[B, 3]`` the oracle's category probabilities from the network's raw outputs.

        The calibrated category head (:meth:`probabilities`), mixed with the lookup of the
        perceived context when the oracle has one (``card.lookup``, see
        :mod:`anunnaki.enlil._oracle_lookup`): ``w · head + (1 - w) · lookup``, category 1
        boosted by the card's ``lookup.boost``.
        """
        probs = self.probabilities(category_logits)
        spec = self.card.lookup
        if spec is None or self.lookup is None:
            return probs
        if spec.weight < 1.0:
            names = [p.name for p in self.card.phenomena]
            phenomena = _softmax(np.asarray(phenomenon_logits, np.float64))
            looked = lookup_probabilities(self.lookup, names, params, phenomena)
            probs = mixed_probabilities(probs, looked, spec.weight)
        return boosted(probs, spec.boost)

    def predict(self, frames: Sequence[npt.NDArray[np.uint8]]) -> list[OraclePrediction]:
        """Assess each frame; see :class:`OraclePrediction`."""
        if len(frames) == 0:
            return []
        cat, params, phen = self.logits(frames)
        probs = self.category_probabilities(cat, params, phen)
        names = self.card.phenomenon_classes
        out = []
        for i in range(len(frames)):
            category = int(np.argmax(probs[i]))
            which = int(np.argmax(phen[i])) if self.card.phenomenon_head else int(category > 0)
            name = names[which] if which < len(names) else CLEAR
            values: dict[str, float] = {}
            if name != CLEAR:
                spec = self.card.phenomena[which - 1]
                values = {n: float(params[i, j]) for j, n in enumerate(spec.param_names)}
            p = tuple(float(v) for v in probs[i])
            out.append(
                OraclePrediction(
                    category, float(probs[i, category]), (p[0], p[1], p[2]), name, values
                )
            )
        return out

    def save(self, path: str | Path) -> str:
        """Write ``NAME.safetensors`` + ``NAME.json``; return the weights' sha256."""
        from safetensors.numpy import save_file

        wpath, spath = oracle_paths(path)
        wpath.parent.mkdir(parents=True, exist_ok=True)
        tensors: dict[str, np.ndarray] = {
            k: v.detach().cpu().numpy().copy() for k, v in self.net.state_dict().items()
        }
        if self.card.lookup is not None and self.lookup is not None:
            tensors.update(self.lookup.tensors())
            self.card = self.card.model_copy(update={"format": ORACLE_FORMAT_LOOKUP})
        tmp = wpath.with_name(wpath.name + ".tmp")
        save_file(tensors, str(tmp))
        tmp.replace(wpath)
        digest = sha256_file(wpath)
        self.card = self.card.model_copy(update={"weights_sha256": digest})
        text = json.dumps(self.card.model_dump(mode="json"), indent=2, sort_keys=True) + "\n"
        tmp_json = spath.with_name(spath.name + ".tmp")
        tmp_json.write_text(text, encoding="utf-8")
        tmp_json.replace(spath)
        return digest


def build_network(card: OracleCard) -> Any:
    """A fresh network for *card*'s architecture, options and heads."""
    factory = ORACLE_ARCHITECTURES.factory(card.architecture)
    return factory(card.max_params, len(card.phenomenon_classes), **card.options)


def _read_card(spath: Path) -> OracleCard:
    try:
        raw = json.loads(spath.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ModelFileError(
            f"cannot read the oracle's sidecar: {exc.strerror or exc}",
            path=str(spath),
            hint="an oracle is NAME.safetensors with NAME.json next to it",
        ) from None
    except json.JSONDecodeError as exc:
        raise ModelFileError(
            f"the oracle's sidecar is not JSON: {exc.msg}",
            path=str(spath),
            line=exc.lineno,
            hint="copy the oracle again or retrain it (anunnaki oracle train)",
        ) from None
    try:
        return OracleCard.model_validate(raw)
    except ValidationError as exc:
        first = exc.errors(include_url=False)[0]
        where = ".".join(str(x) for x in first["loc"]) or "(top level)"
        raise ModelFileError(
            f"bad oracle sidecar at {where}: {first['msg']}",
            path=str(spath),
            element=where,
            hint=f"an oracle sidecar has format {ORACLE_FORMAT!r} (or "
            f"{ORACLE_FORMAT_LOOKUP!r} with a lookup); retrain the oracle",
        ) from None


def load_oracle(path: str | Path, *, sha256: str | None = None) -> OracleModel:
    """Load an oracle file without pickle: sidecar validated, weights hash checked.

    Args:
        path: ``NAME``, ``NAME.safetensors`` or ``NAME.json``.
        sha256: When given (e.g. from the model registry), the weights must have it.

    Raises:
        ModelFileError: A missing or malformed sidecar, a hash mismatch, or weights that do
            not fit the architecture the sidecar names.

    """
    wpath, spath = oracle_paths(path)
    card = _read_card(spath)
    if not wpath.is_file():
        raise ModelFileError(
            "the oracle's weights are missing", path=str(wpath), hint="copy NAME.safetensors too"
        )
    digest = sha256_file(wpath)
    for expected, who in ((card.weights_sha256, "its sidecar"), (sha256, "the model registry")):
        if expected and digest != expected.lower():
            raise ModelFileError(
                f"sha256 mismatch: {who} says {expected[:12]}…, the file is {digest[:12]}…",
                path=str(wpath),
                hint="copy the oracle again, or update the pinned sha256 if it was retrained",
            )
    from safetensors import SafetensorError
    from safetensors.numpy import load_file

    try:
        arrays = load_file(str(wpath))
    except SafetensorError as exc:
        raise ModelFileError(
            f"not a valid safetensors file: {exc}", path=str(wpath), hint="copy it again"
        ) from None
    torch = _torch()
    net = build_network(card)
    lookup = None
    if card.lookup is not None:
        try:
            lookup = ContextLookup.from_tensors(arrays, card.lookup, source=str(wpath))
        except EnlilError as exc:
            raise ModelFileError(
                str(exc), path=str(wpath), hint="copy NAME.safetensors and NAME.json again"
            ) from None
    weights = {k: v for k, v in arrays.items() if not k.startswith(LOOKUP_PREFIX)}
    try:
        net.load_state_dict({k: torch.from_numpy(np.array(v)) for k, v in weights.items()})
    except RuntimeError as exc:
        raise ModelFileError(
            f"the weights do not fit architecture {card.architecture!r}: "
            f"{str(exc).splitlines()[0]}",
            path=str(wpath),
            hint="the sidecar and the weights come from different trainings; copy both again",
        ) from None
    return OracleModel(card, net, lookup)


def expected_calibration_error(probs: np.ndarray, labels: np.ndarray, bins: int = 10) -> float:
    """ECE of the top-class confidence over *bins* equal-width bins."""
    if len(labels) == 0:
        return math.nan
    conf = probs.max(axis=1)
    correct = probs.argmax(axis=1) == labels
    edges = np.linspace(0.0, 1.0, bins + 1)
    ece = 0.0
    for lo, hi in itertools.pairwise(edges):
        mask = (conf > lo) & (conf <= hi)
        if mask.any():
            ece += mask.mean() * abs(float(correct[mask].mean()) - float(conf[mask].mean()))
    return float(ece)


def classification_metrics(
    predicted: Sequence[int] | np.ndarray, truth: Sequence[int] | np.ndarray, n: int = 3
) -> dict[str, Any]:
    """Accuracy, macro-F1 (over the classes present in truth or predictions), recall, confusion."""
    pred = np.asarray(predicted, np.int64)
    true = np.asarray(truth, np.int64)
    confusion = np.zeros((n, n), np.int64)
    for t, p in zip(true, pred, strict=True):
        confusion[t, p] += 1
    f1s, recall = [], {}
    for c in range(n):
        tp = confusion[c, c]
        support, predicted_c = confusion[c].sum(), confusion[:, c].sum()
        if support:
            recall[str(c)] = float(tp / support)
        if support or predicted_c:
            f1s.append(2 * tp / (support + predicted_c))
    return {
        "accuracy": float((pred == true).mean()) if len(true) else math.nan,
        "macro_f1": float(np.mean(f1s)) if f1s else math.nan,
        "per_category_recall": recall,
        "confusion": confusion.tolist(),
        "n": len(true),
    }
