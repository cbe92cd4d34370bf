"""A refused zenoh client is told what to check: the address, the router's SAN, the CAs.

zenoh says ``Unable to connect to any of [...]`` whatever the cause; ``BusConnectError``
adds what a probe of the endpoint found (``anunnaki.bus._diagnose``). Each case is a real
TLS router on loopback and a client that gets one thing wrong.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from bus_helpers import Pki, free_port

from anunnaki.bus import Bus, BusConnectError, TlsConfig, open_bus

pytest.importorskip("zenoh")
pytestmark = pytest.mark.slow


def tls(pki: Pki, name: str, ca: str = "ca") -> TlsConfig:
    return TlsConfig(root_ca=pki.cert(ca), cert=pki.cert(name), key=pki.key(name))


def router(pki: Pki, cert: str) -> Bus:
    endpoint = f"tls/127.0.0.1:{free_port()}"
    return open_bus("zenoh", mode="router", listen=[endpoint], tls=tls(pki, cert), name="router")


@pytest.fixture
def good_router(pki: Pki) -> Iterator[str]:
    with router(pki, "router") as bus:
        yield bus.endpoints[0]


def refusal(endpoint: str, client_tls: TlsConfig) -> str:
    with pytest.raises(BusConnectError) as info:
        open_bus("zenoh", mode="client", connect=[endpoint], tls=client_tls, name="client")
    return str(info.value)


def test_nothing_listening_names_the_address(pki: Pki) -> None:
    port = free_port()
    text = refusal(f"tls/127.0.0.1:{port}", tls(pki, "alice"))
    assert f"nothing answers at 127.0.0.1:{port}" in text
    assert "router runs" in text


def test_a_router_certificate_without_the_loopback_ip_names_the_missing_san(pki: Pki) -> None:
    with router(pki, "faraway") as bus:
        text = refusal(bus.endpoints[0], tls(pki, "alice"))
    assert "Unable to connect" in text  # zenoh's own words stay
    assert "the router's certificate does not name 127.0.0.1" in text
    assert "subjectAltName=IP:127.0.0.1" in text


def test_a_router_signed_by_another_ca_is_named(pki: Pki, good_router: str) -> None:
    text = refusal(good_router, tls(pki, "alice", ca="evil_ca"))
    assert "the router's TLS certificate is not signed by tls.root_ca" in text
    assert "evil_ca.pem" in text


def test_a_client_certificate_the_router_does_not_trust_is_named(
    pki: Pki, good_router: str
) -> None:
    mallory = TlsConfig(root_ca=pki.cert("ca"), cert=pki.cert("mallory"), key=pki.key("mallory"))
    text = refusal(good_router, mallory)
    assert "the router refused this node's certificate mallory.pem" in text


def test_no_client_certificate_under_mutual_tls_is_named(pki: Pki, good_router: str) -> None:
    text = refusal(good_router, TlsConfig(root_ca=pki.cert("ca"), mutual=False))
    assert "it demands a client certificate (mutual TLS)" in text
