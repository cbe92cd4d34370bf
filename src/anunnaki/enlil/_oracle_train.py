"""Training a behavior oracle (paper §3.2): frames perturbed by searched contexts, plus clean.

Each training example is a train-split frame perturbed by one *context* (a point of a
phenomenon's parameter space, normalised to ``[0, 1]^d``) whose behavior category was
measured on the model (Enlil's archive, or :func:`random_contexts` for the Monte-Carlo
baseline), or a clean frame (category 0, phenomenon ``clear``). The network learns the
category (cross-entropy), the normalised context (mean squared error, on perturbed frames
only) and which phenomenon it is (``clear`` or one of those covered: a tactic reads it as
the perceived context, also when the oracle covers one phenomenon). A temperature fitted on
val frames (perturbed the same way, with val-split frames and other seeds) calibrates the
confidence.

An oracle for a camera that sends JPEG learns from frames that went through the same
encoding after the phenomenon (``OracleTrainConfig.encoding``, clean frames too): its
contexts' categories must have been measured through it as well (``anunnaki assess
--encoding``; the archive records it, and :func:`train_oracle` refuses contexts measured
through another encoding than the frames it trains on).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from typing import Any

import numpy as np
import numpy.typing as npt

from anunnaki._blas import torch_threads
from anunnaki.datasets import Dataset
from anunnaki.enlil._context import (
    EnlilError,
    evaluate_context,
    resolve_phenomenon,
    to_phenomenon_vector,
)
from anunnaki.enlil._oracle_lookup import (
    ContextLookup,
    LookupSpec,
    choose_mix,
    kept_rows,
    lookup_probabilities,
)
from anunnaki.enlil._oracle_metrics import (
    classification_metrics,
    expected_calibration_error,
    regression_metrics,
)
from anunnaki.enlil._oracle_net import (
    DropSpec,
    OracleCard,
    OracleModel,
    PhenomenonSpec,
    _torch,
    build_network,
    frames_to_uint8,
)
from anunnaki.lec import Detector
from anunnaki.phenomena import CameraEncoding

__all__ = [
    "ContextSet",
    "LabelledFrames",
    "OracleTrainConfig",
    "categories_for_drops",
    "choice_split",
    "choose_lookup_mix",
    "contexts_from_archive",
    "fit_drop_line",
    "fit_lookup",
    "fit_temperature",
    "merge_context_sets",
    "perturbed_frames",
    "random_contexts",
    "seed_spread",
    "soft_targets",
    "train_oracle",
    "train_oracle_seeds",
]


@dataclass(frozen=True)
class ContextSet:
    """Contexts of one phenomenon with their measured categories.

    Attributes:
        phenomenon: Phenomenon or composition name.
        param_names: Parameter names (vector order).
        params: ``[N, d]`` normalised contexts.
        categories: ``[N]`` behavior categories.
        source: Where they come from (``archive:PATH``, ``random``).
        drops: ``[N]`` the measured relative F1 drops (what the categories come from), or
            ``None`` when unknown (then the oracle gets no context lookup).
        encoding: The camera encoding the contexts were measured through (``jpeg:90``;
            ``""``: none).

    """

    phenomenon: str
    param_names: tuple[str, ...]
    params: npt.NDArray[np.float64]
    categories: npt.NDArray[np.int64]
    source: str = ""
    drops: npt.NDArray[np.float64] | None = None
    encoding: str = ""

    def __post_init__(self) -> None:
        if len(self.params) == 0:
            raise EnlilError(f"{self.phenomenon}: no contexts to train on ({self.source})")
        if self.params.shape[1] != len(self.param_names) or len(self.categories) != len(
            self.params
        ):
            raise EnlilError(
                f"{self.phenomenon}: contexts {self.params.shape} do not match parameters "
                f"{list(self.param_names)} and {len(self.categories)} categories ({self.source})"
            )
        if self.drops is not None and len(self.drops) != len(self.params):
            raise EnlilError(
                f"{self.phenomenon}: {len(self.drops)} drops for {len(self.params)} contexts "
                f"({self.source})"
            )

    def counts(self) -> list[int]:
        """Contexts per category 0, 1, 2."""
        return [int((self.categories == c).sum()) for c in range(3)]


def contexts_from_archive(path: str) -> ContextSet:
    """The contexts of an Enlil archive (:func:`anunnaki.enlil.read_archive`)."""
    from anunnaki.enlil._archive import read_archive

    archive = read_archive(path)
    return ContextSet(
        archive.phenomenon,
        tuple(archive.param_names),
        np.asarray(archive.params, np.float64),
        np.asarray(archive.categories, np.int64),
        f"archive:{path}",
        np.asarray(archive.drop, np.float64),
        archive.meta.encoding,
    )


def merge_context_sets(sets: Sequence[ContextSet]) -> list[ContextSet]:
    """One set per phenomenon, in first-seen order; sets of one phenomenon are concatenated.

    E.g. an Enlil archive and a random (Monte-Carlo) archive of the same phenomenon.

    Raises:
        EnlilError: Two sets of one phenomenon name different parameters, or any two sets
            were measured through different camera encodings.

    """
    merged: dict[str, list[ContextSet]] = {}
    for cset in sets:
        if cset.encoding != sets[0].encoding:
            raise EnlilError(
                f"{cset.source} was measured through the camera encoding "
                f"{cset.encoding or 'none'!r}, {sets[0].source} through "
                f"{sets[0].encoding or 'none'!r}; assess them again with the same --encoding"
            )
        group = merged.setdefault(cset.phenomenon, [])
        if group and group[0].param_names != cset.param_names:
            raise EnlilError(
                f"{cset.phenomenon}: {cset.source} has parameters {list(cset.param_names)}, "
                f"{group[0].source} {list(group[0].param_names)}; give archives of one "
                "phenomenon made by the same version of it"
            )
        group.append(cset)
    return [
        group[0]
        if len(group) == 1
        else ContextSet(
            name,
            group[0].param_names,
            np.concatenate([g.params for g in group]),
            np.concatenate([g.categories for g in group]),
            "+".join(g.source for g in group),
            None
            if any(g.drops is None for g in group)
            else np.concatenate([g.drops for g in group if g.drops is not None]),
            group[0].encoding,
        )
        for name, group in merged.items()
    ]


def random_contexts(
    detector: Detector,
    batch: Dataset,
    phenomenon: str,
    n: int,
    *,
    clean_f1: float,
    thresholds: tuple[float, float] = (0.05, 0.10),
    seed: int = 0,
    encoding: CameraEncoding | None = None,
) -> ContextSet:
    """*n* uniformly random contexts measured on *batch*: the Monte-Carlo baseline's data.

    With *encoding* they are measured through the camera's encoding (*clean_f1* must be too).
    """
    phen = resolve_phenomenon(phenomenon)
    rng = np.random.default_rng(seed)
    units = rng.random((n, len(phen.param_names)))
    results = [
        evaluate_context(
            detector,
            batch,
            phen,
            u,
            clean_f1=clean_f1,
            thresholds=thresholds,
            seed=seed,
            encoding=encoding,
        )
        for u in units
    ]
    cats = np.asarray([r.category for r in results], np.int64)
    drops = np.asarray([r.drop for r in results], np.float64)
    spec = "" if encoding is None else str(encoding)
    return ContextSet(phenomenon, tuple(phen.param_names), units, cats, "random", drops, spec)


@dataclass
class LabelledFrames:
    """Perturbed frames and what the oracle should say about each."""

    frames: list[npt.NDArray[np.uint8]]
    category: npt.NDArray[np.int64]
    params: npt.NDArray[np.float32]
    params_mask: npt.NDArray[np.float32]
    phenomenon: npt.NDArray[np.int64]
    rows: npt.NDArray[np.int64] | None = None  # each frame's context row in its set, -1 clean
    #: each frame's measured relative F1 drop (0 clean; nan where the set has no drops)
    drop: npt.NDArray[np.float32] | None = None

    def subset(self, index: npt.NDArray[np.int64]) -> LabelledFrames:
        """The frames at *index*, with everything said about them."""
        return LabelledFrames(
            [self.frames[int(i)] for i in index],
            self.category[index],
            self.params[index],
            self.params_mask[index],
            self.phenomenon[index],
            None if self.rows is None else self.rows[index],
            None if self.drop is None else self.drop[index],
        )


def _pick_context(
    rng: np.random.Generator, cset: ContextSet, balanced: bool
) -> tuple[npt.NDArray[np.float64], int, int]:
    if balanced:
        present = [c for c in range(3) if (cset.categories == c).any()]
        cat = present[int(rng.integers(len(present)))]
        rows = np.flatnonzero(cset.categories == cat)
        row = int(rows[int(rng.integers(len(rows)))])
    else:
        row = int(rng.integers(len(cset.params)))
    return cset.params[row], int(cset.categories[row]), row


def perturbed_frames(
    data: Dataset,
    sets: Sequence[ContextSet],
    n: int,
    *,
    clean_fraction: float = 0.2,
    balanced: bool = True,
    seed: int = 0,
    encoding: CameraEncoding | None = None,
) -> LabelledFrames:
    """*n* frames of *data*, each clean or perturbed by one context of one of *sets*.

    Args:
        data: The split the frames come from.
        sets: One :class:`ContextSet` per phenomenon (phenomenon class ``i + 1``).
        n: Frames to make.
        clean_fraction: Share of clean frames (category 0, phenomenon ``clear``).
        balanced: Draw a category first, then a context of it (the archive's rare category
            1 is seen as often as the others); else contexts uniformly.
        seed: Frames, contexts and the phenomena's seeds derive from it.
        encoding: The camera's encoding every frame goes through last, clean ones too.

    """
    if len(data) == 0:
        raise EnlilError("perturbed_frames: the split has no images")
    sent = (lambda image: image) if encoding is None else encoding.apply
    rng = np.random.default_rng(seed)
    width = max(len(s.param_names) for s in sets)
    phens = [resolve_phenomenon(s.phenomenon) for s in sets]
    out = LabelledFrames(
        [],
        np.zeros(n, np.int64),
        np.zeros((n, width), np.float32),
        np.zeros((n, width), np.float32),
        np.zeros(n, np.int64),
    )
    out.rows = rows = np.full(n, -1, np.int64)
    out.drop = drops = np.zeros(n, np.float32)
    for i in range(n):
        image = data.image(int(rng.integers(len(data))))
        if rng.random() < clean_fraction:
            out.frames.append(sent(image))
            continue
        which = int(rng.integers(len(sets)))
        unit, cat, rows[i] = _pick_context(rng, sets[which], balanced)
        measured = sets[which].drops
        drops[i] = math.nan if measured is None else measured[rows[i]]
        phen = phens[which]
        params = phen.from_vector(to_phenomenon_vector(phen, unit))
        out.frames.append(sent(phen.apply(image, params, seed=int(rng.integers(2**31)))))
        d = len(unit)
        out.category[i], out.phenomenon[i] = cat, which + 1
        out.params[i, :d], out.params_mask[i, :d] = unit, 1.0
    return out


@dataclass(frozen=True)
class OracleTrainConfig:
    """How an oracle is trained.

    Attributes:
        frames: Training frames (perturbed + clean).
        val_frames: Validation frames (temperature, metrics).
        clean_fraction: Share of clean frames.
        balanced: Draw contexts category-balanced (see :func:`perturbed_frames`).
        epochs: Passes over the training frames.
        batch_size: Frames per step.
        lr: Adam's learning rate (cosine-decayed to 5 % of it).
        input_size: ``(H, W)`` the network sees.
        width: Channels of the first convolution (``small_cnn`` option).
        seed: Everything derives from it.
        threads: torch threads (``0``: leave torch's default).
        lookup: Fit a drop surrogate to the measured contexts
            (:mod:`anunnaki.enlil._oracle_lookup`; needs their drops) and keep it in the
            oracle as a lookup from the perceived context, mixed with the category head
            as chosen on val; ``False``: the head alone, trained on the archive's categories.
        soft_labels: With the surrogate, train the category head on its probabilities of
            each context's category instead of the single measured category.
        architecture: The :data:`anunnaki.enlil.ORACLE_ARCHITECTURES` name.
        architecture_options: Its options besides ``width`` (e.g. ``{"pool": "max"}``).
        drop_head: Train a head predicting the relative F1 drop (needs measured drops).
        drop_weight: The weight of the drop head's squared error in the loss.
        choice_fraction: Share of the val frames the calibration (temperatures, the
            lookup's mix, category 1's boost, the drop's line) is chosen on; the card's val
            figures come from the rest, which nothing was chosen on.
        encoding: The camera encoding every train and val frame goes through after its
            phenomenon (``jpeg:90``; ``""``: none): the contexts' must be the same.

    """

    frames: int = 3000
    val_frames: int = 600
    clean_fraction: float = 0.2
    balanced: bool = True
    epochs: int = 12
    batch_size: int = 64
    lr: float = 3e-3
    input_size: tuple[int, int] = (128, 128)
    width: int = 16
    seed: int = 0
    threads: int = 0
    lookup: bool = True
    soft_labels: bool = True
    architecture: str = "small_cnn"
    architecture_options: dict[str, int | float | str | bool] = field(default_factory=dict)
    drop_head: bool = True
    drop_weight: float = 4.0
    choice_fraction: float = 0.5
    encoding: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


def fit_temperature(logits: np.ndarray, labels: np.ndarray) -> float:
    """The temperature minimising the negative log-likelihood on (*logits*, *labels*)."""
    if len(labels) == 0:
        return 1.0
    z = np.asarray(logits, np.float64)
    best, best_t = math.inf, 1.0
    for t in np.exp(np.linspace(math.log(0.2), math.log(10.0), 80)):
        s = z / t
        s = s - s.max(axis=1, keepdims=True)
        logp = s - np.log(np.exp(s).sum(axis=1, keepdims=True))
        nll = float(-logp[np.arange(len(labels)), labels].mean())
        if nll < best:
            best, best_t = nll, float(t)
    return best_t


def choice_split(
    n: int, fraction: float, *, seed: int = 0
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """``(pick, rest)``: a random *fraction* of ``range(n)`` and the others, both sorted."""
    if not 0.0 < fraction < 1.0:
        raise EnlilError(
            f"the val share calibration is chosen on must be in (0, 1), got {fraction}"
        )
    order = np.random.default_rng([seed, 11]).permutation(n)
    k = min(max(1, round(fraction * n)), n - 1) if n > 1 else n
    return np.sort(order[:k]), np.sort(order[k:])


def fit_drop_line(raw: np.ndarray, measured: np.ndarray) -> DropSpec:
    """The least-squares line from the drop head's *raw* output to the *measured* drops."""
    known = np.isfinite(measured)
    x, y = np.asarray(raw, np.float64)[known], np.asarray(measured, np.float64)[known]
    if len(x) < 2 or float(np.var(x)) == 0.0:
        return DropSpec(scale=1.0, offset=0.0)
    scale, offset = np.polyfit(x, y, 1)
    fitted = scale * x + offset
    return DropSpec(scale=float(scale), offset=float(offset), val=regression_metrics(fitted, y))


def categories_for_drops(
    drops: np.ndarray, thresholds: tuple[float, float] = (0.05, 0.10)
) -> npt.NDArray[np.int64]:
    """The behavior category of each relative F1 drop (the rule of docs/oracles.md)."""
    d = np.asarray(drops, np.float64)
    return np.where(d > thresholds[1], 2, np.where(d > thresholds[0], 1, 0)).astype(np.int64)


def _fit(
    net: Any,
    data: LabelledFrames,
    config: OracleTrainConfig,
    soft: npt.NDArray[np.float32] | None = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> list[float]:
    torch = _torch()
    f = torch.nn.functional
    # uint8 until a batch is drawn (a quarter of the memory; the same floats), and
    # channels-last: these convolutions train in about 3/4 of the time in that layout
    # (benchmarks/enlil_speed.py); the result differs only by float summation order.
    x = frames_to_uint8(data.frames, config.input_size)
    channels_last = torch.channels_last
    net.to(memory_format=channels_last)
    y_cat = torch.from_numpy(data.category if soft is None else soft)
    y_par = torch.from_numpy(data.params)
    mask = torch.from_numpy(data.params_mask)
    y_phen = torch.from_numpy(data.phenomenon)
    raw_drop = data.drop if data.drop is not None else np.full(len(x), np.nan, np.float32)
    drop_mask = torch.from_numpy(np.isfinite(raw_drop).astype(np.float32))
    # drops above 1 do not occur; a slightly negative drop (F1 up) is kept as measured
    y_drop = torch.from_numpy(np.clip(np.nan_to_num(raw_drop), -0.2, 1.0).astype(np.float32))
    gen = torch.Generator().manual_seed(config.seed)
    opt = torch.optim.Adam(net.parameters(), lr=config.lr, weight_decay=1e-4)
    steps = config.epochs * max(1, math.ceil(len(x) / config.batch_size))
    sched = torch.optim.lr_scheduler.OneCycleLR(
        opt, max_lr=config.lr, total_steps=steps, pct_start=0.15
    )
    losses = []
    net.train()
    for _ in range(config.epochs):
        order = torch.randperm(len(x), generator=gen)
        total = 0.0
        for start in range(0, len(x), config.batch_size):
            idx = order[start : start + config.batch_size]
            xb = (x[idx].float() / 255.0).contiguous(memory_format=channels_last)
            if torch.rand(1, generator=gen).item() < 0.5:
                xb = xb.flip(3)  # the phenomena are symmetric left-right; the labels too
            out = net(xb)
            cat, par, phen = out[0], out[1], out[2]
            loss = f.cross_entropy(cat, y_cat[idx])
            if len(out) > 3:
                dm = drop_mask[idx]
                err = (out[3] - y_drop[idx]) ** 2 * dm
                loss = loss + config.drop_weight * err.sum() / dm.sum().clamp(min=1.0)
            m = mask[idx]
            loss = loss + ((par[:, : m.shape[1]] - y_par[idx]) ** 2 * m).sum() / m.sum().clamp(
                min=1.0
            )
            # clear vs each phenomenon, also for one phenomenon: a frame's perceived
            # context ('clear' or 'fog') is what tactics read (A4.context)
            loss = loss + 0.5 * f.cross_entropy(phen, y_phen[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += float(loss.detach()) * len(idx)
        losses.append(total / len(x))
        if progress is not None:
            progress("epochs", len(losses), config.epochs)
    net.eval()  # left channels-last: OracleModel runs it so, and save() writes C order
    return losses


def fit_lookup(
    sets: Sequence[ContextSet], *, thresholds: tuple[float, float] = (0.05, 0.10)
) -> ContextLookup | None:
    """The drop surrogates of *sets* (:class:`ContextLookup`); ``None`` when drops are unknown."""
    if any(s.drops is None for s in sets):
        return None
    return ContextLookup.from_contexts(
        {s.phenomenon: (s.params, s.drops) for s in sets if s.drops is not None},
        thresholds=thresholds,
    )


def soft_targets(
    lookup: ContextLookup, sets: Sequence[ContextSet], frames: LabelledFrames
) -> npt.NDArray[np.float32]:
    """``[F, 3]`` the surrogate's category probabilities of each frame's context.

    Clean frames get category 0. These replace the archive's single noisy measurements as
    training targets of the category head.
    """
    out = np.zeros((len(frames.category), 3), np.float32)
    out[:, 0] = 1.0
    for i, cset in enumerate(sets):
        rows = np.flatnonzero(frames.phenomenon == i + 1)
        if len(rows):
            d = len(cset.param_names)
            out[rows] = lookup.vote(cset.phenomenon, frames.params[rows, :d])
    return out


def choose_lookup_mix(
    lookup: ContextLookup,
    sets: Sequence[ContextSet],
    val: LabelledFrames,
    *,
    head: np.ndarray,
    params: np.ndarray,
    phenomenon_logits: np.ndarray,
) -> LookupSpec:
    """The lookup's mix with the head (and category 1's boost), chosen on the *val* frames.

    Each val frame's own context is left out of the surrogate (leave-one-out), so the
    choice sees the lookup as it works on contexts it has not measured.

    Args:
        lookup: The surrogates of *sets*.
        sets: The measured contexts, one set per phenomenon (the oracle's order).
        val: Val frames perturbed by those contexts, with their ``rows``.
        head: ``[F, 3]`` the category head's calibrated probabilities on them.
        params: ``[F, D]`` the perceived contexts.
        phenomenon_logits: ``[F, 1 + P]`` the phenomenon head's logits.

    """
    names = [s.phenomenon for s in sets]
    rows = val.rows if val.rows is not None else np.full(len(val.category), -1, np.int64)
    exclude = {}
    for i, cset in enumerate(sets):
        kept = np.full(len(cset.params), -1, np.int64)
        keep = kept_rows(len(cset.params))
        kept[keep] = np.arange(len(keep))
        mine = (val.phenomenon == i + 1) & (rows >= 0)
        exclude[cset.phenomenon] = np.where(mine, kept[np.where(mine, rows, 0)], -1)
    z = np.exp(phenomenon_logits - phenomenon_logits.max(axis=1, keepdims=True))
    looked = lookup_probabilities(
        lookup, names, params, z / z.sum(axis=1, keepdims=True), exclude=exclude
    )
    weight, boost, f1 = choose_mix(head, looked, val.category)
    return lookup.spec(weight, boost, {"split": "val", "frames": len(val.category), "macro_f1": f1})


def _frames_encoding(sets: Sequence[ContextSet], spec: str) -> CameraEncoding | None:
    """The frames' camera encoding, which must be the one the contexts were measured through."""
    encoding = CameraEncoding.parse(spec)
    spec = "" if encoding is None else str(encoding)
    if sets[0].encoding != spec:
        raise EnlilError(
            f"train_oracle: the contexts of {sets[0].source} were measured through the camera "
            f"encoding {sets[0].encoding or 'none'!r}, the frames would go through "
            f"{spec or 'none'!r}; train with encoding={sets[0].encoding!r} "
            "(oracle train --encoding) or assess again with the frames' encoding"
        )
    return encoding


def train_oracle(
    train: Dataset,
    val: Dataset,
    sets: Sequence[ContextSet],
    *,
    model_id: str,
    model_sha256: str = "",
    thresholds: tuple[float, float] = (0.05, 0.10),
    config: OracleTrainConfig | None = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> OracleModel:
    """Train an oracle for *model_id* on *sets* (one per phenomenon); see the module docstring.

    *progress* ``(stage, done, total)`` is called as the stages advance: ``frames`` (the
    train and val frames perturbed, 0..2), ``epochs`` (after each one), ``calibrate`` (0..1).

    Returns:
        The oracle, its card holding val metrics (``val.accuracy``, ``val.macro_f1``,
        ``val.ece`` after temperature scaling) and how it was trained.

    """
    if not sets:
        raise EnlilError("train_oracle: give at least one set of contexts (an archive)")
    cfg = config or OracleTrainConfig()
    with torch_threads(cfg.threads):  # as it found them after
        return _train_oracle(
            train,
            val,
            sets,
            model_id=model_id,
            model_sha256=model_sha256,
            thresholds=thresholds,
            cfg=cfg,
            progress=progress,
        )


def _train_oracle(
    train: Dataset,
    val: Dataset,
    sets: Sequence[ContextSet],
    *,
    model_id: str,
    model_sha256: str,
    thresholds: tuple[float, float],
    cfg: OracleTrainConfig,
    progress: Callable[[str, int, int], None] | None,
) -> OracleModel:
    sets = merge_context_sets(sets)
    encoding = _frames_encoding(sets, cfg.encoding)
    drop_head = cfg.drop_head and all(s.drops is not None for s in sets)
    torch = _torch()
    torch.manual_seed(cfg.seed)
    card = OracleCard(
        model_id=model_id,
        model_sha256=model_sha256,
        phenomena=[
            PhenomenonSpec(name=s.phenomenon, param_names=list(s.param_names)) for s in sets
        ],
        thresholds=thresholds,
        architecture=cfg.architecture,
        options={"width": cfg.width, **cfg.architecture_options}
        | ({"drop_head": True} if drop_head else {}),
        input_size=cfg.input_size,
    )
    net = build_network(card)
    step = progress or (lambda stage, done, total: None)
    frac, bal = cfg.clean_fraction, cfg.balanced
    step("frames", 0, 2)
    tr = perturbed_frames(
        train, sets, cfg.frames, clean_fraction=frac, balanced=bal, seed=cfg.seed,
        encoding=encoding,
    )  # fmt: skip
    step("frames", 1, 2)
    va = perturbed_frames(
        val, sets, cfg.val_frames, clean_fraction=frac, balanced=bal, seed=cfg.seed + 1_000_003,
        encoding=encoding,
    )  # fmt: skip
    step("frames", 2, 2)
    lookup = fit_lookup(sets, thresholds=thresholds) if cfg.lookup else None
    soft = soft_targets(lookup, sets, tr) if lookup is not None and cfg.soft_labels else None
    losses = _fit(net, tr, cfg, soft, progress)
    step("calibrate", 0, 1)
    oracle = OracleModel(card, net)
    outs = [oracle.outputs(va.frames[i : i + 256]) for i in range(0, len(va.frames), 256)]
    logits, params, phen = (
        np.concatenate([getattr(o, k) for o in outs]) for k in ("category", "params", "phenomenon")
    )
    raw_drop = np.concatenate([o.drop for o in outs if o.drop is not None]) if drop_head else None
    # the calibration is chosen on one part of the val frames, the card's figures come from
    # the other: no figure is measured on frames anything was chosen on
    pick, rest = choice_split(len(va.category), cfg.choice_fraction, seed=cfg.seed)
    va_pick = va.subset(pick)
    temperature = fit_temperature(logits[pick], va.category[pick])
    oracle.card = card.model_copy(update={"temperature": temperature})
    head = oracle.probabilities(logits)
    if lookup is not None:
        spec = choose_lookup_mix(
            lookup, sets, va_pick, head=head[pick], params=params[pick],
            phenomenon_logits=phen[pick],
        )  # fmt: skip
        oracle.lookup = lookup
        oracle.card = oracle.card.model_copy(update={"lookup": spec})
    if lookup is not None:
        # the mix and category 1's boost move the confidence: a second temperature on the
        # final probabilities keeps them calibrated
        mixed = np.log(np.clip(oracle.category_probabilities(logits, params, phen), 1e-12, 1.0))
        t_out = fit_temperature(mixed[pick], va.category[pick])
        oracle.card = oracle.card.model_copy(update={"output_temperature": t_out})
    probs = oracle.category_probabilities(logits, params, phen)
    if raw_drop is not None and va.drop is not None:
        oracle.card = oracle.card.model_copy(
            update={"drop": fit_drop_line(raw_drop[pick], va.drop[pick])}
        )
    val_metrics = classification_metrics(probs[rest].argmax(axis=1), va.category[rest])
    val_metrics["ece"] = expected_calibration_error(probs[rest], va.category[rest])
    val_metrics["frames"] = len(rest)
    predicted = oracle.predicted_drop(raw_drop)
    if predicted is not None and va.drop is not None:
        known = rest[np.isfinite(va.drop[rest])]
        val_metrics["drop"] = regression_metrics(predicted[known], va.drop[known])
        val_metrics["drop_category_macro_f1"] = classification_metrics(
            categories_for_drops(predicted[rest], thresholds), va.category[rest]
        )["macro_f1"]
    if lookup is not None:
        head_metrics = classification_metrics(head[rest].argmax(axis=1), va.category[rest])
        val_metrics["head_macro_f1"] = head_metrics["macro_f1"]
    training = {
        "contexts": [
            {"phenomenon": s.phenomenon, "source": s.source, "counts": s.counts()} for s in sets
        ],
        "config": {k: v for k, v in asdict(cfg).items() if k != "extra"} | cfg.extra,
        "train_frames": len(tr.frames),
        "val_frames": len(va.frames),
        "val_choice_frames": len(pick),
        "loss": [round(v, 5) for v in losses],
        "phenomenon_head": True,
        "soft_labels": soft is not None,
    }
    oracle.card = oracle.card.model_copy(
        update={"metrics": {"val": val_metrics}, "training": training}
    )
    step("calibrate", 1, 1)
    return oracle


def seed_spread(values: Sequence[float]) -> dict[str, float]:
    """``mean``, ``sd`` (sample), ``min``, ``max`` and ``spread`` (max - min) of one figure."""
    v = np.asarray([x for x in values if x is not None and math.isfinite(x)], np.float64)
    if len(v) == 0:
        return {"mean": math.nan, "sd": math.nan, "min": math.nan, "max": math.nan, "spread": 0.0}
    return {
        "mean": float(v.mean()),
        "sd": float(v.std(ddof=1)) if len(v) > 1 else 0.0,
        "min": float(v.min()),
        "max": float(v.max()),
        "spread": float(v.max() - v.min()),
        "n": float(len(v)),
    }


def train_oracle_seeds(
    train: Dataset,
    val: Dataset,
    sets: Sequence[ContextSet],
    seeds: Sequence[int],
    *,
    model_id: str,
    model_sha256: str = "",
    thresholds: tuple[float, float] = (0.05, 0.10),
    config: OracleTrainConfig | None = None,
    progress: Callable[[int, str, int, int], None] | None = None,
) -> tuple[list[OracleModel], dict[str, dict[str, float]]]:
    """One oracle per seed of one recipe, and the mean and spread of their val figures.

    *progress* ``(seed, stage, done, total)``: :func:`train_oracle`'s, with the seed first.

    Returns:
        The oracles (in *seeds*' order) and, per val figure (``accuracy``, ``macro_f1``,
        ``ece``, ``drop_rmse``), :func:`seed_spread` over the seeds.

    """
    if not seeds:
        raise EnlilError("train_oracle_seeds: give at least one seed")
    base = config or OracleTrainConfig()
    oracles = [
        train_oracle(
            train, val, sets, model_id=model_id, model_sha256=model_sha256,
            thresholds=thresholds, config=replace(base, seed=int(seed)),
            progress=None if progress is None else partial(progress, int(seed)),
        )
        for seed in seeds
    ]  # fmt: skip
    vals = [o.card.metrics["val"] for o in oracles]
    figures = {k: [float(v[k]) for v in vals] for k in ("accuracy", "macro_f1", "ece")}
    if all("drop" in v for v in vals):
        figures["drop_rmse"] = [float(v["drop"]["rmse"]) for v in vals]
    return oracles, {k: seed_spread(v) for k, v in figures.items()}
