"""Training and evaluating the CenterNet detector on CPU.

Why the loop is this simple: the data (a few thousand 128 × 128 frames) fits in memory, so
there is no DataLoader and no worker processes — targets are encoded in numpy per batch,
which costs far less than the forward/backward pass on two threads. Everything random
(initial weights, batch order, augmentation) is drawn from the one ``seed``, split with
``numpy.random.SeedSequence``; with the same data, seed and thread count a run is repeatable.

Augmentation: horizontal flips, a random zoom (scale and shift), and — for robust per-domain
models — phenomena from :mod:`anunnaki.phenomena` at random strengths (:class:`Augmenter`).
"""

from __future__ import annotations

import math
import random
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import torch

from anunnaki._names import NameRuleError, check_name
from anunnaki.datasets import Dataset
from anunnaki.lec._centernet import (
    _PAD,
    STRIDE,
    CenterNetDetector,
    _resize,
    centernet_loss,
    encode_targets,
)
from anunnaki.lec._detector import DetectionResult, Detector, DetectorError
from anunnaki.lec._hidden import hide_boxes
from anunnaki.lec._metrics import Metrics, choose_threshold, f1_at_iou
from anunnaki.lec._recipe import (
    CandidatePerturb,
    WeightAverage,
    candidate_losses,
    consistency_loss,
    pick,
)
from anunnaki.phenomena import PHENOMENA, CameraEncoding, Mask, Phenomenon

__all__ = [
    "Augmenter",
    "EpochHook",
    "Perturb",
    "SharedClassesDetector",
    "TrainConfig",
    "TrainResult",
    "TrainState",
    "evaluate_detector",
    "predict",
    "shared_classes",
    "train_detector",
]

#: Predictions below this score are never kept when measuring (the threshold search floor).
SCORE_FLOOR = 0.05

Image = npt.NDArray[np.uint8]
Boxes = npt.NDArray[np.float32]
Labels = npt.NDArray[np.int64]

#: ``perturb(image, rng) -> image`` (``TrainConfig.perturb``): ``uint8`` ``(H, W, 3)`` in and
#: out, drawing only from *rng*. It may return ``(image, mask)`` instead, with the
#: phenomenon's occlusion mask (``Phenomenon.occlusion``, or ``None``): boxes it hides then
#: become ignore boxes (``anunnaki.lec.hide_boxes``).
Perturb = Callable[[Image, np.random.Generator], "Image | tuple[Image, Mask | None]"]


class Augmenter:
    """Applies phenomena at random strengths, for training robust per-domain models.

    For each image, with probability *probability*, one of the phenomena is picked at
    random and applied with ``strength`` drawn uniformly from ``[0, max_strength]``:
    parameters that the phenomenon's ``strength_target`` moves get
    ``strength_params(strength)``; the other ("free") parameters — a raindrop's position,
    the slant of rain, the angle of a motion blur — are drawn uniformly within
    ``± strength`` × half their range around their identity value. Pin a free parameter
    with a composition step, e.g. ``compose(("hsl", {"hue": 0}))``.

    Args:
        phenomena: Names (``"fog"``, ``"raindrop"``, ``"fog+raindrop"``) or instances.
        probability: Share of images that get a phenomenon (the rest stay clean).
        max_strength: Upper end of the strength range.

    """

    def __init__(
        self,
        phenomena: Sequence[str | Phenomenon],
        *,
        probability: float = 0.8,
        max_strength: float = 1.0,
    ) -> None:
        if not 0.0 <= probability <= 1.0:
            raise DetectorError(f"augment probability must be in [0, 1], got {probability}")
        if not 0.0 <= max_strength <= 1.0:
            raise DetectorError(f"augment max_strength must be in [0, 1], got {max_strength}")
        self.phenomena = [PHENOMENA.create(p) if isinstance(p, str) else p for p in phenomena]
        self.probability = probability
        self.max_strength = max_strength

    @property
    def names(self) -> list[str]:
        """The phenomena's names."""
        return [p.name for p in self.phenomena]

    def sample_params(self, phenomenon: Phenomenon, rng: np.random.Generator) -> dict[str, float]:
        """Random parameters for *phenomenon* (see the class docstring)."""
        s = float(rng.uniform(0.0, self.max_strength))
        params = phenomenon.strength_params(s)
        identity = phenomenon.identity_params()
        target = phenomenon.strength_params(1.0)
        for spec in phenomenon.params:
            if target[spec.name] == identity[spec.name]:
                half = (spec.high - spec.low) / 2
                lo = max(spec.low, identity[spec.name] - s * half)
                hi = min(spec.high, identity[spec.name] + s * half)
                params[spec.name] = float(rng.uniform(lo, hi))
        return phenomenon.validate(params)

    def __call__(self, image: Image, rng: np.random.Generator) -> Image:
        """Return *image* perturbed (or unchanged, with probability 1 - *probability*)."""
        return self.occluded(image, rng)[0]

    def occluded(self, image: Image, rng: np.random.Generator) -> tuple[Image, Mask | None]:
        """As calling it, with the phenomenon's occlusion mask (``None``: nothing hidden).

        The same draws from *rng* as a call, so the two give the same image.
        """
        if not self.phenomena or rng.random() >= self.probability:
            return image, None
        phenomenon = self.phenomena[int(rng.integers(len(self.phenomena)))]
        params = self.sample_params(phenomenon, rng)
        seed = int(rng.integers(2**31 - 1))
        out = phenomenon.apply(image, params, seed=seed)
        return out, phenomenon.occlusion(image.shape, params, seed)


