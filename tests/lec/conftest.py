"""Session fixture of the LEC tests: a small rover detector, trained once and cached.

See ``lec_helpers.py``: the model is cached under pytest's cache directory keyed by a hash of
the settings and of the source of ``anunnaki.lec``, ``anunnaki.datasets`` and ``anunnaki.sim``.
The cache is locked while it is checked and filled: with ``make test``'s two xdist workers the
first trains and the second waits, then reads its model.

Training it takes about 40 s on a quiet machine and over 120 s (the suite's per-test timeout)
on a loaded one, and pytest-timeout counts a fixture's setup against its first test: the
tests that use it get a timeout that holds the training (and the wait for the other worker's;
``SLOW_FIXTURES`` in tests/conftest.py).
"""

from __future__ import annotations

import fcntl
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
        return _trained(tmp_path_factory.mktemp("lec-model"))
    base = Path(cache.mkdir("anunnaki-lec"))
    with (base / ".lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        for old in base.iterdir():
            if old.name not in (key, ".lock"):
                shutil.rmtree(old, ignore_errors=True)
        return _trained(base / key)


def _trained(root: Path) -> Trained:
    """The model in ``root``: read when it is done there, otherwise trained there now."""
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
