"""Notifications: the ``notify`` action of a tactic, sent by e-mail, webhook or log.

The paper's fail-safe tactic (§3.4, Fig. 10) switches the rover to manual mode and e-mails
the operator. Sending is the one place where the autonomic manager talks to the world
outside the managed system, so this module is built around two promises:

* **The manager survives.** :meth:`Notifier.send` never raises for a delivery problem (server
  down, refused, timeout, HTTP 500, a bad address, missing configuration): it returns a
  :class:`NotifyResult` with ``ok=False`` and a readable ``error``, and logs it on the
  ``anunnaki.utu.notify`` logger. A slow server must not stall the MAPE loop either, so
  :meth:`Notifier.send_in_background` hands the work to a small thread pool owned by the
  notifier.
* **A tactics file is not trusted to steer the manager.** Tactics name recipients and URLs;
  the Utu configuration (written by whoever deploys the manager) names the SMTP server,
  the credentials and which webhook hosts may be called (``webhook.allowed_hosts``).
  Line breaks in header fields are refused (no header injection), webhook URLs must be
  ``http``/``https`` without credentials, redirects are not followed, environment proxies
  are not used, and webhook URLs are shown without their path in errors and logs (paths
  often hold a secret token).

Only the standard library talks to the network (:mod:`smtplib`, :mod:`urllib.request`).
Dependencies come in through the constructor: the wall clock for the ``Date`` header and the
timer for ``duration_s`` are injected, as is the environment that ``smtp.password_env`` is
read from.
"""

from __future__ import annotations

import base64
import http.client
import json
import logging
import os
import re
import smtplib
import socket
import ssl
import threading
import time
import urllib.error
import urllib.request
import uuid
from collections.abc import Callable, Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from datetime import UTC, datetime
from email.message import EmailMessage
from email.utils import format_datetime
from pathlib import Path
from typing import Any, Final, Literal, Self
from urllib.parse import urlsplit

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    SecretStr,
    field_validator,
    model_validator,
)

from anunnaki._closing import Closing
from anunnaki.tactics import Notice, NotifyAction

__all__ = [
    "LOGGER_NAME",
    "Channel",
    "LogLevel",
    "Notification",
    "Notifier",
    "NotifyConfig",
    "NotifyResult",
    "SmtpConfig",
    "WebhookConfig",
]

LOGGER_NAME: Final = "anunnaki.utu.notify"
"""The logger that log-channel notifications and delivery failures are written to."""

Channel = Literal["email", "webhook", "log"]
"""Where a notification goes."""

LogLevel = Literal["DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL"]
"""A :mod:`logging` level by name."""

_CHANNELS: Final = ("email", "webhook", "log")
_ADDRESS_CHARS = r"[^\s@<>(),;:\"\[\]\\]+"
_ADDRESS = re.compile(rf"{_ADDRESS_CHARS}@{_ADDRESS_CHARS}\.{_ADDRESS_CHARS}")
_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")
_LINE_BREAK = re.compile(r"[\r\n\x0b\x0c\x85\u2028\u2029]")
_HEADER_NAME = re.compile(r"[!#$%&'*+\-.^_`|~0-9A-Za-z]+")
_LOGGER_SUFFIX = re.compile(r"[A-Za-z0-9_\-]+(\.[A-Za-z0-9_\-]+)*")
_RESERVED_HEADERS: Final = frozenset(
    {"content-type", "content-length", "host", "transfer-encoding"}
)
_USER_AGENT: Final = "anunnaki-utu-notify/1"


# --------------------------------------------------------------------------- configuration


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _one_line(value: str, what: str) -> str:
    if _CONTROL.search(value):
        raise ValueError(f"{what} must be one line without control characters")
    return value