@dataclass(frozen=True)
class TrainConfig:
    """How to train (all options keyword-only at the call sites; defaults suit 128 × 128).

    Attributes:
        epochs: Passes over the training split (14: the rover default model's, 247 s for
            2000 images at 128 × 128 on 2 threads — inside the 5-minute budget).
        batch_size: Images per step.
        lr: Peak learning rate (AdamW, one warm-up epoch, then cosine decay to 2 %).
        weight_decay: AdamW weight decay.
        width: Network base width (see :class:`CenterNet`).
        stride: Output stride of the heat map (4, or 2 for very small objects).
        seed: Seeds weights, batch order and augmentation.
        threads: ``torch.set_num_threads`` during training (``None``: leave as is).
        input_size: ``(width, height)`` the network runs at; default the first training
            image's size.
        augment: Phenomena applied at random strengths (see :class:`Augmenter`).
        augment_prob: Share of training images that get a phenomenon.
        flip: Random horizontal flips.
        zoom: Random zoom range: scale in ``[1 - zoom, 1 + zoom]`` with a random shift.
        photometric: Random brightness, contrast (each ``± photometric``) and colour balance
            (``± photometric / 4`` per channel) on every image, before any phenomenon.
            Without it the simulator's steady lighting teaches a model that loses a quarter
            of its F1 when the frame is dimmed by 9 % (measured on the rover).
        model_id: The trained model's id.
        domain: The trained model's domain.
        ignore: Honour the data's ignore boxes (no background loss inside them), and make
            a box that a phenomenon hides (``augment`` or ``perturb`` with an occlusion mask,
            mean over the box at least ``anunnaki.phenomena.HIDDEN``) one too; off, an
            unlabelled object is background like any other pixel and a hidden one a target.
        init: Start from this model's weights (a model file or a detector) instead of
            random ones — fine-tuning a domain model from the default one. Its classes,
            width and stride must match; ``width``/``stride`` are then taken from it.
        perturb: ``perturb(image, rng) -> image`` (:data:`Perturb`) applied to every
            training image last, after ``augment``, with a random stream of its own: two
            trainings that differ only in it see the same images, zooms, flips and order
            (Enki's context sources, ``anunnaki.enki``). A :class:`CandidatePerturb`
            offers several candidates per image and the loop keeps one (worst-of-k: the
            highest loss under the network being trained; ``anunnaki.lec._recipe``).
        consistency: λ of the consistency loss (0: off): each step adds λ × the
            Jensen-Shannon divergence between the heat maps of the perturbed images and of
            their clean views (the same image after zoom, flip and recolouring, before
            ``perturb``), the clean views' output detached (:func:`consistency_loss`). The
            clean views of the perturbed images go through the network in the same batch
            (one forward pass, so BatchNorm normalises both alike; each counted).
        ema: Decay of an exponential moving average of the weights (0: off). On, the saved
            model has the averaged weights, and the val threshold (and the per-epoch val
            F1) is chosen with them (:class:`WeightAverage`).

    """

    epochs: int = 14
    batch_size: int = 32
    lr: float = 3e-3
    weight_decay: float = 1e-4
    width: int = 16
    stride: int = STRIDE
    seed: int = 0
    threads: int | None = 2
    input_size: tuple[int, int] | None = None
    augment: tuple[str | Phenomenon, ...] = ()
    augment_prob: float = 0.8
    flip: bool = True
    zoom: float = 0.25
    photometric: float = 0.25
    model_id: str = "centernet"
    domain: str = "default"
    ignore: bool = True
    init: str | Path | CenterNetDetector | None = None
    perturb: Perturb | None = None
    consistency: float = 0.0
    ema: float = 0.0

    def __post_init__(self) -> None:
        """The id and the domain are names (``anunnaki._names``): an id becomes file names.

        The domain only has to be a name here; a registry (where models are swapped by
        domain) also wants it an identifier, and ``train-detector --domain`` asks that.
        """
        if not self.consistency >= 0.0 or not 0.0 <= self.ema < 1.0:
            raise DetectorError(
                f"TrainConfig: consistency must be >= 0 and ema in [0, 1); got "
                f"{self.consistency} and {self.ema}"
            )
        try:
            check_name(self.model_id, what="model id")
            check_name(self.domain, what="domain")
        except NameRuleError as exc:
            raise DetectorError(f"TrainConfig: {exc}") from None


@dataclass
class TrainState:
    """Where a training stands after an epoch: enough to continue it bit for bit.

    ``train_detector(..., checkpoint=...)`` hands one over after every epoch;
    ``train_detector(..., resume=state)`` continues from it with the same settings (the
    caller checks that they are). :meth:`save`/:meth:`load` use ``torch.save`` and
    ``torch.load(weights_only=True)``: tensors, numbers and strings only, nothing unpickled.

    Attributes:
        epoch: Epochs done.
        step: Optimiser steps done.
        network: The network's ``state_dict``.
        optimizer: The optimiser's ``state_dict``.
        rngs: The bit-generator states of the batch order, augmentation and perturbation
            streams, and torch's generator state.
        history: The per-epoch figures so far (as :attr:`TrainResult.history`).
        ema: The weight average (:meth:`WeightAverage.as_dict`), when ``TrainConfig.ema``.
        counts: The forward passes and candidates so far (as :attr:`TrainResult.counts`).

    """

    epoch: int
    step: int
    network: dict[str, Any]
    optimizer: dict[str, Any]
    rngs: dict[str, Any]
    history: list[dict[str, float]]
    ema: dict[str, Any] | None = None
    counts: dict[str, int] = field(default_factory=dict)

    def save(self, path: str | Path) -> None:
        """Write the state to *path* atomically (a temporary file renamed into place)."""
        target = Path(path)
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = target.with_name(f".tmp-{target.name}")
        torch.save(self.__dict__, tmp)
        tmp.replace(target)

    @classmethod
    def load(cls, path: str | Path) -> TrainState:
        """Read a state written by :meth:`save`.

        Raises:
            DetectorError: The file is not a readable training state.

        """
        try:
            data = torch.load(path, map_location="cpu", weights_only=True)
            return cls(**data)
        except Exception as exc:  # torch raises several kinds for a damaged file
            raise DetectorError(
                f"{path}: not a readable training checkpoint ({exc}); delete it to restart "
                "from the previous one"
            ) from exc


