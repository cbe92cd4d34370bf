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

import json
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
from anunnaki.errors import MissingExtraError, ModelFileError, validation_message
from anunnaki.lec import sha256_file
from anunnaki.plugins import Registry

__all__ = [
    "CLEAR",
    "ORACLE_ARCHITECTURES",
    "ORACLE_FORMAT",
    "DropSpec",
    "NetOutputs",
    "OracleCard",
    "OracleModel",
    "OraclePrediction",
    "PhenomenonSpec",
    "load_oracle",
    "oracle_paths",
    "tempered",
]

ORACLE_FORMAT = "anunnaki-oracle/1"
#: The format of an oracle whose file also holds a context lookup (:class:`LookupSpec`).
ORACLE_FORMAT_LOOKUP = "anunnaki-oracle/2"
#: The phenomenon head's name for an unperturbed frame.
CLEAR = "clear"

#: Oracle network architectures: name → ``build(n_params, n_phenomena, **options) -> nn.Module``
#: whose ``forward(x)`` returns ``(category_logits [B, 3], params [B, d], phenomenon_logits
#: [B, P])`` for ``x`` ``[B, 3, H, W]`` float in ``[0, 1]``, and a fourth ``drop [B]`` (the
#: predicted relative F1 drop, uncalibrated) when built with ``drop_head=True``.
ORACLE_ARCHITECTURES: Registry[Any] = Registry(
    "oracle architecture", group="anunnaki.oracle_architectures", error=EnlilError
)
ORACLE_ARCHITECTURES.register_lazy("small_cnn", "anunnaki.enlil._oracle_net:build_small_cnn")
ORACLE_ARCHITECTURES.register_lazy("patch_cnn", "anunnaki.enlil._oracle_net:build_patch_cnn")


def _torch() -> Any:
    try:
        import torch
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise MissingExtraError("the behavior oracle's network (torch)", "vision") from exc
    return torch


def build_small_cnn(
    n_params: int, n_phenomena: int, *, width: int = 16, hidden: int = 64, drop_head: bool = False
) -> Any:
    """The default oracle network (see the module's docstring).

    *drop_head*: a fourth output, the predicted relative F1 drop of the model (files
    written before the head existed load without it).
    """
    torch = _torch()
    nn = torch.nn

    class SmallOracleCNN(nn.Module):  # type: ignore[misc,name-defined]
        def __init__(self) -> None:
            super().__init__()
            w = width
            self.features = nn.Sequential(
                _block(3, w), _block(w, 2 * w), _block(2 * w, 3 * w), _block(3 * w, 4 * w)
            )
            _add_heads(
                self, 2 * 4 * w + 6, hidden=hidden, n_params=n_params,
                n_phenomena=n_phenomena, drop_head=drop_head,
            )  # fmt: skip

        def forward(self, x: Any) -> tuple[Any, ...]:
            stats = torch.cat(_mean_std(x), dim=1)
            f = self.features(x)
            pooled = torch.cat([*_mean_std(f), stats], dim=1)
            return _run_heads(self, pooled)

    return SmallOracleCNN()


def build_patch_cnn(
    n_params: int,
    n_phenomena: int,
    *,
    width: int = 16,
    hidden: int = 64,
    pool: str = "max+attention",
    drop_head: bool = False,
) -> Any:
    """An oracle network that keeps spatial resolution and pools over patches.

    Three strided convolutions (1/8 of the input: a 16 x 16 map of patches for a 128 x 128
    frame, each seeing about 30 x 30 pixels), one more convolution at that resolution and a
    1 x 1 patch embedding; then, besides the global mean and standard deviation of
    :func:`build_small_cnn`, the **maximum** over patches and/or an **attention** pool (a
    softmax over per-patch scores weighting the patch features). One patch that shows a
    raindrop or a smudge decides the max and takes the attention's weight wherever it is on
    the lens; a global mean dilutes it over the whole frame.

    *pool*: ``max``, ``attention`` or ``max+attention``.
    """
    torch = _torch()
    nn = torch.nn
    kinds = pool.split("+")
    if not kinds or any(k not in ("max", "attention") for k in kinds):
        raise EnlilError(
            f"patch_cnn: pool {pool!r} is not one of 'max', 'attention', 'max+attention'"
        )
    use_max, use_attention = "max" in kinds, "attention" in kinds

    class PatchOracleCNN(nn.Module):  # type: ignore[misc,name-defined]
        def __init__(self) -> None:
            super().__init__()
            w = width
            self.features = nn.Sequential(
                _block(3, w), _block(w, 2 * w), _block(2 * w, 3 * w), _block(3 * w, 3 * w, 1)
            )
            self.embed = nn.Sequential(nn.Conv2d(3 * w, hidden, 1), nn.ReLU(inplace=True))
            self.score = nn.Conv2d(hidden, 1, 1) if use_attention else None
            feats = 2 * hidden + hidden * (int(use_max) + int(use_attention)) + 6
            _add_heads(
                self, feats, hidden=hidden, n_params=n_params, n_phenomena=n_phenomena,
                drop_head=drop_head,
            )  # fmt: skip

        def forward(self, x: Any) -> tuple[Any, ...]:
            stats = torch.cat(_mean_std(x), dim=1)
            patches = self.embed(self.features(x))  # [B, hidden, h, w]
            parts = [*_mean_std(patches), stats]
            flat = patches.flatten(2)  # [B, hidden, h*w]
            if use_max:
                parts.append(flat.amax(dim=2))
            if self.score is not None:
                weights = torch.softmax(self.score(patches).flatten(2), dim=2)  # [B, 1, h*w]
                parts.append((flat * weights).sum(dim=2))
            return _run_heads(self, torch.cat(parts, dim=1))

    return PatchOracleCNN()


