"""Fixtures of Enki's tests: a tiny rendered rover dataset and a copy of the shipped models.

The dataset is four layouts of four 128 × 128 frames (8 train, 4 val, 4 test images): enough
for the shipped ``rover-default`` to find its pedestrians (a real clean F1, which the phenomena
really lower) and for every stage of the chain to run in seconds.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

MODELS = Path(__file__).resolve().parents[2] / "examples" / "models"


@pytest.fixture(scope="session")
def rover_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny rendered rover dataset (train, val, test)."""
    pytest.importorskip("pybullet")
    pytest.importorskip("ribs")
    from anunnaki.sim import make_dataset

    out = tmp_path_factory.mktemp("enki-data") / "rover"
    make_dataset(
        "rover", out, train_layouts=[0, 1], val_layouts=[2], test_layouts=[3], per_layout=4,
        width=128, height=128, seed=0, workers=1, overwrite=True,
    )  # fmt: skip
    return out


@pytest.fixture()
def models(tmp_path: Path) -> Path:
    """A copy of examples/models (the registry and its files) in a fresh folder."""
    out = tmp_path / "models"
    shutil.copytree(MODELS, out)
    return out