@dataclass
class TrainResult:
    """What :func:`train_detector` returns.

    Attributes:
        detector: The trained detector, its threshold set from the validation split and
            its metrics recorded (saved into the sidecar by ``save_detector``).
        threshold: The score threshold chosen on the validation split.
        val: Metrics on the validation split at that threshold.
        test: Metrics on the test split, when one was given.
        seconds: Wall-clock time of the epochs (without any evaluation; a resumed training
            counts the epochs done before too).
        history: Per epoch: ``epoch``, ``loss``, ``heat``, ``box`` (mean losses; also
            ``consistency`` when it is on), ``seconds``.
        counts: What the training spent beside its optimiser steps, in images through the
            network: ``train_forwards`` (with gradient, the steps' batches),
            ``select_forwards`` (no-grad passes scoring worst-of-k candidates),
            ``consistency_forwards`` (clean views beside the perturbed ones) and
            ``candidates`` (candidate images rendered by a :class:`CandidatePerturb`).

    """

    detector: CenterNetDetector
    threshold: float
    val: Metrics
    test: Metrics | None
    seconds: float
    history: list[dict[str, float]] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)


#: ``on_step(step, total_steps, info)`` — info has ``epoch`` and the running ``loss``.
ProgressHook = Callable[[int, int, dict[str, float]], None]

#: ``on_epoch(info)`` after every epoch — info has ``epoch``, ``epochs``, the epoch's mean
#: ``loss`` (``heat``, ``box``), its ``seconds`` and ``val_f1``: F1 on the val split at the
#: threshold that maximises it then (what the final threshold choice would pick).
EpochHook = Callable[[dict[str, float]], None]


def _zoom(
    image: Image,
    boxes: Boxes,
    labels: Labels,
    rng: np.random.Generator,
    amount: float,
    *,
    ignore: Boxes | None = None,
) -> tuple[Image, Boxes, Labels, Boxes]:
    """Scale and shift the image; boxes mostly pushed out become ignore boxes."""
    import cv2

    h, w = image.shape[:2]
    s = float(rng.uniform(1.0 - amount, 1.0 + amount))
    # Shift so the scaled image still covers the frame when zooming in, and stays inside it
    # (with a border) when zooming out.
    tx = float(rng.uniform(min(0.0, w - s * w), max(0.0, w - s * w)))
    ty = float(rng.uniform(min(0.0, h - s * h), max(0.0, h - s * h)))
    m = np.array([[s, 0.0, tx], [0.0, s, ty]], np.float64)
    out = np.asarray(
        cv2.warpAffine(image, m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT),
        dtype=np.uint8,
    )
    shift = np.array([tx, ty, tx, ty])
    ig = np.zeros((0, 4)) if ignore is None else ignore.astype(np.float64).reshape(-1, 4)
    ig = ig * s + shift
    nb = boxes.astype(np.float64).reshape(-1, 4) * s + shift
    area = (nb[:, 2] - nb[:, 0]) * (nb[:, 3] - nb[:, 1])
    for b in (nb, ig):
        b[:, 0::2] = b[:, 0::2].clip(0, w)
        b[:, 1::2] = b[:, 1::2].clip(0, h)
    bw, bh = nb[:, 2] - nb[:, 0], nb[:, 3] - nb[:, 1]
    keep = (bw * bh >= 0.5 * area) & (bw >= 2) & (bh >= 2)
    seen = (bw > 0) & (bh > 0)
    ig = np.concatenate([ig, nb[seen & ~keep]])
    ig = ig[(ig[:, 2] > ig[:, 0]) & (ig[:, 3] > ig[:, 1])]
    return out, nb[keep].astype(np.float32), labels[keep], ig.astype(np.float32)


def _photometric(image: Image, rng: np.random.Generator, amount: float) -> Image:
    """Random brightness, contrast and colour balance, each within ``± amount``."""
    gain = rng.uniform(1.0 - amount, 1.0 + amount)
    contrast = rng.uniform(1.0 - amount, 1.0 + amount)
    tint = rng.uniform(1.0 - amount / 4, 1.0 + amount / 4, size=3)
    x = image.astype(np.float32)
    mean = x.mean()
    x = ((x - mean) * contrast + mean) * (gain * tint)
    out: Image = np.clip(x + 0.5, 0, 255).astype(np.uint8)
    return out


def _fit(image: Image, boxes: Boxes, size: tuple[int, int]) -> tuple[Image, Boxes]:
    w, h = size
    ih, iw = image.shape[:2]
    if (iw, ih) == (w, h):
        return image, boxes
    scale = np.array([w / iw, h / ih, w / iw, h / ih], np.float32)
    return _resize(image, size), boxes * scale


