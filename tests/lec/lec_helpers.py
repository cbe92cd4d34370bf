"""The LEC tests' models: the shipped rover detector on a few rendered frames, and training.

Most tests need *a* trained detector and frames to run it on, not training itself: the
``trained`` fixture (conftest.py) is the shipped ``examples/models/rover-default`` with 20
validation and 40 test frames of its own held-out layouts (44-46), rendered at its 128 × 128
in a few seconds. One test trains from scratch (``test_lec_train.py``, marked ``training``):
:func:`train_session_model` renders a reduced simulated rover dataset (12 + 2 + 3 layouts of
25 frames at 96 × 96, 10 epochs) and trains it, about 25 s on the 2-core VM when it is quiet.
Until issue #34 every test here waited for that training in a session fixture, 456 s at load
5-9 on a fresh clone (the cache it had was per checkout, so CI always trained).
"""

from __future__ import annotations

import shutil
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from anunnaki.bus import Bus, Sample

#: How long a test waits for something that should happen at once: a deadline against a
#: hung test on a loaded machine, never a measurement.
DEADLINE = 30.0

#: The shipped rover detector (trained at 128 x 128 on layouts 0-39; 40-53 held out).
SHIPPED = Path(__file__).resolve().parents[2] / "examples" / "models" / "rover-default"

#: The frames the shipped model is tested on here: layouts it never saw in training.
SHIPPED_DATA: dict[str, Any] = {
    "train_layouts": [],
    "val_layouts": [44],
    "test_layouts": [45, 46],
    "per_layout": 20,
    "width": 128,
    "height": 128,
    "seed": 0,
}

#: Data and training settings of the model trained from scratch.
SETTINGS: dict[str, Any] = {
    "platform": "rover",
    "width": 96,
    "height": 96,
    "train_layouts": list(range(0, 12)),
    "val_layouts": [12, 13],
    "test_layouts": [14, 15, 16],
    "per_layout": 25,
    "seed": 0,
    "epochs": 10,
    "batch_size": 16,
    "net_width": 16,
    "threads": 1,  # two spin-wait beside a busy core: 195 s of CPU against ~30 (issue #30)
}


@dataclass(frozen=True)
class Trained:
    """A trained model and frames to run it on.

    Attributes:
        model: The weights file (its sidecar beside it).
        data: A dataset folder with ``val`` and ``test`` splits (and ``train`` when trained).
        metrics: ``{"test": {"f1": …, …}}``: the model on ``data``'s test split.
    """

    model: Path
    data: Path
    metrics: dict[str, Any]


def shipped_model(root: Path) -> Trained:
    """A copy of the shipped rover detector in ROOT, with its held-out frames in ROOT/data."""
    from anunnaki.datasets import load_split
    from anunnaki.lec import evaluate_detector, load_detector
    from anunnaki.sim import make_dataset

    root.mkdir(parents=True, exist_ok=True)
    model = root / "rover-default.safetensors"
    for suffix in (".safetensors", ".json"):
        shutil.copy(SHIPPED.with_suffix(suffix), model.with_suffix(suffix))
    make_dataset("rover", root / "data", workers=1, overwrite=True, **SHIPPED_DATA)
    test = evaluate_detector(load_detector(model), load_split(root / "data", "test"))
    return Trained(model, root / "data", {"test": test.as_dict()})


def train_session_model(root: Path) -> tuple[Trained, float]:
    """Render the reduced dataset into ROOT/data, train, save ROOT/model.safetensors.

    Returns the model and the seconds it took, rendering included.
    """
    from anunnaki.datasets import load_split
    from anunnaki.lec import TrainConfig, save_detector, train_detector
    from anunnaki.sim import make_dataset

    s = SETTINGS
    start = time.perf_counter()
    make_dataset(
        s["platform"],
        root / "data",
        train_layouts=s["train_layouts"],
        val_layouts=s["val_layouts"],
        test_layouts=s["test_layouts"],
        per_layout=s["per_layout"],
        width=s["width"],
        height=s["height"],
        seed=s["seed"],
        workers=2,
        overwrite=True,
    )
    splits = [load_split(root / "data", split, cache=True) for split in ("train", "val", "test")]
    config = TrainConfig(
        epochs=s["epochs"],
        batch_size=s["batch_size"],
        seed=s["seed"],
        width=s["net_width"],
        threads=s["threads"],
        model_id="test-rover",
    )
    result = train_detector(splits[0], splits[1], config=config, test=splits[2])
    save_detector(result.detector, root / "model.safetensors")
    trained = Trained(root / "model.safetensors", root / "data", result.detector.metrics)
    return trained, time.perf_counter() - start


class Collector:
    """Collects messages of a topic; ``wait(n)`` blocks (with a deadline) until n arrived."""

    def __init__(self, bus: Bus, topic: str) -> None:
        self.items: list[Any] = []
        self._cond = threading.Condition()
        self.sub = bus.subscribe(topic, self._on, queue=1024)

    def _on(self, sample: Sample) -> None:
        with self._cond:
            self.items.append(sample.message)
            self._cond.notify_all()

    def wait(self, n: int, timeout: float = DEADLINE) -> list[Any]:
        """Block until N messages arrived; return them all."""
        return self.wait_until(lambda items: len(items) >= n, f"{n} messages", timeout)

    def wait_until(
        self, done: Callable[[list[Any]], bool], what: str, timeout: float = DEADLINE
    ) -> list[Any]:
        """Block until ``done(messages)``; return them all."""
        with self._cond:
            assert self._cond.wait_for(lambda: done(self.items), timeout), (
                f"no {what} within {timeout} s ({len(self.items)} messages)"
            )
            return list(self.items)
