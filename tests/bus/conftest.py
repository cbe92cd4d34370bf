"""Fixtures of the bus tests: one contract suite runs against every bus implementation."""

from __future__ import annotations

import shutil
from collections.abc import Iterator

import pytest
from bus_helpers import BUS_KINDS, BusFactory, Pki, make_ca, make_leaf

from anunnaki.bus import Bus, InprocHub


@pytest.fixture(params=BUS_KINDS)
def bus_kind(request: pytest.FixtureRequest) -> str:
    return str(request.param)


@pytest.fixture
def make_bus(bus_kind: str) -> Iterator[BusFactory]:
    factory = BusFactory(bus_kind, InprocHub(), [])
    yield factory
    for bus in factory.opened:
        bus.close()


@pytest.fixture
def bus_pair(make_bus: BusFactory) -> tuple[Bus, Bus]:
    """Two buses that see each other: ``(a, b)``; for zenoh two sessions on loopback."""
    return make_bus(), make_bus()


@pytest.fixture(scope="session")
def pki(tmp_path_factory: pytest.TempPathFactory) -> Pki:
    """Certificates made with the openssl CLI (no Python crypto dependency needed)."""
    if shutil.which("openssl") is None:
        pytest.skip("the openssl command is needed to make test certificates")
    d = tmp_path_factory.mktemp("pki")
    make_ca(d, "ca")
    make_ca(d, "evil_ca")
    for name in ("router", "alice", "bob", "utu", "rover", "operator", "guest"):
        make_leaf(d, name, "ca")
    make_leaf(d, "mallory", "evil_ca")
    make_leaf(d, "faraway", "ca", san="DNS:router.lab,IP:10.0.0.1")  # names no loopback host
    return Pki(d)
