"""Notifications sent for real: e-mail to a local aiosmtpd server, webhooks to a local HTTP server.

Every server runs on 127.0.0.1 on a port the OS picked, in a thread that the fixtures stop and
join. Nothing waits by sleeping: tests wait on events with deadlines.
"""

from __future__ import annotations

import asyncio
import email
import email.policy
import json
import logging
import re
import shutil
import smtplib
import socket
import ssl
import subprocess
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from email.message import EmailMessage
from email.utils import parsedate_to_datetime
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import pytest
import yaml
from pydantic import ValidationError

pytest.importorskip("aiosmtpd")

from aiosmtpd.controller import Controller
from aiosmtpd.smtp import SMTP, AuthResult, Envelope, LoginPassword, Session

from anunnaki.tactics import NotifyAction
from anunnaki.utu.host._notify import (
    LOGGER_NAME,
    Notification,
    Notifier,
    NotifyConfig,
    NotifyResult,
    SmtpConfig,
    WebhookConfig,
)

DEADLINE = 10.0  # seconds any wait may take before the test fails
ROOT = Path(__file__).resolve().parents[2]


# --------------------------------------------------------------------------- helpers


def note(
    channel: Any = "email", to: str | None = "operator@example.com", **kw: Any
) -> Notification:
    fields: dict[str, Any] = {
        "subject": "Rover switched to manual",
        "message": "Object detection is degraded; the rover is now in manual mode.",
        "tactic": "fail-safe",
        "t": 12.5,
        "details": {"goal": "G3", "state": "unsatisfied"},
    }
    fields.update(kw)
    return Notification(channel=channel, to=to, **fields)


