"""Fixtures of the dashboard tests.

One Chromium (Debian's, through Playwright's ``executable_path``; Playwright's own browser
download is never used) serves every browser test of the session.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from dashboard_helpers import CHROMIUM, HERE, RoverRun


@pytest.fixture
def rover_run() -> Iterator[RoverRun]:
    run = RoverRun(HERE / "data" / "rover-approval.yaml")
    try:
        yield run
    finally:
        run.close()


@pytest.fixture(scope="session")
def chromium() -> Iterator[Any]:
    """A persistent headless Chromium context (Debian's binary), shared by the session."""
    if not Path(CHROMIUM).exists():
        pytest.skip(f"Chromium is not installed at {CHROMIUM}: run scripts/setup-browser.sh")
    sync_api = pytest.importorskip("playwright.sync_api")
    profile = tempfile.mkdtemp(prefix="anunnaki-chromium-")
    pw = sync_api.sync_playwright().start()
    try:
        context = pw.chromium.launch_persistent_context(
            profile,
            executable_path=CHROMIUM,
            headless=True,
            args=["--no-sandbox", "--disable-gpu", "--disable-background-networking"],
            viewport={"width": 1440, "height": 1100},
        )
        context.set_default_timeout(30_000)
        try:
            yield context
        finally:
            context.close()
    finally:
        pw.stop()
        shutil.rmtree(profile, ignore_errors=True)
