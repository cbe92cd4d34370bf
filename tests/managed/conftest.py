"""Shared fixtures for the managed-system tests."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from anunnaki.bus import open_bus


@pytest.fixture
def bus() -> Iterator[Any]:
    with open_bus("inproc") as b:
        yield b
