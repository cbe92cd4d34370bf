"""Fixtures of the dashboard tests.

One Chromium (Debian's, through Playwright's ``executable_path``; Playwright's own browser
download is never used) serves every browser test of the session. Without it the browser tests
are skipped, or fail when ``ANUNNAKI_REQUIRE_BROWSER=1`` (as CI sets it).
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterator
from typing import Any

import pytest
from dashboard_helpers import CHROMIUM, HERE, RoverRun, need_browser


@pytest.fixture
def rover_run() -> Iterator[RoverRun]:
    run = RoverRun(HERE / "data" / "rover-approval.yaml")
    try:
        yield run
    finally:
        run.close()


@pytest.fixture(scope="session")
def chromium() -> Iterator[Any]:
    """A persistent headless Chromium context (Debian's binary), shared by the session.

    Without Chromium or Playwright the browser tests are skipped, saying how to install
    them; with ``ANUNNAKI_REQUIRE_BROWSER=1`` (CI) they fail instead.
    """
    need_browser()
    from playwright import sync_api

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
