"""Helpers shared by the bus tests (imported by conftest.py and the test modules)."""

from __future__ import annotations

import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from anunnaki.bus import Bus, InprocHub, open_bus

BUS_KINDS = ["inproc", "zenoh"]


def free_port() -> int:
    """A TCP port free on loopback now (bind to port 0)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def wait_for(predicate: Callable[[], bool], timeout: float = 5.0) -> bool:
    """Re-check ``predicate`` until it holds or the deadline passes (never a fixed sleep)."""
    deadline = time.monotonic() + timeout
    pause = threading.Event()
    while True:
        if predicate():
            return True
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return False
        pause.wait(min(0.005, remaining))


class Collector:
    """A subscriber callback that records samples and signals when enough arrived."""

    def __init__(self) -> None:
        self.samples: list = []
        self._cond = threading.Condition()

    def __call__(self, sample: object) -> None:
        with self._cond:
            self.samples.append(sample)
            self._cond.notify_all()

    def wait(self, n: int, timeout: float = 5.0) -> bool:
        """Wait until at least ``n`` samples arrived."""
        with self._cond:
            return self._cond.wait_for(lambda: len(self.samples) >= n, timeout)

    @property
    def messages(self) -> list:
        return [s.message for s in self.samples]


@dataclass
class BusFactory:
    """Opens buses of one kind that all meet (same hub, or connected zenoh sessions)."""

    kind: str
    hub: InprocHub
    opened: list[Bus]
    first_endpoint: str | None = None

    def __call__(self, **options: Any) -> Bus:
        if self.kind == "inproc":
            bus = open_bus("inproc", hub=self.hub, **options)
        elif self.first_endpoint is None:
            bus = open_bus("zenoh", **options)
            self.first_endpoint = bus.endpoints[0]
        else:
            # Later sessions are peers that connect to the first one (two "processes").
            bus = open_bus("zenoh", connect=[self.first_endpoint], **options)
        self.opened.append(bus)
        return bus


# --- subprocesses ---------------------------------------------------------------------------


def run_python(code: str, *, timeout: float = 20.0) -> subprocess.CompletedProcess[str]:
    """Run ``code`` in a fresh interpreter (the project's venv) and return the result."""
    return subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


# --- TLS material ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Pki:
    """A throwaway PKI.

    ``ca`` signs router, alice, bob, utu, rover, operator, guest and faraway (whose SAN names
    only router.lab and 10.0.0.1); ``evil_ca`` signs mallory.
    """

    dir: Path

    def cert(self, name: str) -> Path:
        return self.dir / f"{name}.pem"

    def key(self, name: str) -> Path:
        return self.dir / f"{name}.key"


def _openssl(*args: str, cwd: Path) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True, timeout=60)


def make_ca(d: Path, name: str) -> None:
    _openssl("genpkey", "-algorithm", "EC", "-pkeyopt", "ec_paramgen_curve:P-256",
             "-out", f"{name}.key", cwd=d)  # fmt: skip
    _openssl("req", "-x509", "-new", "-key", f"{name}.key", "-subj", f"/CN={name}",
             "-days", "2", "-addext", "basicConstraints=critical,CA:TRUE",
             "-addext", "keyUsage=critical,keyCertSign,cRLSign", "-out", f"{name}.pem",
             cwd=d)  # fmt: skip


def make_leaf(d: Path, name: str, ca: str, san: str = "DNS:localhost,IP:127.0.0.1") -> None:
    _openssl("genpkey", "-algorithm", "EC", "-pkeyopt", "ec_paramgen_curve:P-256",
             "-out", f"{name}.key", cwd=d)  # fmt: skip
    _openssl("req", "-new", "-key", f"{name}.key", "-subj", f"/CN={name}",
             "-out", f"{name}.csr", cwd=d)  # fmt: skip
    (d / f"{name}.ext").write_text(
        "basicConstraints=critical,CA:FALSE\n"
        "keyUsage=critical,digitalSignature\n"
        "extendedKeyUsage=serverAuth,clientAuth\n"
        f"subjectAltName={san}\n"
    )
    _openssl("x509", "-req", "-in", f"{name}.csr", "-CA", f"{ca}.pem", "-CAkey", f"{ca}.key",
             "-CAcreateserial", "-days", "2", "-extfile", f"{name}.ext", "-out", f"{name}.pem",
             cwd=d)  # fmt: skip
