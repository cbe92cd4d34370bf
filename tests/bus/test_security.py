"""Across machines (on loopback here): a zenoh router with TLS, mutual TLS and access control.

A throwaway PKI is made with the openssl CLI (fixture ``pki``): ``ca`` signs the router's,
alice's and bob's certificates; ``evil_ca`` signs mallory's.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from bus_helpers import Collector, Pki, free_port

from anunnaki.bus import AccessControl, AccessRule, Bus, BusConnectError, TlsConfig, open_bus
from anunnaki.messages import ModeReply, ModeRequest

pytest.importorskip("zenoh")
pytestmark = pytest.mark.slow


def tls_for(pki: Pki, name: str, ca: str = "ca") -> TlsConfig:
    return TlsConfig(root_ca=pki.cert(ca), cert=pki.cert(name), key=pki.key(name))


class Network:
    """A TLS router and the clients that connect to it; closes them all."""

    def __init__(self, pki: Pki, access_control: AccessControl | None = None) -> None:
        self.pki = pki
        self.endpoint = f"tls/127.0.0.1:{free_port()}"
        self.buses: list[Bus] = []
        self.router = self._keep(
            open_bus(
                "zenoh",
                mode="router",
                listen=[self.endpoint],
                tls=tls_for(pki, "router"),
                access_control=access_control,
                name="router",
            )
        )

    def _keep(self, bus: Bus) -> Bus:
        self.buses.append(bus)
        return bus

    def client(self, name: str, *, ca: str = "ca", tls: TlsConfig | None = None) -> Bus:
        return self._keep(
            open_bus(
                "zenoh",
                mode="client",
                connect=[self.endpoint],
                tls=tls or tls_for(self.pki, name, ca),
                name=name,
            )
        )

    def close(self) -> None:
        for bus in reversed(self.buses):
            bus.close()


@pytest.fixture
def network(pki: Pki) -> Iterator[Network]:
    net = Network(pki)
    yield net
    net.close()


def test_clients_with_the_right_ca_talk_through_the_tls_router(network: Network) -> None:
    alice, bob = network.client("alice"), network.client("bob")
    got = Collector()
    alice.subscribe("/rover/**", got)
    alice.service("/rover/set_mode", lambda r: ModeReply(mode=r.mode, accepted=True))
    pub = bob.publisher("/rover/sensors")
    assert pub.wait_for_subscribers(5)
    pub.put({"mode": "autonomous"})
    assert got.wait(1)
    assert got.samples[0].sender == "bob"
    assert bob.request("/rover/set_mode", ModeRequest(mode="manual"), timeout=5).accepted  # type: ignore[attr-defined]


def test_wrong_root_ca_is_refused(network: Network, pki: Pki) -> None:
    # Mallory's certificate is signed by another CA, which is also all she trusts.
    with pytest.raises(BusConnectError, match="TLS"):
        network.client("mallory", ca="evil_ca")
    # Alice's own certificate, but a root CA that did not sign the router's certificate.
    with pytest.raises(BusConnectError):
        network.client("alice", tls=tls_for(pki, "alice", ca="evil_ca"))
    # The right CA but no client certificate: the router demands one (mutual TLS).
    with pytest.raises(BusConnectError):
        network.client("anon", tls=TlsConfig(root_ca=pki.cert("ca"), mutual=False))


def test_access_control_denies_a_key_for_one_client(pki: Pki) -> None:
    acl = AccessControl(
        default_permission="allow",
        rules=[
            AccessRule(
                id="bob-may-not-publish-secrets",
                permission="deny",
                topics=["/secret/**"],
                messages=["put"],
                flows=["ingress"],
                cert_common_names=["bob"],
            )
        ],
    )
    net = Network(pki, acl)
    try:
        alice, bob = net.client("alice"), net.client("bob")
        got = Collector()
        alice.subscribe("/**", got)
        secret, public = bob.publisher("/secret/plan"), bob.publisher("/public/status")
        assert public.wait_for_subscribers(5)
        assert secret.wait_for_subscribers(5)
        secret.put({"plan": "x"})  # denied at the router
        public.put({"status": "ok"})  # same QoS and link, so it arrives after a leaked secret
        assert got.wait(1)
        alice.publish("/end", {})
        assert got.wait(2)
        assert [s.topic for s in got.samples] == ["/public/status", "/end"]
        # The rule binds bob only: alice may publish on the same key.
        alice_secret = alice.publisher("/secret/plan")
        assert alice_secret.wait_for_subscribers(5)
        alice_secret.put({"plan": "y"})
        assert got.wait(3)
        assert got.samples[2].topic == "/secret/plan"
    finally:
        net.close()


def test_access_control_whitelist(pki: Pki) -> None:
    acl = AccessControl(
        default_permission="deny",
        rules=[
            AccessRule(
                id="status-for-all",
                permission="allow",
                topics=["/status/**"],
                messages=["put", "declare_subscriber"],
                cert_common_names=["alice", "bob"],
            )
        ],
    )
    net = Network(pki, acl)
    try:
        alice, bob = net.client("alice"), net.client("bob")
        got = Collector()
        alice.subscribe("/status/**", got)
        alice.subscribe("/other/**", got)  # its declaration is denied
        status = bob.publisher("/status/battery")
        other = bob.publisher("/other/battery")
        assert status.wait_for_subscribers(5)
        # bob's side believes alice's /other subscription exists, so the put is sent: the
        # router's access control is what stops it.
        assert other.wait_for_subscribers(5)
        other.put({"level": 0.1})
        status.put({"level": 0.9})
        assert got.wait(1)
        status.put({"level": 0.8})
        assert got.wait(2)
        # /other was put before both status messages on the same link: never delivered.
        assert [s.topic for s in got.samples] == ["/status/battery"] * 2
    finally:
        net.close()
