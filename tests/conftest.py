"""Shared test configuration.

Hypothesis runs without its per-example deadline: a deadline is a timed assertion, and on
this project's shared 2-core machines a loaded moment made property tests fail that had
nothing wrong (measurements live in benchmarks/, not in tests).
"""

import os
from collections.abc import Iterator

import pytest
from hypothesis import settings

settings.register_profile("anunnaki", deadline=None)
settings.load_profile("anunnaki")


@pytest.fixture(autouse=True, scope="session")
def _private_operator_token(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """Utu's own operator token file (docs/running.md) lives in the session's folder.

    Every Utu of the suite, and the processes it starts, writes and reads it there (the
    variable is inherited), never in the user's ``~/.config``; clients send it as documented.
    """
    old = os.environ.get("XDG_CONFIG_HOME")
    os.environ["XDG_CONFIG_HOME"] = str(tmp_path_factory.mktemp("config"))
    yield
    if old is None:
        del os.environ["XDG_CONFIG_HOME"]
    else:
        os.environ["XDG_CONFIG_HOME"] = old
