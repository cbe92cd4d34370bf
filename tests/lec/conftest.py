"""Session fixture of the LEC tests: a small rover detector, trained once and cached.

See ``lec_helpers.py``: the model is cached under pytest's cache directory keyed by a hash of
the settings and of the source of ``anunnaki.lec``, ``anunnaki.datasets`` and ``anunnaki.sim``.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from lec_helpers import Trained, cache_key, train_session_model


@pytest.fixture(scope="session")
def trained(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Trained:
    """The session's small rover model (trained on first use, then cached by key)."""
    key = cache_key()
    cache = getattr(request.config, "cache", None)
    if cache is None:
        root = tmp_path_factory.mktemp("lec-model")
    else:
        base = Path(cache.mkdir("anunnaki-lec"))
        for old in base.iterdir():
            if old.name != key:
                shutil.rmtree(old, ignore_errors=True)
        root = base / key
    done = root / "done.json"
    if done.is_file():
        info = json.loads(done.read_text())
        return Trained(root / "model.safetensors", root / "data", info["metrics"], 0.0, True)
    if root.exists():
        shutil.rmtree(root)
    root.mkdir(parents=True)
    metrics, seconds = train_session_model(root)
    done.write_text(json.dumps({"metrics": metrics, "seconds": seconds}))
    return Trained(root / "model.safetensors", root / "data", metrics, seconds, False)
