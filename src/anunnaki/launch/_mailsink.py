"""A local SMTP sink for demos: it accepts every message and keeps it to be printed.

The rover demo's fail-safe e-mails the operator (the paper's Fig. 10); ``anunnaki run
--mail-sink PORT`` starts this sink on ``127.0.0.1:PORT`` before the run and, at the end,
prints what it received and stops it. It is a demo's stand-in for a mail server, never one:
it listens on the loopback interface only, relays nothing, and keeps the messages in memory.
The server is :mod:`aiosmtpd` (``pip install 'anunnaki[mail]'``; ``scripts/setup.sh``
installs it).
"""

from __future__ import annotations

import contextlib
import email
import email.policy
import socket
import threading
from dataclasses import dataclass
from email.message import EmailMessage
from typing import Any

from anunnaki._closing import Closing
from anunnaki.errors import AnunnakiError

__all__ = ["MailSink", "ReceivedMail"]


@dataclass(frozen=True)
class ReceivedMail:
    """One message the sink accepted: envelope sender, recipients, and the parsed message."""

    sender: str
    recipients: tuple[str, ...]
    message: EmailMessage

    def render(self) -> str:
        """The message as a person reads it: the headers that matter, then the text."""
        body = self.message.get_body(preferencelist=("plain",))
        text = body.get_content().strip() if isinstance(body, EmailMessage) else ""
        head = [
            f"From: {self.message.get('From', self.sender)}",
            f"To: {', '.join(self.recipients)}",
            f"Date: {self.message.get('Date', '?')}",
            f"Subject: {self.message.get('Subject', '')}",
        ]
        return "\n".join([*head, "", text])


class _Inbox:
    """The aiosmtpd handler: keep every message."""

    def __init__(self) -> None:
        self.mails: list[ReceivedMail] = []
        self.lock = threading.Lock()
        self.arrived = threading.Event()

    async def handle_DATA(self, server: Any, session: Any, envelope: Any) -> str:
        raw = envelope.original_content or envelope.content or b""
        if isinstance(raw, str):
            raw = raw.encode("utf-8")
        parsed = email.message_from_bytes(raw, policy=email.policy.default)
        if isinstance(parsed, EmailMessage):
            mail = ReceivedMail(str(envelope.mail_from), tuple(envelope.rcpt_tos), parsed)
            with self.lock:
                self.mails.append(mail)
            self.arrived.set()
        return "250 Message accepted"


class MailSink(Closing):
    """An SMTP server on ``127.0.0.1:port`` that keeps what it receives (a context manager).

    Raises:
        AnunnakiError: aiosmtpd is not installed, or the port cannot be bound.

    """

    def __init__(self, port: int, *, host: str = "127.0.0.1") -> None:
        try:
            from aiosmtpd.controller import Controller
        except ImportError:
            raise AnunnakiError(
                "the mail sink needs aiosmtpd: pip install 'anunnaki[mail]' "
                "(scripts/setup.sh installs it)"
            ) from None
        self.host, self.port = host, port
        self._inbox = _Inbox()
        self._controller = Controller(self._inbox, hostname=host, port=port)
        try:
            _bindable(host, port)  # at once: aiosmtpd waits its 5-s ready timeout first
            self._controller.start()
        except (OSError, RuntimeError) as exc:
            loop = self._controller.loop
            with contextlib.suppress(Exception):  # it may have started nothing to stop
                self._controller.stop()
            if not loop.is_running() and not loop.is_closed():
                loop.close()
            raise AnunnakiError(
                f"cannot start the mail sink on {host}:{port}: {exc} (another --mail-sink "
                "port, or stop what listens there)"
            ) from None
        self._open = True

    @property
    def mails(self) -> list[ReceivedMail]:
        """The messages received so far, in order."""
        with self._inbox.lock:
            return list(self._inbox.mails)

    def wait(self, timeout: float) -> bool:
        """Wait up to ``timeout`` seconds for a first message; whether one has arrived."""
        return self._inbox.arrived.wait(timeout)

    def close(self) -> None:
        """Stop the server (idempotent)."""
        if self._open:
            self._open = False
            self._controller.stop()


def _bindable(host: str, port: int) -> None:
    """Raise the ``OSError`` that binding ``host:port`` gives now (a port another server holds).

    With ``SO_REUSEADDR`` as the server sets it: a port left in ``TIME_WAIT`` by a closed
    sink binds; one that something listens on does not.
    """
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        probe.bind((host, port))
