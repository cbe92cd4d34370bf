"""The fine-tune step: a copy of a model trained on frames perturbed by a context source.

One function for every arm of a comparison (Enki's selection, uniform random contexts, a
corruption mix): the same images, epochs, optimiser steps and seed, only the
:class:`~anunnaki.enki.ContextSource` differs (it draws from a random stream of its own, so
the batch order, zooms and flips are the same in every arm). It is
:func:`anunnaki.lec.train_detector` started from the model's weights
(``TrainConfig.init``: the input file is only read) with the source as ``TrainConfig.perturb``.

With a checkpoint folder, the training state is saved after every epoch
(``epoch-NNN.pt``, :class:`anunnaki.lec.TrainState`) and a later call with the same
arguments continues from the last one: after Ctrl-C or ``kill -9`` it ends with the weights
an uninterrupted run has (same thread count). The folder's ``finetune.json`` records what the
checkpoints are of; other arguments are refused rather than mixed.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from anunnaki.datasets import Dataset
from anunnaki.enki._errors import EnkiError
from anunnaki.enki._sources import ContextSource
from anunnaki.lec import TrainResult, read_card, sha256_file, weights_path

__all__ = ["Budget", "finetune"]


@dataclass(frozen=True)
class Budget:
    """What every arm of a comparison spends alike.

    Attributes:
        epochs: Passes over the training split (8: today's fine-tuned rover models').
        batch_size: Images per optimiser step.
        lr: Peak learning rate (AdamW; the training loop's warm-up and cosine decay).
        threads: torch threads (results repeat bit for bit with the same count).
        ema: Decay of the weight average the saved model gets (0: off, the last weights;
            ``TrainConfig.ema``): like the learning rate, the same for every arm.

    The forward passes a source or a consistency loss adds (worst-of-k's scoring, the clean
    views) are not part of the budget's settings; they are counted and reported beside the
    optimiser steps (``detector.training``: ``select_forwards``, ``consistency_forwards``).

    """

    epochs: int = 8
    batch_size: int = 32
    lr: float = 2e-3
    threads: int | None = 2
    ema: float = 0.0

    def __post_init__(self) -> None:
        if self.epochs < 1 or self.batch_size < 1 or self.lr <= 0 or not 0 <= self.ema < 1:
            raise EnkiError(
                f"a fine-tune budget needs epochs >= 1, batch size >= 1, lr > 0 and ema in "
                f"[0, 1); got {self.epochs}, {self.batch_size}, {self.lr}, {self.ema}"
            )

    def steps(self, images: int) -> int:
        """Optimiser steps for *images* training images."""
        return -(-images // self.batch_size) * self.epochs


def _record(
    model: Path,
    train: Dataset,
    source: ContextSource,
    budget: Budget,
    *,
    seed: int,
    consistency: float,
) -> dict[str, Any]:
    record: dict[str, Any] = {
        "model_sha256": sha256_file(weights_path(model)),
        "train": train.name,
        "train_images": len(train),
        "source": source.describe(),
        "budget": asdict(budget),
        "seed": seed,
    }
    if not budget.ema:  # folders made before the weight average keep their record
        del record["budget"]["ema"]
    if consistency:
        record["consistency"] = consistency
    return record


def _latest(folder: Path) -> Path | None:
    found = sorted(folder.glob("epoch-*.pt"))
    return found[-1] if found else None


def _prepare(folder: Path, record: dict[str, Any]) -> Any:
    """Check the folder is about this fine-tune; return the last checkpoint's state."""
    from anunnaki.lec import TrainState

    folder.mkdir(parents=True, exist_ok=True)
    marker = folder / "finetune.json"
    if marker.is_file():
        old = json.loads(marker.read_text(encoding="utf-8"))
        changed = [k for k in [*record, *old] if old.get(k) != record.get(k)]
        if changed:
            key = changed[0]
            raise EnkiError(
                f"{folder}: its checkpoints are of a fine-tune with {key}={old.get(key)!r}, "
                f"this one has {key}={record.get(key)!r}; give another folder (--out) or the "
                "same settings"
            )
    else:
        for stale in folder.glob("epoch-*.pt"):
            stale.unlink()
        marker.write_text(json.dumps(record, indent=2) + "\n", encoding="utf-8")
    last = _latest(folder)
    return None if last is None else TrainState.load(last)


def finetune(
    model: str | Path,
    train: Dataset,
    val: Dataset,
    source: ContextSource,
    *,
    budget: Budget | None = None,
    seed: int = 0,
    test: Dataset | None = None,
    model_id: str | None = None,
    domain: str = "default",
    checkpoints: str | Path | None = None,
    on_step: Any = None,
    on_epoch: Any = None,
    consistency: float = 0.0,
) -> TrainResult:
    """Fine-tune a copy of *model* on *train* perturbed by *source*; threshold chosen on *val*.

    Args:
        model: A CenterNet model file (read, never written).
        train: Training split.
        val: Validation split (the score threshold; per-epoch val F1 with *on_epoch*).
        source: Perturbs each training frame (or leaves it clean).
        budget: Epochs, batch size, learning rate, threads.
        seed: Seeds the batch order, augmentation and the source's draws.
        test: Test split for the reported figures (optional).
        model_id: The new model's id (default: the input's with ``-DOMAIN``).
        domain: The new model's domain.
        checkpoints: Folder for per-epoch checkpoints (resume; see the module docstring).
        on_step: ``on_step(step, total, info)`` after every optimiser step.
        on_epoch: ``on_epoch(info)`` after every epoch (``epoch``, ``loss``, ``val_f1`` …).
        consistency: λ of the consistency loss between each perturbed frame's heat map and
            its clean view's (0: off; ``TrainConfig.consistency``).

    Returns:
        :func:`anunnaki.lec.train_detector`'s result; ``detector.training`` also holds
        ``steps``, the extra forward passes (``select_forwards``, ``consistency_forwards``),
        ``source`` and ``budget``.

    Raises:
        EnkiError: The checkpoint folder is of another fine-tune.

    """
    from anunnaki.lec import TrainConfig, train_detector

    budget = budget or Budget()
    path = weights_path(model)
    if not path.is_file():
        raise EnkiError(f"{model}: no model file there; give a NAME.safetensors made by "
                        "anunnaki train-detector")  # fmt: skip
    card = read_card(path)
    config = TrainConfig(
        epochs=budget.epochs,
        batch_size=budget.batch_size,
        lr=budget.lr,
        seed=seed,
        threads=budget.threads,
        input_size=(int(card.input_size[0]), int(card.input_size[1])),
        model_id=model_id or f"{card.model_id}-{domain}",
        domain=domain,
        init=path,
        perturb=source,
        consistency=consistency,
        ema=budget.ema,
    )
    resume, save = None, None
    if checkpoints is not None:
        folder = Path(checkpoints)
        resume = _prepare(
            folder, _record(path, train, source, budget, seed=seed, consistency=consistency)
        )

        def save(state: Any) -> None:
            state.save(folder / f"epoch-{state.epoch:03d}.pt")
            for old in folder.glob("epoch-*.pt"):
                if old.name != f"epoch-{state.epoch:03d}.pt":
                    old.unlink()

    result = train_detector(
        train, val, config=config, test=test, on_step=on_step, on_epoch=on_epoch,
        checkpoint=save, resume=resume,
    )  # fmt: skip
    result.detector.training |= {"source": source.describe(), "budget": asdict(budget)}
    return result