def closed_port() -> int:
    """A port on 127.0.0.1 that nothing listens on (it was free a moment ago)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture
def make_notifier() -> Iterator[Callable[..., Notifier]]:
    made: list[Notifier] = []

    def make(config: NotifyConfig | None = None, **kw: Any) -> Notifier:
        notifier = Notifier(config, **kw)
        made.append(notifier)
        return notifier

    yield make
    for notifier in made:
        notifier.close()


# --------------------------------------------------------------------------- SMTP server


class Inbox:
    """An aiosmtpd handler that keeps what it receives and refuses one recipient."""

    refused = "nobody@example.com"

    def __init__(self) -> None:
        self.envelopes: list[Envelope] = []
        self.arrived = threading.Event()

    async def handle_RCPT(
        self, server: SMTP, session: Session, envelope: Envelope, address: str, options: list[str]
    ) -> str:
        if address == self.refused:
            return "550 5.1.1 no such user"
        envelope.rcpt_tos.append(address)
        return "250 OK"

    async def handle_DATA(self, server: SMTP, session: Session, envelope: Envelope) -> str:
        self.envelopes.append(envelope)
        self.arrived.set()
        return "250 Message accepted"

    def message(self, i: int = 0) -> EmailMessage:
        raw = self.envelopes[i].original_content
        assert raw is not None
        parsed = email.message_from_bytes(raw, policy=email.policy.default)
        assert isinstance(parsed, EmailMessage)
        return parsed


class EphemeralController(Controller):
    """An aiosmtpd controller on a port the OS picks (``port=0``), read back once bound."""

    def _trigger_server(self) -> None:
        # start() calls this once the server is listening; the base class then connects to
        # self.port, so learn the real port first.
        assert isinstance(self.server, asyncio.Server)
        self.port = self.server.sockets[0].getsockname()[1]
        super()._trigger_server()  # type: ignore[no-untyped-call]


@dataclass
class SmtpServer:
    inbox: Inbox
    port: int
    logins: list[tuple[str, str]] = field(default_factory=list)

    def config(self, **kw: Any) -> NotifyConfig:
        options: dict[str, Any] = {"host": "127.0.0.1", "port": self.port}
        options.update(from_addr="utu@rover.example", timeout=DEADLINE)
        options.update(kw)
        return NotifyConfig(smtp=SmtpConfig(**options))


USER, PASSWORD = "utu", "s3cret-pässword"


@pytest.fixture
def start_smtp() -> Iterator[Callable[..., SmtpServer]]:
    """Start aiosmtpd controllers; every one is stopped (loop and thread joined) afterwards."""
    controllers: list[Controller] = []

    def start(password: str = PASSWORD, **kw: Any) -> SmtpServer:
        inbox = Inbox()
        logins: list[tuple[str, str]] = []

        def authenticator(
            server: SMTP, session: Session, envelope: Envelope, mechanism: str, data: Any
        ) -> AuthResult:
            assert isinstance(data, LoginPassword)
            login, password = data.login.decode(), data.password.decode()
            expected = start_password
            logins.append((login, password))
            # handled=False: aiosmtpd answers a failure itself (535)
            return AuthResult(success=(login, password) == (USER, expected), handled=False)

        start_password = password
        controller = EphemeralController(
            inbox,
            hostname="127.0.0.1",
            port=0,
            server_hostname="mx.test",
            authenticator=authenticator,
            **kw,
        )
        controller.start()
        controllers.append(controller)
        return SmtpServer(inbox, controller.port, logins)

    yield start
    for controller in controllers:
        controller.stop()


@pytest.fixture
def smtp(start_smtp: Callable[..., SmtpServer]) -> SmtpServer:
    """A plain SMTP server without STARTTLS."""
    return start_smtp()


# --------------------------------------------------------------------------- certificates


@dataclass(frozen=True)
class Pki:
    ca: Path
    cert: Path
    key: Path

    def server_context(self) -> ssl.SSLContext:
        context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
        context.load_cert_chain(self.cert, self.key)
        return context


def _openssl(command: str, *extra: str, cwd: Path) -> None:
    """Run ``openssl`` with the words of ``command``, then ``extra`` (arguments with spaces)."""
    args = ["openssl", *command.split(), *extra]
    subprocess.run(args, cwd=cwd, check=True, capture_output=True, timeout=60)


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> Pki:
    """A CA and a server certificate for 127.0.0.1, made with the openssl command."""
    if shutil.which("openssl") is None:
        pytest.skip("the openssl command is needed to make test certificates")
    d = tmp_path_factory.mktemp("smtp-pki")
    ec = "-algorithm EC -pkeyopt ec_paramgen_curve:P-256"
    _openssl(f"genpkey {ec} -out ca.key", cwd=d)
    _openssl(
        "req -x509 -new -key ca.key -subj /CN=test-ca -days 2 -out ca.pem",
        *("-addext", "basicConstraints=critical,CA:TRUE"),
        *("-addext", "keyUsage=critical,keyCertSign,cRLSign"),
        cwd=d,
    )
    _openssl(f"genpkey {ec} -out mx.key", cwd=d)
    _openssl("req -new -key mx.key -subj /CN=mx.test -out mx.csr", cwd=d)
    (d / "mx.ext").write_text(
        "basicConstraints=critical,CA:FALSE\nkeyUsage=critical,digitalSignature\n"
        "extendedKeyUsage=serverAuth\nsubjectAltName=DNS:localhost,IP:127.0.0.1\n"
    )
    _openssl(
        "x509 -req -in mx.csr -CA ca.pem -CAkey ca.key -CAcreateserial -days 2 "
        "-extfile mx.ext -out mx.pem",
        cwd=d,
    )
    return Pki(d / "ca.pem", d / "mx.pem", d / "mx.key")


# --------------------------------------------------------------------------- HTTP server


@dataclass
class Received:
    path: str
    headers: dict[str, str]
    body: bytes


class HookServer(ThreadingHTTPServer):
    """A webhook receiver; handler threads are joined on close (no daemon threads)."""

    daemon_threads = False
    block_on_close = True

    def __init__(self) -> None:
        super().__init__(("127.0.0.1", 0), HookHandler)
        self.received: list[Received] = []
        self.arrived = threading.Event()
        self.entered = threading.Event()  # a handler is blocked on `release`
        self.status = 204
        self.block = False
        self.release = threading.Event()
        self.extra_headers: dict[str, str] = {}

    def handle_error(self, request: Any, client_address: Any) -> None:
        """Ignore a client that gave up (a timed-out request); the tests check the client."""

    def url(self, path: str = "/hook") -> str:
        return f"http://127.0.0.1:{self.server_address[1]}{path}"


class HookHandler(BaseHTTPRequestHandler):
    server: HookServer

    def do_POST(self) -> None:
        length = int(self.headers.get("Content-Length", "0"))
        body = self.rfile.read(length)
        self.server.received.append(Received(self.path, dict(self.headers.items()), body))
        self.server.arrived.set()
        if self.server.block:
            self.server.entered.set()
            self.server.release.wait(DEADLINE)
        self.send_response(self.server.status)
        for name, value in self.server.extra_headers.items():
            self.send_header(name, value)
        self.send_header("Content-Length", "0")
        self.end_headers()

    def do_GET(self) -> None:
        self.server.received.append(Received(self.path, dict(self.headers.items()), b""))
        self.send_response(200)
        self.send_header("Content-Length", "0")
        self.end_headers()

    def log_message(self, format: str, *args: Any) -> None:
        """Keep the test output quiet."""


@pytest.fixture
def hook() -> Iterator[HookServer]:
    server = HookServer()
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.05})
    thread.start()
    try:
        yield server
    finally:
        server.release.set()
        server.shutdown()
        server.server_close()
        thread.join(DEADLINE)
        assert not thread.is_alive()


# --------------------------------------------------------------------------- configuration


def test_config_defaults() -> None:
    config = NotifyConfig()
    assert config.smtp is None
    assert config.webhook.timeout == 3.0
    assert config.webhook.allowed_hosts is None
    assert config.log_level == "WARNING"
    smtp = SmtpConfig(host="mail.example.com", from_addr="utu@example.com")
    assert (smtp.port, smtp.starttls, smtp.ssl, smtp.timeout) == (25, False, False, 5.0)


@pytest.mark.parametrize(
    ("section", "message"),
    [
        (
            {"smtp": {"host": "h", "from_addr": "u@x.org", "starttls": True, "ssl": True}},
            "not both",
        ),
        (
            {"smtp": {"host": "h", "from_addr": "u@x.org", "username": "u", "password": "p"}},
            "clear",
        ),
        ({"smtp": {"host": "h", "from_addr": "u@x.org", "username": "u", "ssl": True}}, "password"),
        (
            {"smtp": {"host": "h", "from_addr": "u@x.org", "password_env": "P", "ssl": True}},
            "username",
        ),
        (
            {"smtp": {"host": "h", "from_addr": "u@x.org", "password": "p", "password_env": "P"}},
            "not both",
        ),
        ({"smtp": {"host": "h", "from_addr": "u@x.org", "password_env": "NOT A NAME"}}, "variable"),
        ({"smtp": {"host": "h", "from_addr": "not-an-address"}}, "e-mail address"),
        ({"smtp": {"host": "h", "from_addr": "u@x.org", "prot": 25}}, "Extra inputs"),
        ({"webhook": {"headers": {"Content-Type": "text/plain"}}}, "set by the notifier"),
        ({"webhook": {"headers": {"X-A": "1\r\nX-B: 2"}}}, "line break"),
        ({"webhook": {"allowed_hosts": ["evil.example/path"]}}, "host name"),
        ({"webhook": {"proxy": "socks5://p:1080"}}, "proxy"),
        ({"log_level": "LOUD"}, "log_level"),
        ({"sms": {}}, "Extra inputs"),
    ],
)
def test_config_refuses(section: dict[str, Any], message: str) -> None:
    with pytest.raises(ValidationError, match=message):
        NotifyConfig.model_validate(section)


def test_config_normalises() -> None:
    config = NotifyConfig.model_validate(
        {"log_level": "info", "webhook": {"allowed_hosts": ["Hooks.Example.COM", "[::1]"]}}
    )
    assert config.log_level == "INFO"
    assert config.webhook.allowed_hosts == ["hooks.example.com", "::1"]


def test_password_is_not_shown() -> None:
    smtp = SmtpConfig(
        host="h", from_addr="u@x.org", starttls=True, username="u", password="hunter2"
    )
    assert "hunter2" not in repr(smtp)
    assert "hunter2" not in str(NotifyConfig(smtp=smtp).model_dump())


def test_docs_yaml_is_a_valid_config() -> None:
    text = (ROOT / "docs" / "notify.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```yaml\n(.*?)```", text, flags=re.DOTALL)
    sections = [yaml.safe_load(b) for b in blocks]
    configs = [s["notify"] for s in sections if isinstance(s, dict) and "notify" in s]
    assert configs, "docs/notify.md shows the notify section"
    for section in configs:
        NotifyConfig.model_validate(section)


def test_notification_from_action() -> None:
    action = NotifyAction(
        channel="email", to="operator@example.com", subject="Manual", message="Degraded."
    )
    n = Notification.from_action(action, tactic="fail-safe", t=3.0, details={"goal": "G3"})
    assert n == Notification("email", "operator@example.com", "Manual", "Degraded.",
                             "fail-safe", 3.0, {"goal": "G3"})  # fmt: skip


# --------------------------------------------------------------------------- e-mail


def test_email_is_delivered(smtp: SmtpServer, make_notifier: Callable[..., Notifier]) -> None:
    notifier = make_notifier(smtp.config(), clock=lambda: 1_700_000_000.0)
    subject = "Rover → manual: détection dégradée ✓"
    result = notifier.send(note(subject=subject, message="Bonjour — the rover is in manual."))
    assert result.ok, result.error
    assert (result.channel, result.to, result.error) == ("email", "operator@example.com", None)
    assert smtp.inbox.arrived.wait(DEADLINE)
    envelope = smtp.inbox.envelopes[0]
    assert envelope.mail_from == "utu@rover.example"
    assert envelope.rcpt_tos == ["operator@example.com"]
    msg = smtp.inbox.message()
    assert msg["Subject"] == subject
    assert msg["From"] == "utu@rover.example"
    assert msg["To"] == "operator@example.com"
    assert msg["X-Anunnaki-Tactic"] == "fail-safe"
    assert parsedate_to_datetime(msg["Date"]).timestamp() == 1_700_000_000.0
    assert re.fullmatch(r"<[0-9a-f]{32}@rover\.example>", msg["Message-ID"])
    assert msg.get_content_type() == "text/plain"
    assert msg.get_content_charset() == "utf-8"
    body = msg.get_content().replace("\r\n", "\n")
    assert body.startswith("Bonjour — the rover is in manual.\n")
    assert "Tactic: fail-safe" in body
    assert "t = 12.5 s" in body
    assert '"goal": "G3"' in body
    # the raw subject is encoded (RFC 2047), not raw 8-bit
    raw = smtp.inbox.envelopes[0].original_content
    assert raw is not None
    assert b"=?utf-8?" in raw.split(b"\r\n\r\n", 1)[0].lower()


def test_email_without_subject_names_the_tactic(
    smtp: SmtpServer, make_notifier: Callable[..., Notifier]
) -> None:
    assert make_notifier(smtp.config()).send(note(subject="")).ok
    assert smtp.inbox.message()["Subject"] == "Anunnaki: tactic fail-safe"


def test_email_server_down(make_notifier: Callable[..., Notifier], caplog: Any) -> None:
    port = closed_port()
    config = NotifyConfig(smtp=SmtpConfig(host="127.0.0.1", port=port, from_addr="u@x.org"))
    with caplog.at_level(logging.WARNING, logger=LOGGER_NAME):
        result = make_notifier(config).send(note())
    assert not result.ok
    assert result.error is not None
    assert f"127.0.0.1:{port}" in result.error
    assert "refused" in result.error
    assert any(result.error in r.getMessage() for r in caplog.records)
    assert all(r.name == LOGGER_NAME for r in caplog.records)


def test_email_server_silent_times_out(make_notifier: Callable[..., Notifier]) -> None:
    with socket.socket() as silent:  # accepts connections (backlog) but never greets
        silent.bind(("127.0.0.1", 0))
        silent.listen(1)
        port = silent.getsockname()[1]
        config = NotifyConfig(
            smtp=SmtpConfig(host="127.0.0.1", port=port, from_addr="u@x.org", timeout=0.2)
        )
        result = make_notifier(config).send(note())
    assert not result.ok
    assert result.error is not None
    assert "timeout" in result.error
    assert f"127.0.0.1:{port}" in result.error


def test_email_starttls_not_offered(
    smtp: SmtpServer, make_notifier: Callable[..., Notifier]
) -> None:
    result = make_notifier(smtp.config(starttls=True)).send(note())
    assert not result.ok
    assert result.error is not None
    assert "STARTTLS" in result.error
    assert f"127.0.0.1:{smtp.port}" in result.error
    assert not smtp.inbox.envelopes  # never falls back to plain text


def test_email_ssl_against_plain_server(
    smtp: SmtpServer, make_notifier: Callable[..., Notifier]
) -> None:
    result = make_notifier(smtp.config(ssl=True)).send(note())
    assert not result.ok
    assert result.error is not None
    assert "TLS" in result.error
    assert not smtp.inbox.envelopes


@pytest.mark.parametrize(
    "fields",
    [
        {"subject": "Hello\r\nBcc: everyone@example.com"},
        {"subject": "Hello\nX-Evil: 1"},
        {"to": "operator@example.com\r\nBcc: everyone@example.com"},
        {"tactic": "fail-safe\r\nBcc: everyone@example.com"},
    ],
)
def test_email_header_injection_refused(
    smtp: SmtpServer, make_notifier: Callable[..., Notifier], fields: dict[str, Any]
) -> None:
    result = make_notifier(smtp.config()).send(note(**fields))
    assert not result.ok
    assert result.error is not None
    assert "header injection" in result.error
    assert not smtp.inbox.envelopes


@pytest.mark.parametrize(
    "to", [None, "", "operator", "a@b.com,c@d.com", "Eve <eve@example.com>", "a b@c.com"]
)
def test_email_bad_address(
    smtp: SmtpServer, make_notifier: Callable[..., Notifier], to: str | None
) -> None:
    result = make_notifier(smtp.config()).send(note(to=to))
    assert not result.ok
    assert result.error is not None
    assert "not an e-mail address" in result.error
    assert not smtp.inbox.envelopes


def test_email_recipient_refused(smtp: SmtpServer, make_notifier: Callable[..., Notifier]) -> None:
    result = make_notifier(smtp.config()).send(note(to=Inbox.refused))
    assert not result.ok
    assert result.error is not None
    assert f"refused recipient {Inbox.refused}: 550" in result.error


def test_email_not_configured(make_notifier: Callable[..., Notifier]) -> None:
    result = make_notifier(NotifyConfig()).send(note())
    assert not result.ok
    assert result.error is not None
    assert "'smtp'" in result.error
    assert "notify" in result.error


def test_email_password_env_missing(make_notifier: Callable[..., Notifier]) -> None:
    config = NotifyConfig(
        smtp=SmtpConfig(host="127.0.0.1", port=closed_port(), from_addr="u@x.org",
                        starttls=True, username=USER, password_env="UTU_SMTP_PASSWORD")
    )  # fmt: skip
    result = make_notifier(config, environ={}).send(note())
    assert not result.ok
    assert result.error is not None
    assert "UTU_SMTP_PASSWORD" in result.error


@pytest.mark.parametrize("password", ["ascii-s3cret", PASSWORD])  # smtplib, own AUTH PLAIN
def test_email_starttls_and_login(
    start_smtp: Callable[..., SmtpServer],
    pki: Pki,
    make_notifier: Callable[..., Notifier],
    password: str,
) -> None:
    server = start_smtp(password, tls_context=pki.server_context(), require_starttls=True)
    config = server.config(
        starttls=True, ca_file=pki.ca, username=USER, password_env="UTU_SMTP_PASSWORD"
    )
    notifier = make_notifier(config, environ={"UTU_SMTP_PASSWORD": password})
    result = notifier.send(note())
    assert result.ok, result.error
    assert server.logins == [(USER, password)]
    assert server.inbox.message()["X-Anunnaki-Tactic"] == "fail-safe"


def test_email_login_refused(
    start_smtp: Callable[..., SmtpServer], pki: Pki, make_notifier: Callable[..., Notifier]
) -> None:
    server = start_smtp(tls_context=pki.server_context())
    config = server.config(starttls=True, ca_file=pki.ca, username=USER, password="wrong")
    result = make_notifier(config).send(note())
    assert not result.ok
    assert result.error is not None
    assert "refused the login as 'utu'" in result.error
    assert "wrong" not in result.error
    assert not server.inbox.envelopes


def test_email_smtps(
    start_smtp: Callable[..., SmtpServer], pki: Pki, make_notifier: Callable[..., Notifier]
) -> None:
    server = start_smtp(ssl_context=pki.server_context())
    result = make_notifier(server.config(ssl=True, ca_file=pki.ca)).send(note())
    assert result.ok, result.error
    assert server.inbox.message()["To"] == "operator@example.com"


def test_email_untrusted_certificate(
    start_smtp: Callable[..., SmtpServer], pki: Pki, make_notifier: Callable[..., Notifier]
) -> None:
    server = start_smtp(tls_context=pki.server_context())
    result = make_notifier(server.config(starttls=True)).send(note())  # no ca_file
    assert not result.ok
    assert result.error is not None
    assert "certificate not trusted" in result.error
    assert "smtp.ca_file" in result.error
    assert not server.inbox.envelopes


# --------------------------------------------------------------------------- webhook


def test_webhook_posts_json(hook: HookServer, make_notifier: Callable[..., Notifier]) -> None:
    config = NotifyConfig(webhook=WebhookConfig(headers={"Authorization": "Bearer t0ken"}))
    result = make_notifier(config).send(note("webhook", hook.url("/rover"), subject="Ü"))
    assert result.ok, result.error
    assert hook.arrived.wait(DEADLINE)
    [got] = hook.received
    assert got.path == "/rover"
    assert got.headers["Content-Type"] == "application/json"
    assert got.headers["Authorization"] == "Bearer t0ken"
    assert got.headers["User-Agent"].startswith("anunnaki")
    assert json.loads(got.body.decode("utf-8")) == {
        "tactic": "fail-safe",
        "subject": "Ü",
        "message": "Object detection is degraded; the rover is now in manual mode.",
        "t": 12.5,
        "details": {"goal": "G3", "state": "unsatisfied"},
    }


def test_webhook_http_500(
    hook: HookServer, make_notifier: Callable[..., Notifier], caplog: Any
) -> None:
    hook.status = 500
    with caplog.at_level(logging.WARNING, logger=LOGGER_NAME):
        result = make_notifier().send(note("webhook", hook.url("/services/T0/SECRET-TOKEN")))
    assert not result.ok
    assert result.error is not None
    assert "HTTP 500" in result.error
    assert result.to == hook.url("/services/T0/SECRET-TOKEN")
    # the path (often a secret) is neither in the error nor in the log
    assert "SECRET-TOKEN" not in result.error
    assert caplog.records
    assert not any("SECRET-TOKEN" in r.getMessage() for r in caplog.records)


def test_webhook_redirect_not_followed(
    hook: HookServer, make_notifier: Callable[..., Notifier]
) -> None:
    hook.status = 307
    hook.extra_headers = {"Location": "http://127.0.0.1:1/elsewhere"}
    result = make_notifier().send(note("webhook", hook.url()))
    assert not result.ok
    assert result.error is not None
    assert "HTTP 307" in result.error
    assert len(hook.received) == 1


def test_webhook_timeout(hook: HookServer, make_notifier: Callable[..., Notifier]) -> None:
    hook.block = True
    config = NotifyConfig(webhook=WebhookConfig(timeout=0.2))
    result = make_notifier(config).send(note("webhook", hook.url()))
    assert not result.ok
    assert result.error is not None
    assert "timeout" in result.error
    assert "0.2 s" in result.error
    assert 0.2 <= result.duration_s < DEADLINE


def test_webhook_connection_refused(make_notifier: Callable[..., Notifier]) -> None:
    port = closed_port()
    result = make_notifier().send(note("webhook", f"http://127.0.0.1:{port}/hook"))
    assert not result.ok
    assert result.error is not None
    assert f"127.0.0.1:{port}" in result.error
    assert "refused" in result.error


@pytest.mark.parametrize(
    ("url", "message"),
    [
        ("file:///etc/passwd", "only http and https"),
        ("ftp://127.0.0.1/x", "only http and https"),
        ("gopher://127.0.0.1:70/", "only http and https"),
        ("http://user:pw@127.0.0.1/hook", "credentials"),
        ("http:///no-host", "names no host"),
        ("http://127.0.0.1:99999/", "not a valid URL"),
        ("http://127.0.0.1/a\r\nX-Evil: 1", "whitespace or control"),
        (None, "needs 'to'"),
    ],
)
def test_webhook_url_refused(
    make_notifier: Callable[..., Notifier], url: str | None, message: str
) -> None:
    result = make_notifier().send(note("webhook", url))
    assert not result.ok
    assert result.error is not None
    assert message in result.error


def test_webhook_allowed_hosts(hook: HookServer, make_notifier: Callable[..., Notifier]) -> None:
    elsewhere = NotifyConfig(webhook=WebhookConfig(allowed_hosts=["hooks.example.com"]))
    result = make_notifier(elsewhere).send(note("webhook", hook.url()))
    assert not result.ok
    assert result.error is not None
    assert "'127.0.0.1' is not in notify.webhook.allowed_hosts" in result.error
    assert not hook.received

    nowhere = NotifyConfig(webhook=WebhookConfig(allowed_hosts=[]))
    assert not make_notifier(nowhere).send(note("webhook", hook.url())).ok
    assert not hook.received

    here = NotifyConfig(webhook=WebhookConfig(allowed_hosts=["hooks.example.com", "127.0.0.1"]))
    assert make_notifier(here).send(note("webhook", hook.url())).ok
    assert len(hook.received) == 1


def test_webhook_details_must_be_json(
    hook: HookServer, make_notifier: Callable[..., Notifier]
) -> None:
    result = make_notifier().send(note("webhook", hook.url(), details={"x": float("nan")}))
    assert not result.ok
    assert result.error is not None
    assert "JSON" in result.error
    assert not hook.received


# --------------------------------------------------------------------------- log


def test_log_channel(make_notifier: Callable[..., Notifier], caplog: Any) -> None:
    ticks = iter([100.0, 100.25])
    notifier = make_notifier(timer=lambda: next(ticks))
    with caplog.at_level(logging.DEBUG, logger=LOGGER_NAME):
        result = notifier.send(note("log", None, message="two\nlines"))
    assert result == NotifyResult(ok=True, channel="log", to=None, error=None, duration_s=0.25)
    [record] = caplog.records
    assert record.name == LOGGER_NAME
    assert record.levelno == logging.WARNING
    line = record.getMessage()
    assert "\n" not in line
    assert line.startswith("notify tactic=")
    assert '"fail-safe"' in line
    assert "t=12.5" in line
    assert 'message="two\\nlines"' in line
    assert 'details={"goal":"G3","state":"unsatisfied"}' in line
    assert record.anunnaki_notify["details"] == {"goal": "G3", "state": "unsatisfied"}


def test_log_channel_level_and_child_logger(
    make_notifier: Callable[..., Notifier], caplog: Any
) -> None:
    notifier = make_notifier(NotifyConfig(log_level="INFO"))
    with caplog.at_level(logging.DEBUG, logger=LOGGER_NAME):
        assert notifier.send(note("log", "rover.ops")).ok
        assert notifier.send(note("log", "not a logger", details={"obj": object()})).ok
    first, second = caplog.records
    assert (first.name, first.levelno) == (f"{LOGGER_NAME}.rover.ops", logging.INFO)
    assert second.name == LOGGER_NAME
    assert 'to="not a logger"' in second.getMessage()


def test_surprises_are_contained(
    smtp: SmtpServer, make_notifier: Callable[..., Notifier], caplog: Any
) -> None:
    def broken_clock() -> float:
        raise ZeroDivisionError("clock bug")

    with caplog.at_level(logging.ERROR, logger=LOGGER_NAME):
        result = make_notifier(smtp.config(), clock=broken_clock).send(note())
    assert not result.ok
    assert result.error == "unexpected ZeroDivisionError: clock bug"
    assert any(r.exc_info for r in caplog.records)


def test_unknown_channel(make_notifier: Callable[..., Notifier]) -> None:
    result = make_notifier().send(note("sms", "+15550100"))
    assert not result.ok
    assert result.error is not None
    assert "unknown channel 'sms'" in result.error
    assert "email, webhook, log" in result.error


# --------------------------------------------------------------------------- background


def test_send_in_background_does_not_block(
    hook: HookServer, make_notifier: Callable[..., Notifier]
) -> None:
    hook.block = True
    notifier = make_notifier()
    done = threading.Event()
    results: list[NotifyResult] = []

    def callback(result: NotifyResult) -> None:
        results.append(result)
        done.set()

    future = notifier.send_in_background(note("webhook", hook.url()), callback)
    assert hook.entered.wait(DEADLINE)  # the server holds the call ...
    assert not future.done()  # ... and the caller is free
    assert not done.is_set()
    hook.release.set()
    assert done.wait(DEADLINE)
    assert results[0].ok, results[0].error
    assert future.result(DEADLINE) is results[0]


def test_callback_error_is_contained(make_notifier: Callable[..., Notifier], caplog: Any) -> None:
    notifier = make_notifier()

    def callback(result: NotifyResult) -> None:
        raise ValueError("callback bug")

    with caplog.at_level(logging.ERROR, logger=LOGGER_NAME):
        future = notifier.send_in_background(note("log", None), callback)
        assert future.result(DEADLINE).ok
    assert any("callback raised" in r.getMessage() for r in caplog.records)


def test_close_joins_and_refuses_more(smtp: SmtpServer) -> None:
    notifier = Notifier(smtp.config())
    workers: set[threading.Thread] = set()

    def callback(result: NotifyResult) -> None:
        workers.add(threading.current_thread())

    futures = [
        notifier.send_in_background(note(to=f"op{i}@example.com"), callback) for i in range(3)
    ]
    notifier.close()  # waits for all three
    assert all(f.done() and f.result().ok for f in futures)
    assert len(smtp.inbox.envelopes) == 3
    assert 1 <= len(workers) <= 2
    assert all(t.name.startswith("anunnaki-notify") for t in workers)
    assert not any(t.is_alive() for t in workers)  # joined
    with pytest.raises(RuntimeError, match="closed"):
        notifier.send_in_background(note("log", None))
    notifier.close()  # again: nothing happens


def test_context_manager_closes(make_notifier: Callable[..., Notifier]) -> None:
    with Notifier() as notifier:
        future = notifier.send_in_background(note("log", None))
    assert future.done()
    with pytest.raises(RuntimeError):
        notifier.send_in_background(note("log", None))


def _disconnected_by_timeout() -> smtplib.SMTPServerDisconnected:
    exc = smtplib.SMTPServerDisconnected("Connection unexpectedly closed")
    exc.__context__ = TimeoutError("timed out")  # as smtplib raises it after a read timeout
    return exc


@pytest.mark.parametrize(
    ("exc", "stage", "expected"),
    [
        (smtplib.SMTPNotSupportedError("no"), "starttls", "does not offer STARTTLS"),
        (smtplib.SMTPNotSupportedError("no"), "login", "does not offer AUTH"),
        (smtplib.SMTPNotSupportedError("no"), "send", ": no (during send)"),
        (smtplib.SMTPSenderRefused(553, b"bad  sender", "x"), "send", "refused sender utu@"),
        (smtplib.SMTPResponseException(451, b"try\r\nlater"), "send", "answered 451 try later"),
        (_disconnected_by_timeout(), "send", "did not answer within 3 s (during send)"),
        (smtplib.SMTPServerDisconnected("gone"), "login", "closed the connection (during login)"),
        (smtplib.SMTPException("odd"), "send", ": odd (during send)"),
        (TimeoutError(), "connect", "did not answer within 3 s (during connect)"),
        (ssl.SSLError(1, "wrong version"), "starttls", "TLS with SMTP server"),
        (socket.gaierror(-2, "Name or service not known"), "connect", "cannot resolve"),
        (ConnectionRefusedError(), "connect", "connection refused"),
        (OSError(101, "Network is unreachable"), "connect", "(during connect): Network is"),
    ],
)
def test_every_smtp_failure_is_explained(exc: OSError, stage: str, expected: str) -> None:
    from anunnaki.utu.host._notify import _Smtp, _smtp_failure

    cfg = SmtpConfig(host="mail.example.com", from_addr="utu@example.com", timeout=3)
    error = _smtp_failure(exc, _Smtp("SMTP server mail.example.com:25", stage, cfg, "op@x.org"))  # type: ignore[arg-type]
    assert expected in error
    assert error.startswith(("SMTP server", "timeout: SMTP server", "TLS with", "cannot"))
