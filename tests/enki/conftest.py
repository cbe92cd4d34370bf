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

#: Seconds a test that uses the rendered dataset may take, its rendering included: quiet it is
#: a few seconds, but pytest-timeout counts a session fixture's setup against its first test,
#: and at load 35 the rendering alone passed the suite's 120 s (a helper's run, 2026-11-27).
RENDERED_TIMEOUT = 600


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Give the tests here that use the rendered dataset a timeout that holds its rendering."""
    here = Path(__file__).parent
    for item in items:
        if (
            item.path.is_relative_to(here)
            and "rover_data" in getattr(item, "fixturenames", ())
            and item.get_closest_marker("timeout") is None
        ):
            item.add_marker(pytest.mark.timeout(RENDERED_TIMEOUT))


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