class SmtpConfig(_Strict):
    """The SMTP server that e-mail notifications are sent through (``notify.smtp``).

    Attributes:
        host: Server name or IP address.
        port: TCP port: 25 (relay), 587 (submission, with ``starttls``) or 465 (``ssl``).
        starttls: Upgrade the connection with STARTTLS before sending; fail if the server
            does not offer it (never falls back to plain text).
        ssl: Speak TLS from the first byte (SMTPS, usually port 465).
        username: Log in as this user (needs ``starttls`` or ``ssl``: a password is never
            sent in clear).
        password: The password, written in the config file. Prefer ``password_env``.
        password_env: Name of an environment variable holding the password, read when a
            message is sent (so the file holds no secret).
        from_addr: Sender address, used in ``From`` and as the envelope sender.
        timeout: Seconds allowed for connecting and for each exchange with the server.
        ca_file: PEM file of the certificate authorities to trust instead of the system's
            (a private CA); certificates and host names are always checked.
        helo_name: Name this host gives in ``EHLO``; by default its fully qualified name.

    """

    host: str = Field(min_length=1)
    port: int = Field(default=25, ge=1, le=65535)
    starttls: bool = False
    ssl: bool = False
    username: str | None = None
    password: SecretStr | None = None
    password_env: str | None = None
    from_addr: str
    timeout: float = Field(default=5.0, gt=0, allow_inf_nan=False)
    ca_file: Path | None = None
    helo_name: str | None = None

    @field_validator("host", "username", "helo_name")
    @classmethod
    def _line(cls, value: str | None) -> str | None:
        if value is not None:
            _one_line(value, "the value")
        return value

    @field_validator("from_addr")
    @classmethod
    def _address(cls, value: str) -> str:
        if _CONTROL.search(value) or not _ADDRESS.fullmatch(value):
            raise ValueError(f"{value!r} is not an e-mail address (e.g. utu@example.com)")
        return value

    @field_validator("password_env")
    @classmethod
    def _env_name(cls, value: str | None) -> str | None:
        if value is not None and not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", value):
            raise ValueError(f"{value!r} is not an environment variable name")
        return value

    @model_validator(mode="after")
    def _consistent(self) -> Self:
        if self.starttls and self.ssl:
            raise ValueError(
                "give either starttls (upgrade a plain connection, port 587) or ssl "
                "(TLS from the start, port 465), not both"
            )
        if self.password is not None and self.password_env is not None:
            raise ValueError("give either password or password_env, not both")
        has_secret = self.password is not None or self.password_env is not None
        if has_secret and self.username is None:
            raise ValueError("a password needs a username")
        if self.username is not None and not has_secret:
            raise ValueError("a username needs a password: set password_env (or password)")
        if self.username is not None and not (self.starttls or self.ssl):
            raise ValueError(
                "logging in would send the password in clear: set starttls: true or ssl: true"
            )
        return self


class WebhookConfig(_Strict):
    """How webhook notifications are posted (``notify.webhook``).

    Attributes:
        timeout: Seconds allowed for connecting and for each read of the answer.
        headers: Extra HTTP headers sent with every call (e.g. ``Authorization``).
            ``Content-Type``, ``Content-Length``, ``Host`` and ``Transfer-Encoding`` are set
            by the notifier and cannot be given.
        allowed_hosts: Host names or IP addresses that webhooks may call, compared without
            case and exactly (no wildcards; the port is not compared). ``None`` allows any
            host; set it in production, so a tactics file cannot make the manager post to
            wherever it likes.
        proxy: An HTTP proxy URL for webhook calls. Proxies named in the environment
            (``http_proxy`` …) are ignored.

    """

    timeout: float = Field(default=3.0, gt=0, allow_inf_nan=False)
    headers: dict[str, str] = Field(default_factory=dict)
    allowed_hosts: list[str] | None = None
    proxy: str | None = None

    @field_validator("headers")
    @classmethod
    def _headers(cls, value: dict[str, str]) -> dict[str, str]:
        for name, text in value.items():
            if not _HEADER_NAME.fullmatch(name):
                raise ValueError(f"{name!r} is not an HTTP header name")
            if name.lower() in _RESERVED_HEADERS:
                raise ValueError(f"header {name!r} is set by the notifier; remove it")
            if _CONTROL.search(text.replace("\t", " ")):
                raise ValueError(f"header {name!r} holds a line break or control character")
        return value

    @field_validator("allowed_hosts")
    @classmethod
    def _hosts(cls, value: list[str] | None) -> list[str] | None:
        if value is None:
            return None
        out: list[str] = []
        for host in value:
            name = host.strip().lower().removeprefix("[").removesuffix("]")
            if not name or _CONTROL.search(name) or any(c in name for c in " /@?#"):
                raise ValueError(f"{host!r} is not a host name or IP address")
            out.append(name)
        return out

    @field_validator("proxy")
    @classmethod
    def _proxy(cls, value: str | None) -> str | None:
        if value is not None and (
            _CONTROL.search(value) or urlsplit(value).scheme not in ("http", "https")
        ):
            raise ValueError(f"{value!r} is not an http(s) proxy URL")
        return value


