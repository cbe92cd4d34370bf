"""Session fixture of the LEC tests: a trained rover detector and frames to run it on.

The shipped ``examples/models/rover-default`` on a few frames of the layouts it was never
trained on, rendered once per session in a few seconds (``lec_helpers.shipped_model``). The
one test about training trains its own model from scratch (``test_lec_train.py``, marked
``training``).
"""

from __future__ import annotations

import pytest
from lec_helpers import Trained, shipped_model


@pytest.fixture(scope="session")
def trained(tmp_path_factory: pytest.TempPathFactory) -> Trained:
    """The shipped rover detector with 20 validation and 40 test frames it never saw."""
    pytest.importorskip("pybullet")
    return shipped_model(tmp_path_factory.mktemp("lec-model"))
