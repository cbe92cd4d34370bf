"""Bus configuration: one typed class, validated on load (YAML or keyword arguments).

A :class:`BusConfig` says which bus to open and, for zenoh, how the session joins the
network. Defaults are safe on one machine: a peer listening on loopback only, multicast
scouting off. Across machines, run a router with TLS (and access control) and let the nodes
connect to it as clients; see ``docs/bus.md``.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Literal, Self

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from anunnaki.bus._keys import (
    DEFAULT_NAMESPACE,
    service_key,
    validate_namespace,
    validate_pattern,
)
from anunnaki.bus._kinds import BUS_KINDS

__all__ = ["AccessControl", "AccessRule", "BusConfig", "TlsConfig", "on_loopback"]

_ENDPOINT = re.compile(r"(tcp|udp|tls|quic|ws|unixsock-stream|unixpipe|vsock|serial)/\S+")
AclMessage = Literal[
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "reply",
    "declare_queryable",
    "liveliness_token",
    "declare_liveliness_subscriber",
    "liveliness_query",
]
Flow = Literal["ingress", "egress"]
_BOTH_FLOWS: tuple[Flow, ...] = ("ingress", "egress")
_TOPIC_MESSAGES: tuple[AclMessage, ...] = ("put", "delete", "declare_subscriber")
_SERVICE_MESSAGES: tuple[AclMessage, ...] = ("query", "reply", "declare_queryable")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class TlsConfig(_Strict):
    """TLS for ``tls/…`` endpoints (zenoh ``transport.link.tls``).

    Attributes:
        root_ca: PEM file of the certificate authority that signed the other side's
            certificate (a router checks clients with it when ``mutual``; a client checks
            the router).
        cert: PEM certificate of this node (needed to listen on TLS, and for ``mutual``).
        key: PEM private key of ``cert``.
        mutual: Mutual TLS: a listener demands a certificate signed by ``root_ca`` from every
            client and a client presents ``cert``. Access-control rules by certificate common
            name need it.
        verify_name: Check that the router's certificate names the host connected to.

    """

    root_ca: Path
    cert: Path | None = None
    key: Path | None = None
    mutual: bool = True
    verify_name: bool = True

    @model_validator(mode="after")
    def _pair(self) -> Self:
        if (self.cert is None) != (self.key is None):
            raise ValueError("cert and key go together: give both or neither")
        if self.mutual and self.cert is None:
            raise ValueError("mutual TLS needs this node's cert and key (or set mutual: false)")
        return self

    def files(self) -> dict[str, Path]:
        """Return the files this section names, by field."""
        out = {"root_ca": self.root_ca}
        if self.cert is not None and self.key is not None:
            out |= {"cert": self.cert, "key": self.key}
        return out


class AccessRule(_Strict):
    """One access-control rule: who (subject), what (messages), where (topics/services).

    Topics and services are ROS-style names or patterns, mapped into the bus namespace;
    ``keys`` takes raw zenoh key expressions. A rule without subject fields applies to
    everybody.

    Attributes:
        id: A unique rule name.
        permission: ``"allow"`` or ``"deny"``.
        topics: Topic names or patterns (``/secret/**``).
        services: Service names or patterns.
        keys: Raw zenoh key expressions.
        messages: zenoh message kinds; default: put, delete and declare_subscriber for topics,
            query, reply and declare_queryable for services.
        flows: ``ingress`` (from the subject) and/or ``egress`` (to the subject).
        cert_common_names: Subjects by TLS certificate common name (needs mutual TLS).
        usernames: Subjects by zenoh user name.
        interfaces: Subjects by network interface (``lo``, ``eth0``).

    """

    id: str = Field(min_length=1)
    permission: Literal["allow", "deny"]
    topics: list[str] = Field(default_factory=list)
    services: list[str] = Field(default_factory=list)
    keys: list[str] = Field(default_factory=list)
    messages: list[AclMessage] | None = None
    flows: list[Flow] = Field(default_factory=lambda: list(_BOTH_FLOWS), min_length=1)
    cert_common_names: list[str] = Field(default_factory=list)
    usernames: list[str] = Field(default_factory=list)
    interfaces: list[str] = Field(default_factory=list)

    @field_validator("topics", "services")
    @classmethod
    def _names(cls, names: list[str]) -> list[str]:
        return [validate_pattern(n) for n in names]

    @model_validator(mode="after")
    def _has_keys(self) -> Self:
        if not (self.topics or self.services or self.keys):
            raise ValueError("a rule needs at least one of topics, services or keys")
        return self

    def key_exprs(self, namespace: str) -> list[str]:
        """Return the rule's zenoh key expressions in ``namespace``."""
        out = [namespace + t for t in self.topics]
        out += [service_key_pattern(s, namespace) for s in self.services]
        return out + list(self.keys)

    def message_kinds(self) -> list[AclMessage]:
        """Return the zenoh message kinds the rule covers."""
        if self.messages is not None:
            return list(self.messages)
        kinds: list[AclMessage] = []
        if self.topics or self.keys:
            kinds += _TOPIC_MESSAGES
        if self.services or self.keys:
            kinds += _SERVICE_MESSAGES
        return kinds


def service_key_pattern(pattern: str, namespace: str) -> str:
    """Key of a service name or pattern (patterns may contain ``*``/``**``)."""
    if "*" in pattern:
        return f"{namespace}/srv{validate_pattern(pattern)}"
    return service_key(pattern, namespace)


class AccessControl(_Strict):
    """Access control enforced by the zenoh instance that carries it (usually the router).

    Attributes:
        default_permission: What happens to messages no rule matches. ``"deny"`` makes the
            rules a whitelist: remember to allow ``declare_subscriber`` for subscribers.
        rules: The rules, each applied to its own subjects.

    """

    default_permission: Literal["allow", "deny"] = "deny"
    rules: list[AccessRule] = Field(default_factory=list)

    @model_validator(mode="after")
    def _unique(self) -> Self:
        ids = [r.id for r in self.rules]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"rule ids must be unique; repeated: {', '.join(dup)}")
        return self

    def to_zenoh(self, namespace: str) -> dict[str, Any]:
        """Build the zenoh ``access_control`` section (zenoh 1.x: rules, subjects, policies)."""
        rules: list[dict[str, Any]] = []
        subjects: list[dict[str, Any]] = []
        policies: list[dict[str, Any]] = []
        for rule in self.rules:
            rules.append(
                {
                    "id": rule.id,
                    "permission": rule.permission,
                    "flows": list(rule.flows),
                    "messages": rule.message_kinds(),
                    "key_exprs": rule.key_exprs(namespace),
                }
            )
            subject: dict[str, Any] = {"id": f"{rule.id}/subject"}
            for field in ("cert_common_names", "usernames", "interfaces"):
                values = getattr(rule, field)
                if values:
                    subject[field] = list(values)
            subjects.append(subject)
            policies.append(
                {"id": f"{rule.id}/policy", "rules": [rule.id], "subjects": [subject["id"]]}
            )
        return {
            "enabled": True,
            "default_permission": self.default_permission,
            "rules": rules,
            "subjects": subjects,
            "policies": policies,
        }


class BusConfig(_Strict):
    """Which bus to open, and how a zenoh session joins the network.

    Attributes:
        kind: A name in :data:`~anunnaki.bus.BUS_KINDS`: ``"inproc"`` (one process, tests),
            ``"zenoh"``, or a plugin's.
        mode: zenoh mode: ``"peer"`` (default), ``"client"`` (connects to a router) or
            ``"router"``.
        listen: Endpoints to listen on, e.g. ``tcp/127.0.0.1:7447``, ``tls/0.0.0.0:7447``.
            Default: a peer listens on ``tcp/127.0.0.1:<free port>``, a router on
            ``tcp/127.0.0.1:7447``, a client nowhere.
        connect: Endpoints to connect to (peers or a router).
        multicast_scouting: Discover peers by UDP multicast (off: name endpoints instead).
        tls: TLS certificates for ``tls/`` endpoints.
        access_control: Rules this instance enforces (usually set on the router).
        namespace: Key prefix isolating this system on a shared network.
        name: This bus's name in message envelopes (``sender``); default host-pid-random.
        zenoh: Raw zenoh config entries applied last, by path
            (``{"transport/link/tx/lease": 3000}``); for what this class does not cover.

    """

    kind: str = "inproc"
    mode: Literal["peer", "client", "router"] = "peer"
    listen: list[str] = Field(default_factory=list)
    connect: list[str] = Field(default_factory=list)
    multicast_scouting: bool = False
    tls: TlsConfig | None = None
    access_control: AccessControl | None = None
    namespace: str = DEFAULT_NAMESPACE
    name: str | None = None
    zenoh: dict[str, Any] = Field(default_factory=dict)

    @field_validator("kind")
    @classmethod
    def _kind(cls, value: str) -> str:
        if value not in BUS_KINDS:
            raise ValueError(str(BUS_KINDS.unknown(value)))
        return value

    @field_validator("namespace")
    @classmethod
    def _namespace(cls, value: str) -> str:
        return validate_namespace(value)

    @field_validator("listen", "connect")
    @classmethod
    def _endpoints(cls, values: list[str]) -> list[str]:
        for ep in values:
            if not _ENDPOINT.fullmatch(ep):
                raise ValueError(
                    f"endpoint {ep!r} is not '<protocol>/<address>' with a zenoh protocol "
                    "(tcp, udp, tls, quic, ws, unixsock-stream, …), e.g. tcp/127.0.0.1:7447"
                )
        return values

    @model_validator(mode="after")
    def _consistent(self) -> Self:
        if self.kind == "inproc":
            used = [
                f
                for f in ("listen", "connect", "tls", "access_control", "zenoh")
                if getattr(self, f)
            ]
            if self.mode != "peer":
                used.append("mode")
            if self.multicast_scouting:
                used.append("multicast_scouting")
            if used:
                raise ValueError(f"{', '.join(used)} only apply to the zenoh bus; set kind: zenoh")
            return self
        if self.mode == "client":
            if self.listen:
                raise ValueError("a client does not listen; remove listen or use mode peer")
            if not self.connect and not self.multicast_scouting:
                raise ValueError("a client needs connect endpoints (its router's)")
        uses_tls = any(ep.startswith(("tls/", "quic/")) for ep in self.listen + self.connect)
        if uses_tls and self.tls is None:
            raise ValueError("tls/quic endpoints need a tls section (root_ca, cert, key)")
        listens_tls = any(ep.startswith(("tls/", "quic/")) for ep in self.listen)
        if self.tls is not None and self.tls.cert is None and listens_tls:
            raise ValueError("listening on tls needs tls.cert and tls.key")
        return self

    def effective_listen(self, free_port: int | None = None) -> list[str]:
        """Return the listen endpoints used: the given ones, or the mode's loopback default."""
        if self.listen or self.mode == "client":
            return list(self.listen)
        if self.mode == "router":
            return ["tcp/127.0.0.1:7447"]
        return [f"tcp/127.0.0.1:{free_port if free_port is not None else 0}"]

    def to_zenoh(self, listen: list[str] | None = None) -> dict[str, Any]:
        """Build the zenoh configuration (a JSON5-able dict) this config stands for.

        It can be written to a file for a standalone ``zenohd`` router. ``zenoh`` raw
        entries are not included (they are applied by path when the session opens).
        """
        conf: dict[str, Any] = {
            "mode": self.mode,
            "listen": {"endpoints": listen if listen is not None else self.effective_listen()},
            "connect": {"endpoints": list(self.connect)},
            "scouting": {"multicast": {"enabled": self.multicast_scouting}},
        }
        if self.tls is not None:
            tls: dict[str, Any] = {
                "root_ca_certificate": str(self.tls.root_ca),
                "enable_mtls": self.tls.mutual,
                "verify_name_on_connect": self.tls.verify_name,
            }
            if self.tls.cert is not None and self.tls.key is not None:
                tls |= {
                    "listen_certificate": str(self.tls.cert),
                    "listen_private_key": str(self.tls.key),
                    "connect_certificate": str(self.tls.cert),
                    "connect_private_key": str(self.tls.key),
                }
            conf["transport"] = {"link": {"tls": tls}}
        if self.access_control is not None:
            conf["access_control"] = self.access_control.to_zenoh(self.namespace)
        return conf

    @classmethod
    def from_file(cls, path: str | Path) -> BusConfig:
        """Load and validate a YAML bus config.

        Raises:
            anunnaki.errors.ModelFileError: Unreadable YAML or an invalid field, naming the
                file, the line and the field.

        """
        from anunnaki._safeyaml import load_yaml, validation_error
        from anunnaki.errors import ModelFileError

        data, lines = load_yaml(path)
        if not isinstance(data, dict):
            raise ModelFileError("a bus config is a YAML mapping", path=path, line=1)
        try:
            return cls.model_validate(data)
        except ValidationError as exc:
            raise validation_error(exc, data, lines, path) from None


def on_loopback(endpoint: str) -> str:
    """How a process on this machine reaches ``endpoint`` (``0.0.0.0``/``[::]`` → loopback)."""
    return endpoint.replace("/0.0.0.0:", "/127.0.0.1:").replace("/[::]:", "/[::1]:")
