"""Why a zenoh session could not connect: a probe of each endpoint, with what to check.

zenoh reports every failed connection the same way (``Unable to connect to any of
[...]``), whether nothing listens at the address, the router's certificate does not name
the host connected to, it was signed by another CA, or the router refused this node's
certificate. After such a failure, :func:`diagnose_connect` probes each ``tcp/`` and
``tls/`` endpoint once with the standard library (a TCP connection; for TLS a handshake
with the same root CA, certificate and name check as the session) and says, per endpoint,
what went wrong and what to change. It runs only after zenoh has failed, with short
deadlines, and never raises.
"""

from __future__ import annotations

import socket
import ssl
from pathlib import Path

from anunnaki.bus._config import BusConfig, TlsConfig

__all__ = ["diagnose_connect"]

_PROBE_TIMEOUT = 1.5  # s: TCP connect and TLS handshake, per endpoint
_VERDICT_WAIT = 0.5  # s: TLS 1.3 servers judge the client's certificate after the handshake

# OpenSSL verify codes (X509_V_ERR_*).
_NAME_MISMATCH = {62, 64}  # hostname, IP address
_UNKNOWN_ISSUER = {2, 19, 20, 21}  # issuer not found, self-signed in chain, local issuer, leaf
_EXPIRED = {9, 10}  # not yet valid, expired


def _split(endpoint: str) -> tuple[str, str, int] | None:
    """``(protocol, host, port)`` of ``tcp/…`` or ``tls/…``; ``None`` for other protocols."""
    protocol, _, rest = endpoint.partition("/")
    if protocol not in ("tcp", "tls"):
        return None
    address = rest.split("#", 1)[0].split("?", 1)[0]
    host, sep, port = address.rpartition(":")
    if not sep or not port.isdigit():
        return None
    return protocol, host.strip("[]"), int(port)


def diagnose_connect(config: BusConfig) -> list[str]:
    """One line per ``connect`` endpoint that a probe finds at fault, saying what to check.

    Args:
        config: The configuration whose session failed to open.

    Returns:
        ``"<endpoint>: <what is wrong>; <what to do>"`` lines; empty when every endpoint
        looks right from here (then the cause lies elsewhere, e.g. the router's rules).

    """
    out = []
    for endpoint in config.connect:
        parts = _split(endpoint)
        if parts is None:
            continue
        protocol, host, port = parts
        problem = _probe(protocol, host, port, config.tls)
        if problem:
            out.append(f"{endpoint}: {problem}")
    return out


def _probe(protocol: str, host: str, port: int, tls: TlsConfig | None) -> str:
    try:
        raw = socket.create_connection((host, port), timeout=_PROBE_TIMEOUT)
    except OSError as exc:
        return (
            f"nothing answers at {host}:{port} ({exc.strerror or exc}); check that the "
            "router runs and that this is its address and port (its listen endpoint)"
        )
    with raw:
        if protocol != "tls" or tls is None:
            return ""
        return _handshake(raw, host, tls)


def _context(tls: TlsConfig) -> ssl.SSLContext | str:
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    ctx.check_hostname = tls.verify_name
    try:
        ctx.load_verify_locations(cafile=str(tls.root_ca))
    except (OSError, ssl.SSLError) as exc:
        return f"tls.root_ca {tls.root_ca} is not a readable PEM certificate ({exc})"
    if tls.cert is not None and tls.key is not None:
        try:
            ctx.load_cert_chain(str(tls.cert), str(tls.key))
        except (OSError, ssl.SSLError) as exc:
            return (
                f"tls.cert {tls.cert} and tls.key {tls.key} do not load as a matching "
                f"certificate and key ({exc})"
            )
    return ctx


def _handshake(raw: socket.socket, host: str, tls: TlsConfig) -> str:
    ctx = _context(tls)
    if isinstance(ctx, str):
        return ctx
    try:
        with ctx.wrap_socket(raw, server_hostname=host) as conn:
            conn.settimeout(_VERDICT_WAIT)
            try:
                closed = conn.recv(1) == b""
            except TimeoutError:
                return ""  # the router waits for zenoh's first message: TLS went through
            if closed:
                return _refused_ours(tls, "it closed the connection")
            return ""
    except ssl.SSLCertVerificationError as exc:
        return _router_cert(exc, host, tls)
    except ssl.SSLError as exc:
        if "alert" in str(exc).lower():
            return _refused_ours(tls, f"TLS alert: {exc.reason or exc}")
        return f"the TLS handshake failed ({exc}); check that the router listens on tls/"
    except OSError as exc:
        return f"the TLS handshake failed ({exc}); check that the router listens on tls/"


def _router_cert(exc: ssl.SSLCertVerificationError, host: str, tls: TlsConfig) -> str:
    code = exc.verify_code
    if code in _NAME_MISMATCH:
        kind = "IP" if code == 64 else "DNS"
        return (
            f"the router's certificate does not name {host} ({exc.verify_message}); make it "
            f"with subjectAltName={kind}:{host}, or connect to a name it has"
        )
    if code in _UNKNOWN_ISSUER:
        return (
            f"the router's TLS certificate is not signed by tls.root_ca {tls.root_ca} "
            f"({exc.verify_message}); give the CA that signed the router's certificate"
        )
    if code in _EXPIRED:
        return f"the router's certificate is not valid now ({exc.verify_message}); renew it"
    return f"the router's certificate is refused ({exc.verify_message})"


def _refused_ours(tls: TlsConfig, why: str) -> str:
    if tls.cert is None:
        return (
            f"the router refused this node ({why}): it demands a client certificate "
            "(mutual TLS); give tls.cert and tls.key"
        )
    return (
        f"the router refused this node's certificate {Path(tls.cert).name} ({why}); it must "
        "be signed by the CA the router trusts (the router's root_ca), be valid now and "
        "allow extendedKeyUsage clientAuth"
    )