class NotifyConfig(_Strict):
    """The ``notify:`` section of a Utu configuration file.

    Attributes:
        smtp: The SMTP server for e-mail; ``None`` (the default) disables e-mail, and an
            e-mail notification then fails with a message saying to add this section.
        webhook: How webhooks are called.
        log_level: Level of the records that log-channel notifications write.

    """

    smtp: SmtpConfig | None = None
    webhook: WebhookConfig = Field(default_factory=WebhookConfig)
    log_level: LogLevel = "WARNING"

    @field_validator("log_level", mode="before")
    @classmethod
    def _upper(cls, value: Any) -> Any:
        return value.upper() if isinstance(value, str) else value


# --------------------------------------------------------------------------- values


@dataclass(frozen=True)
class Notification:
    """One message to send, as the Execute service builds it from a ``notify`` action.

    Attributes:
        channel: ``email``, ``webhook`` or ``log``.
        to: An e-mail address (``email``), an ``http(s)`` URL (``webhook``), or for ``log``
            optionally a logger name under ``anunnaki.utu.notify`` (``None``: that logger).
        subject: One line; for e-mail an empty subject becomes ``Anunnaki: tactic <name>``.
        message: The text for the person (may span lines).
        tactic: Name of the tactic whose action this is.
        t: The manager's time of the decision, in seconds (the ``now`` given to ``step``).
        details: JSON-compatible context (goal states, oracle output, …) sent along.

    """

    channel: Channel
    to: str | None
    subject: str
    message: str
    tactic: str
    t: float
    details: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def from_action(
        cls,
        action: NotifyAction | Notice,
        *,
        tactic: str,
        t: float,
        details: Mapping[str, Any] | None = None,
    ) -> Notification:
        """Build the notification a tactic's ``notify`` action asks for at time ``t``."""
        return cls(
            channel=action.channel,
            to=action.to,
            subject=action.subject,
            message=action.message,
            tactic=tactic,
            t=t,
            details=dict(details or {}),
        )


@dataclass(frozen=True)
class NotifyResult:
    """What became of one notification.

    Attributes:
        ok: Delivered (accepted by the SMTP server, answered 2xx by the webhook, logged).
        channel: The notification's channel.
        to: The notification's ``to``, as given.
        error: Why it was not delivered (``None`` when ``ok``).
        duration_s: Seconds spent sending, measured with the notifier's timer.

    """

    ok: bool
    channel: str
    to: str | None
    error: str | None
    duration_s: float


class _Refused(Exception):
    """A notification that cannot be sent; the message is the result's ``error``."""


_Stage = Literal["connect", "starttls", "login", "send"]


def _email_headers(n: Notification) -> tuple[str, str]:
    """The recipient and subject, refused if they could inject headers."""
    to = n.to or ""
    subject = n.subject or f"Anunnaki: tactic {n.tactic}"
    for what, value in (("to", to), ("subject", subject), ("tactic", n.tactic)):
        if _LINE_BREAK.search(value):
            raise _Refused(f"refused: {what!r} holds a line break (header injection)")
        if _CONTROL.search(value):
            raise _Refused(f"refused: {what!r} holds a control character")
    if not _ADDRESS.fullmatch(to):
        raise _Refused(f"{to!r} is not an e-mail address (e.g. operator@example.com)")
    return to, subject


