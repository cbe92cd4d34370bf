"""Helpers of the dashboard tests: a deterministic rover run, frames, paths.

The rover run is the example's goal model, binding and trace with tactics that wait for an
operator's approval (data/tactics-approval.yaml), driven step by step: the test decides
when trace time moves on (``RoverRun.run_to``), so what the page must show at each point is
known exactly. Utu and the dashboard each have their own session on one in-process hub, as
they would on zenoh.
"""

from __future__ import annotations

import contextlib
import importlib.util
import json
import os
import socket
import struct
import time
import urllib.error
import urllib.request
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import pytest

from anunnaki.bus import InprocHub, open_bus
from anunnaki.managed import ScriptedSystem
from anunnaki.topics import DECISIONS as DECISIONS_TOPIC
from anunnaki.utu import AutonomicManager, load_config
from anunnaki.utu.cycle import DecisionTail

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
ROVER = ROOT / "examples" / "rover"
ARTIFACTS = HERE / "artifacts"
CHROMIUM = os.environ.get("ANUNNAKI_CHROMIUM", "/usr/bin/chromium")
TOKEN = "s3cret-Operator-token-2026"
#: Set to 1 (CI does) to make a missing browser a failure instead of a skip.
REQUIRE_BROWSER = "ANUNNAKI_REQUIRE_BROWSER"
#: Deadlines of the tests, in seconds: generous, the machine is shared (a loaded machine
#: answers late, never wrongly). Nothing waits for them unless something is wrong.
DEADLINE = 60.0
#: How long a test's dashboard waits for Utu's answer to an operator action or to its
#: start-up query (the product's defaults, 3 s, are for people watching a page).
PATIENCE = {"operator_timeout": DEADLINE}


def browser_missing() -> str | None:
    """Why the browser tests cannot run here, and how to fix it (``None``: they can)."""
    if not Path(CHROMIUM).exists():
        return (
            f"Chromium is not installed at {CHROMIUM}: install it with "
            "scripts/setup-browser.sh (as root; scripts/setup.sh runs it)"
        )
    if importlib.util.find_spec("playwright") is None:
        return "Playwright is not installed: pip install -e '.[dev]' (scripts/setup.sh does)"
    return None


def need_browser() -> None:
    """Skip the calling test without a browser, or fail it when the browser is required."""
    missing = browser_missing()
    if missing is None:
        return
    if os.environ.get(REQUIRE_BROWSER) == "1":
        pytest.fail(f"{REQUIRE_BROWSER}=1 requires the browser tests. {missing}", pytrace=False)
    pytest.skip(f"{missing} (with {REQUIRE_BROWSER}=1 this is a failure)")


def wait_for(
    predicate: Callable[[], Any], timeout: float = DEADLINE, what: str = "condition"
) -> Any:
    """Re-check ``predicate`` until it returns something true (returned) or the deadline."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.02)


def free_port() -> int:
    """A TCP port free on loopback now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def png(width: int, height: int, rgb: tuple[int, int, int]) -> bytes:
    """A solid-colour PNG file (no imaging library needed)."""
    row = b"\x00" + bytes(rgb) * width
    raw = row * height

    def chunk(kind: bytes, data: bytes) -> bytes:
        crc = zlib.crc32(kind + data) & 0xFFFFFFFF
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(raw))
        + chunk(b"IEND", b"")
    )


class RoverRun:
    """Utu (composed manager) against the scripted rover, stepped by the test."""

    def __init__(self, config: Path) -> None:
        self.hub = InprocHub()
        self.bus = open_bus("inproc", hub=self.hub, name="utu")
        cfg = load_config(config)
        self.manager = AutonomicManager.from_config(cfg, bus=self.bus)
        self.rover = ScriptedSystem(self.bus, ROVER / "trace.jsonl", publish_clock=True)
        self.tail = DecisionTail(self.manager.knowledge, from_start=True)
        self.model = self.manager.model
        self.tactics = self.manager.tactics
        self.t = -1.0

    def _publish_decisions(self) -> None:
        rows = self.tail.read()
        if rows:
            self.bus.publish(
                DECISIONS_TOPIC,
                {
                    "decisions": [
                        {"id": d.id, "t": d.t, "kind": d.kind, "tactic": d.tactic, "data": d.data}
                        for d in rows
                    ]
                },
            )

    def step(self, t: float) -> None:
        """One Utu step at ``t`` (takes queued inputs and operator calls)."""
        self.manager.step(t)
        self._publish_decisions()
        self.t = max(self.t, t)

    def run_to(self, t_end: float) -> None:
        """Replay the trace up to ``t_end``, one Utu step per instant."""
        for t in self.rover.instants():
            if self.t < t <= t_end:
                self.rover.step(t)
                self.step(t)

    def decisions(self, kind: str) -> list[Any]:
        return [d for d in self.manager.knowledge.decisions(limit=10_000) if d.kind == kind]

    def close(self) -> None:
        self.rover.close()
        self.manager.close()
        self.bus.close()


@dataclass
class Reply:
    status_code: int
    headers: dict[str, str]
    content: bytes

    def json(self) -> Any:
        return json.loads(self.content)

    @property
    def text(self) -> str:
        return self.content.decode()


class Web:
    """A tiny HTTP client on the standard library (no test-only dependency)."""

    _servers: ClassVar[list[Any]] = []

    def __init__(self, url: str) -> None:
        self.url = url.rstrip("/")

    @classmethod
    def serve(cls, app: Any) -> Web:
        """Serve ``app`` on a free loopback port until the end of the session."""
        from anunnaki.dashboard import DashboardServer

        server = DashboardServer(app, port=0)
        server.start()
        cls._servers.append(server)
        return cls(server.url)

    def request(
        self, method: str, path: str, body: Any = None, headers: dict[str, str] | None = None
    ) -> Reply:
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.url + path, data=data, method=method)
        if data is not None:
            req.add_header("Content-Type", "application/json")
        for k, v in (headers or {}).items():
            req.add_header(k, v)
        try:
            with urllib.request.urlopen(req, timeout=30) as r:
                return Reply(r.status, {k.lower(): v for k, v in r.headers.items()}, r.read())
        except urllib.error.HTTPError as e:
            return Reply(e.code, {k.lower(): v for k, v in e.headers.items()}, e.read())

    def get(self, path: str) -> Reply:
        return self.request("GET", path)

    def post(self, path: str, json: Any = None, headers: dict[str, str] | None = None) -> Reply:
        return self.request("POST", path, {} if json is None else json, headers)

    @contextlib.contextmanager
    def stream(self, path: str) -> Iterator[Any]:
        """An open streaming response (iterate it for lines; ``.headers`` as for Reply)."""
        r = urllib.request.urlopen(self.url + path, timeout=30)
        r.headers_lower = {k.lower(): v for k, v in r.headers.items()}
        try:
            yield _Stream(r)
        finally:
            r.close()


class _Stream:
    def __init__(self, response: Any) -> None:
        self._r = response
        self.headers = response.headers_lower

    def __iter__(self) -> Iterator[bytes]:
        while True:
            line = self._r.readline()
            if not line:
                return
            yield line
