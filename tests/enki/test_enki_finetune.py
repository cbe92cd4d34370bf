"""The fine-tune step: arms with one seed and budget train on the same images, equally long."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("torch")

from anunnaki.datasets import load_split
from anunnaki.enki import (
    ArchiveContexts,
    Budget,
    ContextSource,
    CorruptionMix,
    EnkiError,
    UniformContexts,
    finetune,
)
from anunnaki.lec import sha256_file


class Recorder(ContextSource):
    """Records a hash of every image the loop hands over, then lets *inner* perturb it."""

    kind = "recorder"

    def __init__(self, inner: ContextSource) -> None:
        super().__init__(clean=0.0)
        self.inner = inner
        self.seen: list[str] = []
        self.changed = 0

    def perturb(self, image: Any, rng: np.random.Generator) -> Any:
        self.seen.append(hashlib.sha256(image.tobytes()).hexdigest())
        out = self.inner(image, rng)
        self.changed += int(not np.array_equal(out, image))
        return out


def test_three_arms_same_seed_and_budget_same_steps_on_the_same_images(
    rover_data: Path, models: Path
) -> None:
    train, val = load_split(rover_data, "train"), load_split(rover_data, "val")
    model = models / "rover-default.safetensors"
    before = sha256_file(model)
    budget = Budget(epochs=2, batch_size=3, threads=1)
    arms = {
        "enki": ArchiveContexts("hsl", [[0.5, 0.1, 0.2], [0.9, 0.8, 0.1]], clean=0.2),
        "uniform": UniformContexts("hsl", clean=0.2),
        "mix": CorruptionMix(exclude=("snow", "motion_blur"), clean=0.2),
    }
    seen, steps = {}, {}
    for name, source in arms.items():
        recorder = Recorder(source)
        result = finetune(model, train, val, recorder, budget=budget, seed=3, domain="hsl")
        seen[name], steps[name] = recorder.seen, result.detector.training["steps"]
        assert recorder.changed > 0  # the source really perturbed frames
        assert result.detector.training["source"]["kind"] == "recorder"
    assert steps == {"enki": 6, "uniform": 6, "mix": 6} and budget.steps(len(train)) == 6
    assert len(seen["enki"]) == 2 * len(train)
    assert seen["enki"] == seen["uniform"] == seen["mix"]
    assert sha256_file(model) == before
    assert "snow" not in arms["mix"].describe()["phenomena"]


def test_checkpoints_refuse_another_fine_tune(
    rover_data: Path, models: Path, tmp_path: Path
) -> None:
    train, val = load_split(rover_data, "train"), load_split(rover_data, "val")
    model = models / "rover-default.safetensors"
    budget = Budget(epochs=1, batch_size=8, threads=1)
    finetune(model, train, val, UniformContexts("fog"), budget=budget, checkpoints=tmp_path / "c")
    assert (tmp_path / "c" / "epoch-001.pt").is_file()
    with pytest.raises(EnkiError, match="seed"):
        finetune(model, train, val, UniformContexts("fog"), budget=budget, seed=1,
                 checkpoints=tmp_path / "c")  # fmt: skip
    with pytest.raises(EnkiError, match="no model file"):
        finetune(tmp_path / "none.safetensors", train, val, UniformContexts("fog"))
    with pytest.raises(EnkiError, match="clean share"):
        UniformContexts("fog", clean=1.0)
