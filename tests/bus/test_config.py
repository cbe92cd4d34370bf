"""BusConfig: validation, the zenoh configuration it stands for, and open_bus options."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from pydantic import ValidationError

from anunnaki.bus import (
    BUS_KINDS,
    AccessControl,
    AccessRule,
    BusConfig,
    BusConfigError,
    InprocBus,
    InprocHub,
    TlsConfig,
    open_bus,
)
from anunnaki.errors import ModelFileError


def test_defaults_are_safe() -> None:
    config = BusConfig(kind="zenoh")
    assert config.mode == "peer"
    assert config.multicast_scouting is False
    assert config.namespace == "anunnaki"
    assert config.effective_listen(7000) == ["tcp/127.0.0.1:7000"]
    assert BusConfig(kind="zenoh", mode="router").effective_listen() == ["tcp/127.0.0.1:7447"]
    conf = config.to_zenoh(["tcp/127.0.0.1:7000"])
    assert conf == {
        "mode": "peer",
        "listen": {"endpoints": ["tcp/127.0.0.1:7000"]},
        "connect": {"endpoints": []},
        "scouting": {"multicast": {"enabled": False}},
    }


def test_tls_and_access_control_to_zenoh() -> None:
    config = BusConfig(
        kind="zenoh",
        mode="router",
        listen=["tls/0.0.0.0:7447"],
        namespace="lab",
        tls=TlsConfig(root_ca=Path("ca.pem"), cert=Path("r.pem"), key=Path("r.key")),
        access_control=AccessControl(
            default_permission="deny",
            rules=[
                AccessRule(
                    id="ops",
                    permission="allow",
                    topics=["/utu/**"],
                    services=["/lm_manager/*"],
                    cert_common_names=["utu"],
                ),
            ],
        ),
    )
    conf = config.to_zenoh()
    assert conf["transport"]["link"]["tls"] == {
        "root_ca_certificate": "ca.pem",
        "enable_mtls": True,
        "verify_name_on_connect": True,
        "listen_certificate": "r.pem",
        "listen_private_key": "r.key",
        "connect_certificate": "r.pem",
        "connect_private_key": "r.key",
    }
    acl = conf["access_control"]
    assert acl["enabled"] is True and acl["default_permission"] == "deny"
    assert acl["rules"] == [
        {
            "id": "ops",
            "permission": "allow",
            "flows": ["ingress", "egress"],
            "messages": [
                "put", "delete", "declare_subscriber", "query", "reply", "declare_queryable"
            ],
            "key_exprs": ["lab/utu/**", "lab/srv/lm_manager/*"],
        }
    ]  # fmt: skip
    assert acl["subjects"] == [{"id": "ops/subject", "cert_common_names": ["utu"]}]
    assert acl["policies"] == [{"id": "ops/policy", "rules": ["ops"], "subjects": ["ops/subject"]}]


def test_zenoh_accepts_the_generated_configuration() -> None:
    zenoh = pytest.importorskip("zenoh")
    import json

    config = BusConfig(
        kind="zenoh",
        mode="router",
        listen=["tls/127.0.0.1:7447"],
        tls=TlsConfig(root_ca=Path("ca.pem"), cert=Path("r.pem"), key=Path("r.key")),
        access_control=AccessControl(
            rules=[AccessRule(id="r", permission="allow", topics=["/a/**"], usernames=["u"])]
        ),
    )
    conf = zenoh.Config.from_json5(json.dumps(config.to_zenoh()))
    assert json.loads(conf.get_json("transport/link/tls/enable_mtls")) is True
    assert json.loads(conf.get_json("access_control/default_permission")) == "deny"


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"kind": "inproc", "listen": ["tcp/127.0.0.1:1"]}, "only apply to the zenoh bus"),
        ({"kind": "inproc", "mode": "router"}, "only apply to the zenoh bus"),
        ({"kind": "zenoh", "mode": "client"}, "a client needs connect endpoints"),
        (
            {"kind": "zenoh", "mode": "client", "connect": ["tcp/h:1"], "listen": ["tcp/h:2"]},
            "a client does not listen",
        ),
        ({"kind": "zenoh", "listen": ["127.0.0.1:7447"]}, "is not '<protocol>/<address>'"),
        ({"kind": "zenoh", "connect": ["tls/h:1"]}, "need a tls section"),
        (
            {"kind": "zenoh", "listen": ["tls/h:1"], "tls": {"root_ca": "ca", "mutual": False}},
            "listening on tls needs tls.cert",
        ),
        ({"kind": "zenoh", "tls": {"root_ca": "ca"}}, "mutual TLS needs"),
        ({"kind": "zenoh", "tls": {"root_ca": "ca", "cert": "c"}}, "cert and key go together"),
        ({"kind": "zenoh", "namespace": "/anunnaki"}, "invalid namespace"),
        ({"kind": "zenoh", "colour": "blue"}, "Extra inputs"),
        (
            {"kind": "zenoh", "access_control": {"rules": [{"id": "r", "permission": "allow"}]}},
            "at least one of topics",
        ),
        (
            {
                "kind": "zenoh",
                "access_control": {
                    "rules": [
                        {"id": "r", "permission": "allow", "topics": ["/a"]},
                        {"id": "r", "permission": "deny", "topics": ["/b"]},
                    ]
                },
            },
            "repeated: r",
        ),
        (
            {
                "kind": "zenoh",
                "access_control": {
                    "rules": [{"id": "r", "permission": "allow", "topics": ["/a b"]}]
                },
            },
            "invalid topic pattern",
        ),
    ],
)
def test_invalid_configs(fields: dict, message: str) -> None:
    with pytest.raises(ValidationError, match=message):
        BusConfig.model_validate(fields)
    kind = fields.pop("kind")
    with pytest.raises(BusConfigError, match=message):
        open_bus(kind, **fields)


def test_open_bus_kinds_and_options() -> None:
    with pytest.raises(BusConfigError, match="unknown bus kind 'mqtt'; valid names: inproc, zenoh"):
        open_bus("mqtt")
    with pytest.raises(BusConfigError, match="hub only applies"):
        open_bus("zenoh", hub=InprocHub())
    hub = InprocHub()
    with open_bus(BusConfig(namespace="lab"), hub=hub, name="n") as bus:
        assert isinstance(bus, InprocBus)
        assert bus.hub is hub
        assert (bus.namespace, bus.name, bus.endpoints) == ("lab", "n", ())
        assert "InprocBus 'n'" in repr(bus)
    with open_bus(BusConfig(namespace="lab"), namespace="other") as bus:
        assert bus.namespace == "other"


def test_a_bus_kind_is_a_plugin_of_the_bus_kinds_slot() -> None:
    opened: list[BusConfig] = []

    def recording(
        config: BusConfig, *, clock: Any = None, hub: InprocHub | None = None
    ) -> InprocBus:
        opened.append(config)
        return InprocBus(hub=hub, namespace=config.namespace, name=config.name, clock=clock)

    assert BUS_KINDS.names() == ["inproc", "zenoh"]
    BUS_KINDS.register(recording)
    try:
        with open_bus("recording", namespace="lab") as bus:
            assert isinstance(bus, InprocBus) and bus.namespace == "lab"
        assert [c.kind for c in opened] == ["recording"]
        assert BusConfig.model_validate({"kind": "recording"}).kind == "recording"
    finally:
        BUS_KINDS.unregister("recording")
    with pytest.raises(BusConfigError, match="unknown bus kind 'recording'"):
        open_bus("recording")


def test_from_file(tmp_path: Path) -> None:
    good = tmp_path / "bus.yaml"
    good.write_text(
        "kind: zenoh\n"
        "mode: client\n"
        "connect: [tls/router.lab:7447]\n"
        "tls:\n"
        "  root_ca: /etc/anunnaki/ca.pem\n"
        "  cert: /etc/anunnaki/utu.pem\n"
        "  key: /etc/anunnaki/utu.key\n"
    )
    config = BusConfig.from_file(good)
    assert config.tls is not None and config.tls.cert == Path("/etc/anunnaki/utu.pem")
    bad = tmp_path / "bad.yaml"
    bad.write_text("kind: zenoh\nmode: client\nconnect: [tcp/h:1]\nmulticast: true\n")
    with pytest.raises(ModelFileError) as info:
        BusConfig.from_file(bad)
    assert info.value.line == 4
    assert "unknown field 'multicast'" in str(info.value)