def _batch_tensors(
    samples: Sequence[tuple[Image, Boxes, Labels, Boxes]],
    size: tuple[int, int],
    num_classes: int,
    stride: int,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    w, h = size
    ph, pw = -(-h // _PAD) * _PAD, -(-w // _PAD) * _PAD
    out_hw = (ph // stride, pw // stride)
    images = np.zeros((len(samples), ph, pw, 3), np.uint8)
    heats, box_ts, weights = [], [], []
    for i, (image, boxes, labels, ignore) in enumerate(samples):
        images[i, :h, :w] = image
        heat, box_t, weight = encode_targets(
            boxes, labels, num_classes=num_classes, out_hw=out_hw, stride=stride, ignore=ignore
        )
        heats.append(heat)
        box_ts.append(box_t)
        weights.append(weight)
    return (
        torch.from_numpy(images).permute(0, 3, 1, 2).float().contiguous(),
        torch.from_numpy(np.stack(heats)),
        torch.from_numpy(np.stack(box_ts)),
        torch.from_numpy(np.stack(weights)),
    )


def predict(
    det: Detector,
    data: Dataset | Sequence[Image],
    *,
    batch_size: int = 32,
    score_floor: float = SCORE_FLOOR,
    transform: Callable[[int, Image], Image] | None = None,
) -> list[DetectionResult]:
    """Run *det* over a dataset (or images), keeping every candidate down to *score_floor*.

    Args:
        det: Any :class:`Detector`; a :class:`CenterNetDetector` is asked for candidates
            down to *score_floor*, others return what they return.
        data: A :class:`Dataset` or a sequence of images.
        batch_size: Images per ``detect`` call.
        score_floor: Lowest score kept (threshold search happens above it).
        transform: ``transform(index, image)`` applied to each image first (a phenomenon).

    """
    n = len(data)
    out: list[DetectionResult] = []
    for start in range(0, n, batch_size):
        batch = []
        for i in range(start, min(n, start + batch_size)):
            image = data.image(i) if isinstance(data, Dataset) else data[i]
            batch.append(transform(i, image) if transform is not None else image)
        if isinstance(det, CenterNetDetector) or (
            isinstance(det, SharedClassesDetector) and isinstance(det.inner, CenterNetDetector)
        ):
            out.extend(det.detect(batch, score_threshold=score_floor))
        else:
            out.extend(det.detect(batch))
    return out


def phenomenon_params(
    phenomenon: str | Phenomenon, params: Any, strength: float | None
) -> tuple[Phenomenon, Any]:
    """The phenomenon and its parameters from ``params`` or a ``strength`` (not both)."""
    phen = PHENOMENA.create(phenomenon) if isinstance(phenomenon, str) else phenomenon
    if params is not None and strength is not None:
        raise DetectorError("give the phenomenon's params or a strength, not both")
    chosen = (
        phen.validate(params)
        if params is not None
        else phen.strength_params(1.0 if strength is None else strength)
    )
    return phen, chosen


def evaluate_detector(
    det: Detector,
    data: Dataset,
    *,
    phenomenon: str | Phenomenon | None = None,
    params: dict[str, float] | None = None,
    strength: float | None = None,
    seed: int = 0,
    score_threshold: float | None = None,
    iou: float = 0.5,
    batch_size: int = 32,
    encoding: CameraEncoding | None = None,
) -> Metrics:
    """Precision/recall/F1 of *det* on *data*, optionally under a phenomenon.

    Args:
        det: The detector.
        data: The split to measure on (the test split for reported figures).
        phenomenon: Applied to every image first (name or instance), if given.
        params: The phenomenon's parameters (exclusive with *strength*).
        strength: ``phenomenon.strength_params(strength)`` (default 1.0 when neither is
            given).
        seed: Image *i* gets the phenomenon with seed ``seed + i``.
        score_threshold: Default: the detector's own ``score_threshold`` (0.0 when it has
            none).
        iou: IoU needed for a match.
        batch_size: Images per ``detect`` call.
        encoding: A camera's encoding every image goes through after the phenomenon (or
            alone, without one): the frames as a camera that sends JPEG delivers them.

    What it reads of the detector: ``classes`` (matched to the dataset's by name),
    ``detect(images)`` and, if present, ``score_threshold``.

    Raises:
        DetectorError: The detector's class names are not the dataset's, or both ``params``
            and ``strength`` were given.

    """
    transform: Callable[[int, Image], Image] | None = None
    if phenomenon is not None:
        phen, chosen = phenomenon_params(phenomenon, params, strength)

        def transform(i: int, image: Image) -> Image:
            out = phen.apply(image, chosen, seed=seed + i)
            return out if encoding is None else encoding.apply(out)

    elif encoding is not None:

        def transform(i: int, image: Image) -> Image:
            return encoding.apply(image)

    remap = class_map(det, data)
    thr = score_threshold
    if thr is None:
        thr = float(getattr(det, "score_threshold", 0.0))
    preds = predict(det, data, batch_size=batch_size, transform=transform)
    if remap is not None:
        preds = [DetectionResult(p.boxes, remap[p.labels], p.scores) for p in preds]
    return f1_at_iou(preds, data.truths(), iou=iou, score_threshold=thr)


def class_map(det: Detector, data: Dataset) -> npt.NDArray[np.int64] | None:
    """How the detector's class indices map onto the dataset's, by name (``None``: the same).

    The same names in another order are mapped; a class one side has and the other has not
    is an error naming both lists (matching by index would score apples as pears).

    Raises:
        DetectorError: The detector's and the dataset's class names differ.

    """
    mine, theirs = tuple(det.classes), tuple(data.classes)
    if mine == theirs:
        return None
    if sorted(mine) != sorted(theirs) or len(set(mine)) != len(mine):
        shared = [c for c in theirs if c in mine]
        raise DetectorError(
            f"the detector's classes {list(mine)} are not the dataset's {list(theirs)}; "
            "evaluate on a dataset with the same class names (their order may differ)"
            + (
                f", or on the classes both have ({', '.join(shared)}: --shared-classes, "
                "anunnaki.lec.shared_classes)"
                if shared
                else ""
            )
        )
    return np.asarray([theirs.index(name) for name in mine], dtype=np.int64)


class SharedClassesDetector:
    """A detector that reports only some of its classes, renumbered (:func:`shared_classes`).

    Args:
        inner: The detector.
        classes: The class names kept, in the order of the new label indices.

    """

    def __init__(self, inner: Detector, classes: Sequence[str]) -> None:
        self.inner = inner
        self.classes = tuple(classes)
        self.model_id = inner.model_id
        self.domain = inner.domain
        own = tuple(inner.classes)
        self._map = np.asarray([self.classes.index(c) if c in self.classes else -1 for c in own])

    @property
    def score_threshold(self) -> float:
        """The inner detector's (0.0 when it has none)."""
        return float(getattr(self.inner, "score_threshold", 0.0))

    def detect(self, images: Any, **options: Any) -> list[DetectionResult]:
        """The inner detector's detections of the kept classes (*options* passed on)."""
        out = []
        for r in self.inner.detect(images, **options):
            labels = self._map[np.asarray(r.labels, np.int64)]
            keep = labels >= 0
            out.append(DetectionResult(r.boxes[keep], labels[keep], r.scores[keep]))
        return out


def shared_classes(det: Detector, data: Dataset) -> tuple[Detector, Dataset]:
    """*det* and *data* cut to the class names both have, to measure a detector on those.

    E.g. a third-party person detector (``pedestrian``) on a dataset of ``pedestrian`` and
    ``deer``: the dataset's deer boxes (and ignore boxes) are dropped, and so are the
    detector's detections of classes the dataset lacks. A detection of a kept class on a
    dropped object (a "pedestrian" on a deer) still counts as a false positive.

    Returns:
        The detector (wrapped only if it has classes the dataset lacks) and the dataset,
        whose ``classes`` are the shared names in the dataset's order.

    Raises:
        DetectorError: The two have no class name in common (naming both lists).

    """
    mine = set(det.classes)
    shared = tuple(c for c in data.classes if c in mine)
    if not shared:
        raise DetectorError(
            f"the detector's classes {list(det.classes)} and the dataset's "
            f"{list(data.classes)} have no class in common; nothing can be measured: use a "
            "dataset labelled with (some of) the model's class names"
        )
    kept = _keep_classes(data, shared)
    if mine <= set(shared):
        return det, kept
    return SharedClassesDetector(det, shared), kept


def _keep_classes(data: Dataset, names: tuple[str, ...]) -> Dataset:
    """*data* with only the boxes (and ignore boxes) of *names*, relabelled into them."""
    if names == data.classes:
        return data
    new = np.asarray([names.index(c) if c in names else -1 for c in data.classes], np.int64)
    records = []
    for r in data.records:
        labels, ignore_labels = new[r.labels], new[r.ignore_labels]
        records.append(
            replace(
                r,
                boxes=r.boxes[labels >= 0],
                labels=labels[labels >= 0],
                ignore=r.ignore[ignore_labels >= 0],
                ignore_labels=ignore_labels[ignore_labels >= 0],
            )
        )
    return Dataset(names, records, name=f"{data.name} ({', '.join(names)})", cache=data.cache)


def _initial(
    init: str | Path | CenterNetDetector | None, classes: tuple[str, ...]
) -> CenterNetDetector | None:
    """The detector to start from (``TrainConfig.init``), checked against the data."""
    if init is None:
        return None
    from anunnaki.lec._detector import load_detector

    det = init if isinstance(init, CenterNetDetector) else load_detector(init)
    if not isinstance(det, CenterNetDetector):
        raise DetectorError(
            f"can only fine-tune a CenterNet model; {init} is a {type(det).__name__}"
        )
    if tuple(det.classes) != tuple(classes):
        raise DetectorError(
            f"the initial model's classes {det.classes} differ from the data's {classes}"
        )
    return det


def train_detector(
    train: Dataset,
    val: Dataset,
    *,
    config: TrainConfig | None = None,
    test: Dataset | None = None,
    on_step: ProgressHook | None = None,
    on_epoch: EpochHook | None = None,
    checkpoint: Callable[[TrainState], None] | None = None,
    resume: TrainState | None = None,
) -> TrainResult:
    """Train a :class:`CenterNetDetector` and measure it.

    The score threshold is chosen on *val* to maximise F1 (:func:`choose_threshold`); the
    validation and, when given, test metrics at that threshold are stored in
    ``detector.metrics`` together with the training settings in ``detector.training``.

    Args:
        train: Training split.
        val: Validation split (threshold choice).
        config: Settings (defaults: :class:`TrainConfig`).
        test: Test split for the reported figures (optional).
        on_step: Called after every optimiser step (progress bars).
        on_epoch: Called after every epoch with its figures (:data:`EpochHook`); given
            one, training also measures the val F1 after each epoch (one pass over *val*,
            in eval mode: the weights and the random draws are the same as without it).
        checkpoint: Called after every epoch (before *on_epoch*) with the
            :class:`TrainState` to save, so that a killed training can be resumed.
        resume: A state from *checkpoint* of a training with the same data and *config*:
            training continues after its epoch and ends as the uninterrupted run would.

    Raises:
        DetectorError: The splits have different classes, or a split is empty.

    """
    cfg = config or TrainConfig()
    _check_splits(train, val, test, cfg)
    seeds = np.random.SeedSequence(cfg.seed).spawn(4)
    weight_seed = int(seeds[0].generate_state(1)[0])
    rngs = {
        "order": np.random.default_rng(seeds[1]),
        "aug": np.random.default_rng(seeds[2]),
        "perturb": np.random.default_rng(seeds[3]),
    }
    random.seed(cfg.seed)
    torch.manual_seed(cfg.seed)
    first = train.image(0)
    size = cfg.input_size or (int(first.shape[1]), int(first.shape[0]))
    start_from = _initial(cfg.init, train.classes)
    det = _new_detector(cfg, train.classes, size, weight_seed, start_from)
    old_threads = torch.get_num_threads()
    if cfg.threads is not None:
        torch.set_num_threads(cfg.threads)
    try:
        loop = _Loop(
            cfg, det, _fitted(train, size, cfg), size, rngs=rngs, num_classes=len(train.classes)
        )
        if resume is not None:
            loop.restore(resume)
        for epoch in range(loop.epoch, cfg.epochs):
            loop.run_epoch(epoch, on_step)
            if checkpoint is not None:
                checkpoint(loop.state())
            if on_epoch is not None:
                on_epoch(loop.history[-1] | {"epochs": cfg.epochs, "val_f1": loop.val_f1(val)})
        seconds = loop.seconds
        loop.finish()
        det.network.eval()
        threshold, val_m, test_m = _measure(det, val, test)
    finally:
        torch.set_num_threads(old_threads)
    det.score_threshold = threshold
    metrics: dict[str, Any] = {"iou": 0.5, "score_threshold": threshold, "val": val_m.as_dict()}
    if test_m is not None:
        metrics["test"] = test_m.as_dict()
    det.metrics = metrics
    history = loop.history
    det.training = _training_record(
        cfg, train, val=val, test=test, start_from=start_from, seconds=seconds, history=history
    ) | {"steps": loop.step, **loop.counts, "consistency": cfg.consistency, "ema": cfg.ema}
    return TrainResult(det, threshold, val_m, test_m, seconds, history, dict(loop.counts))


class _Loop:
    """The optimiser loop of :func:`train_detector`, one epoch at a time (resumable)."""

    def __init__(
        self,
        cfg: TrainConfig,
        det: CenterNetDetector,
        data: list[_Sample],
        size: tuple[int, int],
        *,
        rngs: dict[str, np.random.Generator],
        num_classes: int,
    ) -> None:
        self.cfg, self.det, self.data, self.size, self.rngs = cfg, det, data, size, rngs
        self.num_classes = num_classes
        self.augmenter = (
            Augmenter(cfg.augment, probability=cfg.augment_prob) if cfg.augment else None
        )
        self.steps_per_epoch = math.ceil(len(data) / cfg.batch_size)
        total = self.steps_per_epoch * cfg.epochs
        self.total = total
        self.lr_at = _lr_schedule(cfg.lr, min(self.steps_per_epoch, total // 4 + 1), total)
        self.opt = torch.optim.AdamW(
            det.network.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay
        )
        self.history: list[dict[str, float]] = []
        self.epoch = 0
        self.step = 0
        self.seconds = 0.0
        self.ema = WeightAverage(det.network, cfg.ema) if cfg.ema > 0 else None
        self.counts = dict.fromkeys(
            ("train_forwards", "select_forwards", "consistency_forwards", "candidates"), 0
        )

    def state(self) -> TrainState:
        """The state after the last epoch (see :class:`TrainState`)."""
        rngs: dict[str, Any] = {k: g.bit_generator.state for k, g in self.rngs.items()}
        rngs["torch"] = torch.get_rng_state()
        rngs["seconds"] = self.seconds
        return TrainState(
            self.epoch,
            self.step,
            self.det.network.state_dict(),
            self.opt.state_dict(),
            rngs,
            [dict(h) for h in self.history],
            None if self.ema is None else self.ema.as_dict(),
            dict(self.counts),
        )

    def restore(self, state: TrainState) -> None:
        """Continue from *state* (weights, optimiser, random streams, counters)."""
        if not 0 < state.epoch <= self.cfg.epochs or state.step != state.epoch * (
            self.steps_per_epoch
        ):
            raise DetectorError(
                f"the checkpoint is of epoch {state.epoch}, step {state.step}; this training "
                f"has {self.cfg.epochs} epochs of {self.steps_per_epoch} steps: it was made "
                "with other data or settings — delete it to start over"
            )
        self.det.network.load_state_dict(state.network)
        self.opt.load_state_dict(state.optimizer)
        for key, gen in self.rngs.items():
            gen.bit_generator.state = state.rngs[key]
        torch.set_rng_state(state.rngs["torch"])
        self.seconds = float(state.rngs.get("seconds", 0.0))
        self.epoch, self.step = state.epoch, state.step
        self.history = [dict(h) for h in state.history]
        if (self.ema is None) != (state.ema is None):
            raise DetectorError(
                f"the checkpoint was made with ema {'on' if state.ema else 'off'}, this "
                f"training has it {'on' if self.ema else 'off'}: delete it to start over"
            )
        if self.ema is not None and state.ema is not None:
            self.ema.restore(state.ema)
        self.counts |= {k: int(v) for k, v in state.counts.items()}

    def run_epoch(self, epoch: int, on_step: ProgressHook | None) -> None:
        """One pass over the data in a fresh random order."""
        cfg, net = self.cfg, self.det.network
        net.train()
        t0 = time.perf_counter()
        sums = {"loss": 0.0, "heat": 0.0, "box": 0.0}
        if cfg.consistency > 0:
            sums["consistency"] = 0.0
        perm = self.rngs["order"].permutation(len(self.data))
        for b in range(self.steps_per_epoch):
            drawn = [
                self._sample(int(idx))
                for idx in perm[b * cfg.batch_size : (b + 1) * cfg.batch_size]
            ]
            samples = self._choose(drawn)
            x, heat_t, box_t, weight = _batch_tensors(
                samples, self.size, self.num_classes, net.stride
            )
            for group in self.opt.param_groups:
                group["lr"] = self.lr_at(self.step)
            loss, parts = self._loss((x, heat_t, box_t, weight), samples, drawn)
            self.opt.zero_grad(set_to_none=True)
            loss.backward()  # type: ignore[no-untyped-call]
            torch.nn.utils.clip_grad_norm_(net.parameters(), 10.0)
            self.opt.step()
            if self.ema is not None:
                self.ema.update(net)
            self.counts["train_forwards"] += len(samples)
            self.step += 1
            sums["loss"] += float(loss.detach())
            for k, v in parts.items():
                sums[k] += v
            if on_step is not None:
                on_step(self.step, self.total, {"epoch": epoch + 1, "loss": sums["loss"] / (b + 1)})
        seconds = time.perf_counter() - t0
        self.seconds += seconds
        self.history.append(
            {"epoch": epoch + 1, **{k: v / self.steps_per_epoch for k, v in sums.items()}}
            | {"seconds": seconds}
        )
        self.epoch = epoch + 1

    def _sample(self, index: int) -> _Drawn:
        """The augmented sample and its perturbed candidates (one, unless worst-of-k)."""
        sample = _augmented(self.data[index], self.cfg, self.size, self.rngs["aug"], self.augmenter)
        perturb, rng = self.cfg.perturb, self.rngs["perturb"]
        if perturb is None:
            return sample, [(sample[0], None)], 0
        if isinstance(perturb, CandidatePerturb):
            found = perturb.candidates(sample[0], rng)
            if not found:
                raise DetectorError(f"{type(perturb).__name__}.candidates gave no image")
            # drawn whatever the selection, so that arms differing only in it stay paired
            drawn = int(rng.integers(len(found))) if len(found) > 1 else 0
            return sample, [_masked(c) for c in found], drawn
        return sample, [_masked(perturb(sample[0], rng))], 0

    def _hidden(self, sample: _Sample, candidate: _Candidate) -> _Sample:
        """*sample* with a candidate's image; the boxes its mask hides become ignore boxes."""
        image, mask = candidate
        _, boxes, labels, ignore = sample
        if self.cfg.ignore:
            boxes, labels, ignore = hide_boxes(boxes, labels, ignore, mask)
        return image, boxes, labels, ignore

    def _choose(self, drawn: list[_Drawn]) -> list[_Sample]:
        """Each image with its kept candidate (worst-of-k: scored as the network stands)."""
        select = getattr(self.cfg.perturb, "select", "random")
        kept = [d[2] for d in drawn]
        scored = [i for i, d in enumerate(drawn) if len(d[1]) > 1 and select == "hardest"]
        self.counts["candidates"] += sum(len(d[1]) for d in drawn if len(d[1]) > 1)
        if scored:
            flat = [self._hidden(drawn[i][0], c) for i in scored for c in drawn[i][1]]
            x, heat_t, box_t, weight = _batch_tensors(
                flat, self.size, self.num_classes, self.det.network.stride
            )
            losses = candidate_losses(
                self.det.network, x, heat_t, box_t, weight, batch_size=self.cfg.batch_size
            )
            self.counts["select_forwards"] += len(flat)
            at = 0
            for i in scored:
                n = len(drawn[i][1])
                kept[i] = pick(losses[at : at + n], kept[i], "hardest")
                at += n
        return [self._hidden(d[0], d[1][k]) for d, k in zip(drawn, kept, strict=True)]

    def _loss(
        self,
        batch: tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor],
        samples: list[_Sample],
        drawn: list[_Drawn],
    ) -> tuple[torch.Tensor, dict[str, float]]:
        """The detector loss, plus λ × the consistency loss of the perturbed images."""
        x, heat_t, box_t, weight = batch
        net, lam = self.det.network, self.cfg.consistency
        views = [
            i for i, (s, d) in enumerate(zip(samples, drawn, strict=True))
            if lam > 0 and not np.array_equal(s[0], d[0][0])
        ]  # fmt: skip
        if not views:
            loss, parts = centernet_loss(net(x), heat_t, box_t, weight)
            return loss, parts | ({"consistency": 0.0} if lam > 0 else {})
        clean, *_ = _batch_tensors(
            [drawn[i][0] for i in views], self.size, self.num_classes, net.stride
        )
        heat, box = net(torch.cat([x, clean]))
        n = len(x)
        loss, parts = centernet_loss((heat[:n], box[:n]), heat_t, box_t, weight)
        extra = consistency_loss(heat[torch.as_tensor(views)], heat[n:])
        self.counts["consistency_forwards"] += len(views)
        return loss + lam * extra, parts | {"consistency": float(extra.detach())}

    def val_f1(self, val: Dataset) -> float:
        """F1 on *val* at its best threshold now, with the weights that would be saved."""
        if self.ema is None:
            return _val_f1(self.det, val)
        net = self.det.network
        current = {k: v.detach().clone() for k, v in net.state_dict().items()}
        net.load_state_dict(self.ema.state)
        try:
            return _val_f1(self.det, val)
        finally:
            net.load_state_dict(current)

    def finish(self) -> None:
        """Put the saved weights in the network: the average, when there is one."""
        if self.ema is not None:
            self.det.network.load_state_dict(self.ema.state)


def _new_detector(
    cfg: TrainConfig,
    classes: Sequence[str],
    size: tuple[int, int],
    seed: int,
    start_from: CenterNetDetector | None,
) -> CenterNetDetector:
    """A fresh detector, or one with the weights (and shape) of ``start_from``."""
    det = CenterNetDetector.create(
        classes,
        input_size=size,
        width=cfg.width if start_from is None else start_from.network.width,
        head=None if start_from is None else start_from.network.head_channels,
        stride=cfg.stride if start_from is None else start_from.network.stride,
        seed=seed,
        model_id=cfg.model_id,
        domain=cfg.domain,
    )
    if start_from is not None:
        det.network.load_state_dict(start_from.network.state_dict())
    return det


def _val_f1(det: CenterNetDetector, val: Dataset) -> float:
    """F1 on *val* at its best threshold now; the network is left in training mode."""
    det.network.eval()
    try:
        preds = predict(det, val)
        truths = val.truths()
        return float(f1_at_iou(preds, truths, score_threshold=choose_threshold(preds, truths)).f1)
    finally:
        det.network.train()


def _measure(
    det: CenterNetDetector, val: Dataset, test: Dataset | None
) -> tuple[float, Metrics, Metrics | None]:
    """The score threshold that maximises F1 on ``val``, and the metrics at it."""
    val_preds = predict(det, val)
    threshold = choose_threshold(val_preds, val.truths())
    val_m = f1_at_iou(val_preds, val.truths(), score_threshold=threshold)
    test_m = None
    if test is not None:
        test_m = f1_at_iou(predict(det, test), test.truths(), score_threshold=threshold)
    return threshold, val_m, test_m


_Sample = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""One training image with its boxes, labels and ignore boxes."""

#: A perturbed candidate: its image and the perturbation's occlusion mask (``None``: none).
_Candidate = tuple[np.ndarray, Mask | None]
_Drawn = tuple[_Sample, list[_Candidate], int]


def _masked(out: Any) -> _Candidate:
    """A perturb's output as (image, mask): it may return the image alone (no mask)."""
    return (out[0], out[1]) if isinstance(out, tuple) else (out, None)


"""A sample as augmented, its perturbed candidates and the index drawn among them."""


def _check_splits(train: Dataset, val: Dataset, test: Dataset | None, cfg: TrainConfig) -> None:
    if train.classes != val.classes or (test is not None and test.classes != train.classes):
        raise DetectorError(
            f"the splits have different classes: train {train.classes}, val {val.classes}"
            + (f", test {test.classes}" if test is not None else "")
        )
    if len(train) == 0 or len(val) == 0:
        raise DetectorError(f"empty split: train has {len(train)} images, val {len(val)}")
    if cfg.epochs < 1 or cfg.batch_size < 1:
        raise DetectorError("epochs and batch_size must be at least 1")


def _fitted(train: Dataset, size: tuple[int, int], cfg: TrainConfig) -> list[_Sample]:
    """The training images fitted to the input size, with their boxes (ignore boxes if used)."""
    data = []
    no_ignore = np.zeros((0, 4), np.float32)
    for i, r in enumerate(train.records):
        raw = train.image(i)
        image, boxes = _fit(raw, r.boxes, size)
        ignore = _fit(raw, r.ignore, size)[1] if cfg.ignore else no_ignore
        data.append((image, boxes, r.labels, ignore))
    return data


def _lr_schedule(lr: float, warmup: int, total: int) -> Callable[[int], float]:
    """Linear warm-up over ``warmup`` steps, then a cosine decay to 2 % at ``total``."""

    def lr_at(step: int) -> float:
        if step < warmup:
            return lr * (step + 1) / warmup
        t = (step - warmup) / max(1, total - warmup)
        return lr * (0.02 + 0.98 * 0.5 * (1 + math.cos(math.pi * t)))

    return lr_at


def _augmented(
    sample: _Sample,
    cfg: TrainConfig,
    size: tuple[int, int],
    rng: np.random.Generator,
    augmenter: Augmenter | None,
) -> _Sample:
    """One sample as a step sees it: zoomed, flipped, recoloured and augmented (in order)."""
    image, boxes, labels, ignore = sample
    if cfg.zoom > 0:
        image, boxes, labels, ignore = _zoom(image, boxes, labels, rng, cfg.zoom, ignore=ignore)
    if cfg.flip and rng.random() < 0.5:
        image = np.ascontiguousarray(image[:, ::-1])
        boxes = boxes.copy()
        boxes[:, [0, 2]] = size[0] - boxes[:, [2, 0]]
        ignore = ignore.copy()
        ignore[:, [0, 2]] = size[0] - ignore[:, [2, 0]]
    if cfg.photometric > 0:
        image = _photometric(image, rng, cfg.photometric)
    if augmenter is not None:
        image, mask = augmenter.occluded(image, rng)
        if cfg.ignore:
            boxes, labels, ignore = hide_boxes(boxes, labels, ignore, mask)
    return image, boxes, labels, ignore


def _training_record(
    cfg: TrainConfig,
    train: Dataset,
    *,
    val: Dataset,
    test: Dataset | None,
    start_from: CenterNetDetector | None,
    seconds: float,
    history: list[dict[str, float]],
) -> dict[str, Any]:
    """The settings and figures of a training, as ``detector.training`` keeps them."""
    return {
        "epochs": cfg.epochs,
        "batch_size": cfg.batch_size,
        "lr": cfg.lr,
        "seed": cfg.seed,
        "threads": cfg.threads,
        "augment": [a if isinstance(a, str) else a.name for a in cfg.augment],
        "augment_prob": cfg.augment_prob if cfg.augment else 0.0,
        "perturb": None if cfg.perturb is None else type(cfg.perturb).__name__,
        "flip": cfg.flip,
        "zoom": cfg.zoom,
        "photometric": cfg.photometric,
        "ignore": cfg.ignore,
        "ignore_boxes": train.num_ignore if cfg.ignore else 0,
        "init": None if start_from is None else start_from.model_id,
        "data": train.name,
        "train_images": len(train),
        "val_images": len(val),
        "test_images": len(test) if test is not None else 0,
        "seconds": round(seconds, 1),
        "images_per_second": round(len(train) * cfg.epochs / max(seconds, 1e-9), 1),
        "final_loss": history[-1]["loss"] if history else None,
    }