@dataclass(frozen=True)
class _Smtp:
    """Where an SMTP exchange failed: the server, the stage, the configuration, the recipient."""

    where: str
    stage: _Stage
    cfg: SmtpConfig
    to: str


def _smtp_text(value: bytes | str) -> str:
    text = value.decode("utf-8", "replace") if isinstance(value, bytes) else value
    return " ".join(text.split())


def _not_supported(exc: Any, c: _Smtp) -> str:
    need = {
        "starttls": "STARTTLS (smtp.starttls is true)",
        "login": "AUTH (smtp.username is set)",
    }.get(c.stage)
    if need is None:
        return f"{c.where}: {exc} (during {c.stage})"
    return f"{c.where} does not offer {need}"


def _recipient_refused(exc: Any, c: _Smtp) -> str:
    code, text = next(iter(exc.recipients.values()), (0, b""))
    return f"{c.where} refused recipient {c.to}: {code} {_smtp_text(text)}"


def _disconnected(exc: Any, c: _Smtp) -> str:
    if isinstance(exc.__context__, TimeoutError):  # smtplib wraps read timeouts
        return _timed_out(exc, c)
    return f"{c.where} closed the connection (during {c.stage}): {exc}"


def _timed_out(exc: Any, c: _Smtp) -> str:
    return f"timeout: {c.where} did not answer within {c.cfg.timeout:g} s (during {c.stage})"


# What an SMTP failure means to the operator, most specific exception first.
_SMTP_FAILURES: tuple[tuple[type[BaseException], Callable[[Any, _Smtp], str]], ...] = (
    (smtplib.SMTPNotSupportedError, _not_supported),
    (
        smtplib.SMTPAuthenticationError,
        lambda e, c: (
            f"{c.where} refused the login as {c.cfg.username!r}: {e.smtp_code} "
            f"{_smtp_text(e.smtp_error)}"
        ),
    ),
    (smtplib.SMTPRecipientsRefused, _recipient_refused),
    (
        smtplib.SMTPSenderRefused,
        lambda e, c: (
            f"{c.where} refused sender {c.cfg.from_addr}: {e.smtp_code} {_smtp_text(e.smtp_error)}"
        ),
    ),
    (
        smtplib.SMTPResponseException,
        lambda e, c: (
            f"{c.where} answered {e.smtp_code} {_smtp_text(e.smtp_error)} (during {c.stage})"
        ),
    ),
    (smtplib.SMTPServerDisconnected, _disconnected),
    (smtplib.SMTPException, lambda e, c: f"{c.where}: {e} (during {c.stage})"),
    (TimeoutError, _timed_out),
    (
        ssl.SSLCertVerificationError,
        lambda e, c: (
            f"TLS with {c.where} failed: certificate not trusted ({e.verify_message}); "
            "set smtp.ca_file for a private CA"
        ),
    ),
    (ssl.SSLError, lambda e, c: f"TLS with {c.where} failed: {getattr(e, 'reason', None) or e}"),
    (socket.gaierror, lambda e, c: f"cannot resolve {c.where}: {e.strerror or e}"),
    (ConnectionRefusedError, lambda e, c: f"cannot connect to {c.where}: connection refused"),
)


def _smtp_failure(exc: OSError, c: _Smtp) -> str:
    """The error of a failed SMTP exchange, for the notification's result."""
    for kind, explain in _SMTP_FAILURES:
        if isinstance(exc, kind):
            return explain(exc, c)
    return f"cannot talk to {c.where} (during {c.stage}): {exc.strerror or exc}"


class _NoRedirect(urllib.request.HTTPRedirectHandler):
    """Refuse redirects: a 3xx answer is a failed call, never a call to another host."""

    def redirect_request(  # noqa: PLR0917 (the base class's signature)
        self,
        req: urllib.request.Request,
        fp: Any,
        code: int,
        msg: str,
        headers: Any,
        newurl: str,
    ) -> None:
        return None