def _block(cin: int, cout: int, stride: int = 2) -> Any:
    nn = _torch().nn
    return nn.Sequential(
        nn.Conv2d(cin, cout, 3, stride=stride, padding=1, bias=False),
        nn.BatchNorm2d(cout),
        nn.ReLU(inplace=True),
    )


def _add_heads(
    net: Any, feats: int, *, hidden: int, n_params: int, n_phenomena: int, drop_head: bool
) -> None:
    """The shared trunk and heads: category, context, phenomenon (and the drop)."""
    nn = _torch().nn
    net.trunk = nn.Sequential(nn.Linear(feats, hidden), nn.ReLU(inplace=True))
    net.category = nn.Linear(hidden, 3)
    net.params = nn.Linear(hidden, max(n_params, 1))
    net.phenomenon = nn.Linear(hidden, max(n_phenomena, 1))
    net.drop = nn.Linear(hidden, 1) if drop_head else None


def _run_heads(net: Any, pooled: Any) -> tuple[Any, ...]:
    torch = _torch()
    h = net.trunk(pooled)
    out = (net.category(h), torch.sigmoid(net.params(h)), net.phenomenon(h))
    return out if net.drop is None else (*out, net.drop(h).squeeze(1))


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


class DropSpec(BaseModel):
    """How the drop head's raw output becomes the predicted relative F1 drop.

    ``drop = scale * raw + offset``, the line fitted on val frames (least squares against
    each frame's measured drop); ``val`` holds its figures there (``rmse``, ``spearman``).
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    scale: float = 1.0
    offset: float = 0.0
    val: dict[str, float] = Field(default_factory=dict)


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
        output_temperature: Temperature of the final category probabilities (after the
            lookup's mix and category 1's boost), fitted on val so that the confidence
            stays calibrated; 1 (none) in files written before it existed.
        drop: The calibration of the drop head (:class:`DropSpec`), or ``None`` (no head).

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
    output_temperature: float = Field(default=1.0, gt=0.0)
    drop: DropSpec | None = None

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
        drop: The predicted relative F1 drop of the model (calibrated), or ``None`` for an
            oracle without a drop head.

    """

    category: int
    confidence: float
    probs: tuple[float, float, float]
    phenomenon: str
    params: dict[str, float]
    drop: float | None = None


@dataclass(frozen=True)
class NetOutputs:
    """The network's raw outputs for a batch of frames.

    Attributes:
        category: ``[B, 3]`` category logits (untempered).
        params: ``[B, D]`` perceived normalised contexts.
        phenomenon: ``[B, 1 + P]`` phenomenon logits.
        drop: ``[B]`` the drop head's raw output, or ``None`` without one.

    """

    category: np.ndarray
    params: np.ndarray
    phenomenon: np.ndarray
    drop: np.ndarray | None = None


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


def tempered(probs: np.ndarray, temperature: float) -> np.ndarray:
    """*probs* ``[B, 3]`` sharpened (T < 1) or softened (T > 1): ``p^(1/T)``, renormalised."""
    if temperature == 1.0:
        return probs
    logp = np.log(np.clip(probs, 1e-12, 1.0)) / temperature
    return _softmax(logp)


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

    def outputs(self, frames: Sequence[npt.NDArray[np.uint8]]) -> NetOutputs:
        """Every raw output of the network for *frames* (:class:`NetOutputs`)."""
        torch = _torch()
        x = frames_to_uint8(frames, self.card.input_size, channels_last=True).float() / 255.0
        with torch.inference_mode():
            out = self.net(x)
        drop = out[3].numpy() if len(out) > 3 else None
        return NetOutputs(out[0].numpy(), out[1].numpy(), out[2].numpy(), drop)

    def logits(
        self, frames: Sequence[npt.NDArray[np.uint8]]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Raw outputs for *frames*: category logits (untempered), params, phenomenon logits."""
        out = self.outputs(frames)
        return out.category, out.params, out.phenomenon

    def predicted_drop(self, raw: np.ndarray | None) -> np.ndarray | None:
        """The calibrated relative F1 drop from the drop head's raw output (``None``: no head)."""
        spec = self.card.drop
        if raw is None or spec is None:
            return None
        out: np.ndarray = np.minimum(spec.scale * np.asarray(raw, np.float64) + spec.offset, 1.0)
        return out

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
        if spec is not None and self.lookup is not None:
            if spec.weight < 1.0:
                names = [p.name for p in self.card.phenomena]
                phenomena = _softmax(np.asarray(phenomenon_logits, np.float64))
                looked = lookup_probabilities(self.lookup, names, params, phenomena)
                probs = mixed_probabilities(probs, looked, spec.weight)
            probs = boosted(probs, spec.boost)
        return tempered(probs, self.card.output_temperature)

    def predict(self, frames: Sequence[npt.NDArray[np.uint8]]) -> list[OraclePrediction]:
        """Assess each frame; see :class:`OraclePrediction`."""
        if len(frames) == 0:
            return []
        raw = self.outputs(frames)
        cat, params, phen = raw.category, raw.params, raw.phenomenon
        probs = self.category_probabilities(cat, params, phen)
        drops = self.predicted_drop(raw.drop)
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
                    category,
                    float(probs[i, category]),
                    (p[0], p[1], p[2]),
                    name,
                    values,
                    None if drops is None else float(drops[i]),
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
            f"bad oracle sidecar at {where}: {validation_message(first)}",
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