def _redact(url: str) -> str:
    """Show a URL without path, query and fragment (they often carry a secret token)."""
    try:
        parts = urlsplit(url)
        host = parts.hostname or "?"
        port = parts.port
    except ValueError:
        return "<invalid URL>"
    if ":" in host:
        host = f"[{host}]"
    shown = f"{parts.scheme}://{host}" + (f":{port}" if port is not None else "")
    return shown + ("/…" if parts.path not in ("", "/") or parts.query else "/")


def _json(value: Any) -> str:
    """Strict compact JSON (what a webhook receives): no NaN, no unknown types."""
    return json.dumps(value, ensure_ascii=False, allow_nan=False, separators=(",", ":"))


def _log_json(value: Any) -> str:
    """Lenient compact JSON for a log line: anything unknown is shown by its ``repr``."""
    try:
        return json.dumps(value, ensure_ascii=False, separators=(",", ":"), default=repr)
    except ValueError:  # a circular structure
        return json.dumps(repr(value), ensure_ascii=False)


# --------------------------------------------------------------------------- the notifier


class Notifier(Closing):
    """Sends notifications; never raises for a delivery failure.

    Use :meth:`send` from a thread that may block for up to the configured timeouts, or
    :meth:`send_in_background` from the MAPE loop. Call :meth:`close` (or use the notifier
    as a context manager) to wait for notifications still being sent.

    Args:
        config: The ``notify`` configuration (default: log and webhooks only, no e-mail).
        clock: Wall-clock time in seconds since the epoch, for the e-mail ``Date`` header.
        timer: A monotonic timer in seconds, for :attr:`NotifyResult.duration_s`.
        environ: Where ``smtp.password_env`` is looked up (default: :data:`os.environ`).
        logger: Where notifications and failures are logged (default:
            ``logging.getLogger("anunnaki.utu.notify")``).

    """

    def __init__(
        self,
        config: NotifyConfig | None = None,
        *,
        clock: Callable[[], float] = time.time,
        timer: Callable[[], float] = time.monotonic,
        environ: Mapping[str, str] | None = None,
        logger: logging.Logger | None = None,
    ) -> None:
        self._config = config if config is not None else NotifyConfig()
        self._clock = clock
        self._timer = timer
        self._environ: Mapping[str, str] = os.environ if environ is None else environ
        self._logger = logger if logger is not None else logging.getLogger(LOGGER_NAME)
        self._log_level = logging.getLevelNamesMapping()[self._config.log_level]
        self._opener = self._build_opener(self._config.webhook)
        self._executor = ThreadPoolExecutor(max_workers=2, thread_name_prefix="anunnaki-notify")
        self._closed = False
        self._lock = threading.Lock()

    @property
    def config(self) -> NotifyConfig:
        """The configuration this notifier was built with."""
        return self._config

    # ----------------------------------------------------------------------- public API

    def send(self, notification: Notification) -> NotifyResult:
        """Send ``notification`` now and wait for the outcome.

        Blocks for at most about the channel's timeout (``smtp.timeout`` per exchange,
        ``webhook.timeout`` per connect/read).

        Returns:
            ``ok=True``, or ``ok=False`` with the reason in ``error`` (also logged as a
            warning). Delivery problems never raise.

        """
        start = self._timer()
        error: str | None = None
        try:
            self._dispatch(notification)
        except _Refused as exc:
            error = str(exc)
        except Exception as exc:  # a bug or a surprise must not take the manager down
            error = f"unexpected {type(exc).__name__}: {exc}"
            self._logger.error(
                "notify %s failed unexpectedly (tactic %s)",
                notification.channel,
                notification.tactic,
                exc_info=True,
            )
        duration = max(0.0, self._timer() - start)
        result = NotifyResult(
            ok=error is None,
            channel=notification.channel,
            to=notification.to,
            error=error,
            duration_s=duration,
        )
        self._report(notification, result)
        return result

    def send_in_background(
        self,
        notification: Notification,
        callback: Callable[[NotifyResult], object] | None = None,
    ) -> Future[NotifyResult]:
        """Send ``notification`` on a worker thread; return at once.

        At most two notifications are sent at a time; more wait in order. ``callback``
        is called on the worker thread with the :class:`NotifyResult`; if it raises, the
        exception is logged and dropped.

        Returns:
            A future holding the result (it never holds an exception).

        Raises:
            RuntimeError: the notifier is closed.

        """
        with self._lock:
            if self._closed:
                raise RuntimeError("this Notifier is closed; no more notifications are sent")
            return self._executor.submit(self._deliver, notification, callback)

    def close(self) -> None:
        """Stop taking background notifications and wait for those already handed over.

        Waits at most about the channel timeouts for each notification still queued.
        Calling it again does nothing.
        """
        with self._lock:
            self._closed = True
        self._executor.shutdown(wait=True)

    # ----------------------------------------------------------------------- plumbing

    def _deliver(
        self, notification: Notification, callback: Callable[[NotifyResult], object] | None
    ) -> NotifyResult:
        result = self.send(notification)
        if callback is not None:
            try:
                callback(result)
            except Exception:
                self._logger.error(
                    "notify callback raised (tactic %s)", notification.tactic, exc_info=True
                )
        return result

    def _dispatch(self, notification: Notification) -> None:
        channel = notification.channel
        if channel == "email":
            self._send_email(notification)
        elif channel == "webhook":
            self._send_webhook(notification)
        elif channel == "log":
            self._send_log(notification)
        else:
            raise _Refused(f"unknown channel {channel!r}; valid channels: {', '.join(_CHANNELS)}")

    def _report(self, notification: Notification, result: NotifyResult) -> None:
        if notification.channel == "log" and result.ok:
            return  # the log line is the notification itself
        shown = self._shown_to(notification)
        if result.ok:
            self._logger.info(
                "notify %s to %s sent (tactic %s) in %.3f s",
                notification.channel,
                shown,
                notification.tactic,
                result.duration_s,
            )
        else:
            self._logger.warning(
                "notify %s to %s failed (tactic %s): %s",
                notification.channel,
                shown,
                notification.tactic,
                result.error,
            )

    @staticmethod
    def _shown_to(notification: Notification) -> str:
        to = notification.to
        if to is None:
            return "-"
        if notification.channel == "webhook":
            return _redact(to)
        return repr(to) if _CONTROL.search(to) else to

    # ----------------------------------------------------------------------- log

    def _send_log(self, n: Notification) -> None:
        # Never refused: a name that is no logger name stays in the record, on the base logger.
        logger = self._logger
        record: dict[str, Any] = {}
        if n.to and _LOGGER_SUFFIX.fullmatch(n.to):
            logger = logger.getChild(n.to)
        elif n.to:
            record["to"] = n.to
        record.update(
            tactic=n.tactic, t=n.t, subject=n.subject, message=n.message, details=dict(n.details)
        )
        line = " ".join(f"{key}={_log_json(value)}" for key, value in record.items())
        logger.log(self._log_level, "notify %s", line, extra={"anunnaki_notify": record})

    # ----------------------------------------------------------------------- e-mail

    def _send_email(self, n: Notification) -> None:
        cfg = self._config.smtp
        if cfg is None:
            raise _Refused(
                "e-mail is not configured: add a 'smtp' section (host, from_addr) under "
                "'notify' in the Utu configuration"
            )
        to, subject = _email_headers(n)
        password = self._password(cfg)
        message = self._email_message(n, cfg, to, subject)
        where = f"SMTP server {cfg.host}:{cfg.port}"
        try:
            context = self._tls_context(cfg) if (cfg.starttls or cfg.ssl) else None
        except OSError as exc:
            raise _Refused(f"cannot load smtp.ca_file {str(cfg.ca_file)!r}: {exc}") from None
        stage: list[_Stage] = ["connect"]
        try:
            self._smtp_send(cfg, message, to, password, context=context, stage=stage)
        except OSError as exc:  # smtplib's, ssl's and socket's errors all are OSErrors
            raise _Refused(_smtp_failure(exc, _Smtp(where, stage[0], cfg, to))) from None

    def _smtp_send(
        self,
        cfg: SmtpConfig,
        message: EmailMessage,
        to: str,
        password: str | None,
        *,
        context: ssl.SSLContext | None,
        stage: list[_Stage],
    ) -> None:
        """Connect, STARTTLS, log in and send; ``stage[0]`` says how far it got."""
        client: smtplib.SMTP
        if cfg.ssl:
            client = smtplib.SMTP_SSL(
                cfg.host, cfg.port, local_hostname=cfg.helo_name, timeout=cfg.timeout,
                context=context,
            )  # fmt: skip
        else:
            client = smtplib.SMTP(
                cfg.host, cfg.port, local_hostname=cfg.helo_name, timeout=cfg.timeout
            )
        with client:
            if cfg.starttls:
                stage[0] = "starttls"
                client.starttls(context=context)
            if cfg.username is not None and password is not None:
                stage[0] = "login"
                self._login(client, cfg.username, password, f"SMTP server {cfg.host}:{cfg.port}")
            stage[0] = "send"
            client.send_message(message, from_addr=cfg.from_addr, to_addrs=[to])

    @staticmethod
    def _login(client: smtplib.SMTP, username: str, password: str, where: str) -> None:
        if username.isascii() and password.isascii():
            client.login(username, password)  # negotiates CRAM-MD5, PLAIN or LOGIN
            return
        # smtplib sends credentials as ASCII only; AUTH PLAIN (RFC 4616) carries UTF-8.
        client.ehlo_or_helo_if_needed()
        if not client.has_extn("auth"):
            raise smtplib.SMTPNotSupportedError("SMTP AUTH extension not supported by server.")
        if "PLAIN" not in client.esmtp_features["auth"].upper().split():
            raise _Refused(
                f"{where} does not offer AUTH PLAIN, which a non-ASCII username or password needs"
            )
        secret = b"\0" + username.encode("utf-8") + b"\0" + password.encode("utf-8")
        code, reply = client.docmd("AUTH", "PLAIN " + base64.b64encode(secret).decode("ascii"))
        if code != 235:
            raise smtplib.SMTPAuthenticationError(code, reply)

    def _password(self, cfg: SmtpConfig) -> str | None:
        if cfg.password is not None:
            return cfg.password.get_secret_value()
        if cfg.password_env is not None:
            value = self._environ.get(cfg.password_env)
            if not value:
                raise _Refused(
                    f"the environment variable {cfg.password_env} (smtp.password_env) is not "
                    "set or empty"
                )
            return value
        return None

    @staticmethod
    def _tls_context(cfg: SmtpConfig) -> ssl.SSLContext:
        cafile = None if cfg.ca_file is None else str(cfg.ca_file)
        return ssl.create_default_context(cafile=cafile)

    def _email_message(
        self, n: Notification, cfg: SmtpConfig, to: str, subject: str
    ) -> EmailMessage:
        msg = EmailMessage()
        msg["Subject"] = subject
        msg["From"] = cfg.from_addr
        msg["To"] = to
        msg["Date"] = format_datetime(datetime.fromtimestamp(self._clock(), tz=UTC))
        domain = cfg.from_addr.rpartition("@")[2]
        msg["Message-ID"] = f"<{uuid.uuid4().hex}@{domain}>"
        msg["X-Anunnaki-Tactic"] = n.tactic
        footer = [f"Tactic: {n.tactic}", f"Time: t = {n.t:g} s"]
        if n.details:
            try:
                details = json.dumps(dict(n.details), ensure_ascii=False, indent=2, default=str)
            except ValueError as exc:
                raise _Refused(f"the details are not JSON-compatible: {exc}") from None
            footer.append(f"Details: {details}")
        body = n.message.rstrip("\n") + "\n\n-- \nSent by Anunnaki (Utu).\n"
        msg.set_content(body + "\n".join(footer) + "\n", charset="utf-8")
        return msg

    # ----------------------------------------------------------------------- webhook

    @staticmethod
    def _build_opener(cfg: WebhookConfig) -> urllib.request.OpenerDirector:
        proxies = {} if cfg.proxy is None else {"http": cfg.proxy, "https": cfg.proxy}
        opener = urllib.request.OpenerDirector()
        for handler in (
            urllib.request.ProxyHandler(proxies),
            urllib.request.HTTPHandler(),
            urllib.request.HTTPSHandler(context=ssl.create_default_context()),
            urllib.request.HTTPDefaultErrorHandler(),
            _NoRedirect(),
            urllib.request.HTTPErrorProcessor(),
            urllib.request.UnknownHandler(),
        ):
            opener.add_handler(handler)
        return opener

    def _webhook_url(self, url: str | None) -> str:
        if not url:
            raise _Refused("a webhook notification needs 'to': an http(s) URL")
        if _CONTROL.search(url) or any(c.isspace() for c in url):
            raise _Refused("refused: the webhook URL holds whitespace or control characters")
        try:
            parts = urlsplit(url)
            host = parts.hostname
            _ = parts.port  # raises for a bad port
        except ValueError as exc:
            raise _Refused(f"refused: {_redact(url)} is not a valid URL ({exc})") from None
        if parts.scheme.lower() not in ("http", "https"):
            raise _Refused(
                f"refused: only http and https URLs can be called, not {parts.scheme or '?'!r}"
            )
        if not host:
            raise _Refused(f"refused: the webhook URL {_redact(url)} names no host")
        if parts.username is not None or parts.password is not None:
            raise _Refused(
                "refused: credentials in a webhook URL are not sent; put them in "
                "notify.webhook.headers (e.g. Authorization)"
            )
        allowed = self._config.webhook.allowed_hosts
        if allowed is not None and host.lower() not in allowed:
            raise _Refused(
                f"refused: host {host!r} is not in notify.webhook.allowed_hosts "
                f"({', '.join(allowed) or 'empty'})"
            )
        return url

    def _send_webhook(self, n: Notification) -> None:
        cfg = self._config.webhook
        url = self._webhook_url(n.to)
        shown = _redact(url)
        payload = {
            "tactic": n.tactic,
            "subject": n.subject,
            "message": n.message,
            "t": n.t,
            "details": dict(n.details),
        }
        try:
            body = _json(payload).encode("utf-8")
        except (TypeError, ValueError) as exc:
            raise _Refused(f"the notification is not JSON-compatible: {exc}") from None
        # urllib folds header names to one case, so a configured User-Agent replaces ours.
        headers = {"User-Agent": _USER_AGENT, **cfg.headers, "Content-Type": "application/json"}
        request = urllib.request.Request(url, data=body, headers=headers, method="POST")
        try:
            with self._opener.open(request, timeout=cfg.timeout) as response:
                status = response.status
        except urllib.error.HTTPError as exc:
            with exc:
                raise _Refused(f"HTTP {exc.code} {exc.reason} from {shown}") from None
        except urllib.error.URLError as exc:
            reason = exc.reason
            if isinstance(reason, TimeoutError):
                raise _Refused(self._timeout(shown, cfg.timeout)) from None
            if isinstance(reason, ConnectionRefusedError):
                raise _Refused(f"cannot connect to {shown}: connection refused") from None
            if isinstance(reason, OSError):
                reason = reason.strerror or reason
            raise _Refused(f"cannot reach {shown}: {reason}") from None
        except TimeoutError:
            raise _Refused(self._timeout(shown, cfg.timeout)) from None
        except (OSError, http.client.HTTPException) as exc:
            raise _Refused(f"call to {shown} failed: {type(exc).__name__}: {exc}") from None
        if not 200 <= status < 300:
            raise _Refused(f"HTTP {status} from {shown}")

    @staticmethod
    def _timeout(shown: str, seconds: float) -> str:
        return f"timeout: {shown} did not answer within {seconds:g} s"
