"""Operator tokens: how strong one must be, where Utu finds its own, how one is checked.

The dashboard's token guards its HTTP operator actions; Utu's operator token guards the bus
services that change what Utu does (pause, resume, approve, reject, reload). Anyone may still
request a run-stop (guideline S4).

Those services are never open by accident: a Utu given no token (neither
``$ANUNNAKI_OPERATOR_TOKEN`` nor ``operator_token_file``) uses the user's own token file,
:func:`default_token_file`, and writes a fresh token there first if there is none, readable
by the user alone (mode 0600), as notebook servers do; ``anunnaki reload`` and the
dashboard read it from there. Every run of one user shares it, so a client started later,
or a node of another process, finds the same token.
"""

from __future__ import annotations

import contextlib
import hmac
import logging
import math
import os
import secrets
import stat
from pathlib import Path
from typing import Any, Final

from anunnaki.errors import ModelFileError

__all__ = [
    "MIN_TOKEN_BITS",
    "OPERATOR_TOKEN_ENV",
    "client_operator_token",
    "default_token_file",
    "service_operator_token",
    "token_matches",
    "token_weakness",
    "user_operator_token",
]

log = logging.getLogger("anunnaki.tokens")

#: The environment variable that holds Utu's operator token (for Utu and its clients).
OPERATOR_TOKEN_ENV: Final = "ANUNNAKI_OPERATOR_TOKEN"

#: The least estimated strength of an operator token, in bits.
MIN_TOKEN_BITS = 128

_CLASSES: tuple[tuple[str, int], ...] = (
    ("abcdefghijklmnopqrstuvwxyz", 26),
    ("ABCDEFGHIJKLMNOPQRSTUVWXYZ", 26),
    ("0123456789", 10),
)
_URLSAFE = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_")


def token_weakness(token: str) -> str | None:
    """Why ``token`` is too weak to guard operator actions, or ``None`` when it will do.

    Its strength is estimated as ``length × log2(alphabet)``, the alphabet being the sum of
    the character classes it uses (lower case 26, upper case 26, digits 10, anything else
    33), and must reach :data:`MIN_TOKEN_BITS`; a token of one repeated character or with
    fewer than 8 distinct characters is refused whatever its length. A token made of the
    URL-safe base64 alphabet in both cases counts as drawn from all 64 (a 22-character
    ``secrets.token_urlsafe(16)`` may happen to hold no digit, no ``-`` and no ``_``: it
    passes).
    """
    if not token.strip():
        return "it is empty"
    alphabet = sum(size for chars, size in _CLASSES if any(c in chars for c in token))
    if any(not any(c in chars for chars, _ in _CLASSES) for c in token):
        alphabet += 33
    if set(token) <= _URLSAFE and not token.islower() and not token.isupper():
        alphabet = max(alphabet, 64)
    bits = len(token) * math.log2(max(alphabet, 2))
    if len(set(token)) < 8:
        return f"it uses {len(set(token))} distinct characters (at least 8)"
    if bits < MIN_TOKEN_BITS:
        return f"about {bits:.0f} bits, fewer than {MIN_TOKEN_BITS}"
    return None


def token_matches(given: Any, expected: str) -> bool:
    """Whether ``given`` is ``expected``, compared in constant time (a non-string is not)."""
    return isinstance(given, str) and hmac.compare_digest(given.encode(), expected.encode())


def default_token_file() -> Path:
    """Where Utu keeps the user's operator token when none is given.

    ``$XDG_CONFIG_HOME/anunnaki/operator-token`` (``~/.config/anunnaki/operator-token`` when
    ``XDG_CONFIG_HOME`` is unset).
    """
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "anunnaki" / "operator-token"


def _read_private(path: Path) -> str:
    """The token in ``path``, which only its owner may read or write."""
    try:
        mode = path.stat().st_mode
        text = path.read_text(encoding="utf-8").strip()
    except OSError as exc:
        raise ModelFileError(
            f"cannot read the operator token: {exc.strerror}", path=str(path)
        ) from None
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise ModelFileError(
            f"the operator token file is open to others (mode {stat.S_IMODE(mode):04o})",
            path=str(path),
            hint=f"chmod 600 {path}",
        )
    if (weak := token_weakness(text)) is not None:
        raise ModelFileError(
            f"the operator token is too weak: {weak}",
            path=str(path),
            hint=f"delete {path}; Utu writes a fresh one at its next start",
        )
    return text


def user_operator_token() -> tuple[str, Path, bool]:
    """The user's operator token, written first if missing: ``(token, file, generated)``.

    A new token (``secrets.token_urlsafe(32)``, 256 bits) is written to a private temporary
    file and linked into place, so processes starting at once all end with the one token
    that won.

    Raises:
        ModelFileError: The file is unreadable, open to others, or holds a weak token.

    """
    path = default_token_file()
    if not path.exists():
        try:
            made = _write_new(path)
        except OSError as exc:
            raise ModelFileError(
                f"cannot write the operator token: {exc.strerror}",
                path=str(path),
                hint=f"give one in ${OPERATOR_TOKEN_ENV}, or set XDG_CONFIG_HOME to a folder "
                "you can write",
            ) from None
        return _read_private(path), path, made
    return _read_private(path), path, False


def _write_new(path: Path) -> bool:
    """Write a fresh token to ``path`` unless another process did first; ``True``: this one."""
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(secrets.token_urlsafe(32) + "\n")
        try:
            os.link(tmp, path)
        except FileExistsError:  # another process won the race: its token holds
            return False
        return True
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()


def client_operator_token() -> str | None:
    """The operator token a client sends: ``$ANUNNAKI_OPERATOR_TOKEN``, else the user's file.

    ``None`` when neither exists (no Utu of this user has started here; give the token in
    the variable).

    Raises:
        ModelFileError: The user's file is unreadable, open to others, or weak.

    """
    if (token := os.environ.get(OPERATOR_TOKEN_ENV)) is not None:
        return token
    path = default_token_file()
    return _read_private(path) if path.exists() else None


def service_operator_token(
    who: str, *, given: str | None = None, file: str | os.PathLike[str] | None = None
) -> str:
    """The token an operator service of ``who`` (``utu``, ``the model manager``) checks.

    The one ``given``, else ``$ANUNNAKI_OPERATOR_TOKEN``, else the token ``file``, else the
    user's own token file (:func:`user_operator_token`: written first if missing, and
    logged where), so operator services are never open by accident. Every service finds its
    token this one way.

    Raises:
        ModelFileError: A token file is unreadable, or the token too weak (naming where it
            came from).

    """
    token, where, from_file = given, "operator_token", False
    if token is None:
        token, where = os.environ.get(OPERATOR_TOKEN_ENV), f"${OPERATOR_TOKEN_ENV}"
    if token is None and file is not None:
        where, from_file = os.fspath(file), True
        try:
            token = Path(where).read_text(encoding="utf-8").strip()
        except OSError as exc:
            raise ModelFileError(
                f"cannot read the operator token: {exc.strerror}", path=where
            ) from None
    if token is None:
        token, path, generated = user_operator_token()  # checked as it is read
        log.info(
            "%s: operator token %s %s (mode 0600); anunnaki reload and the dashboard read it there",
            who,
            "written to" if generated else "read from",
            path,
        )
        return token
    if (weak := token_weakness(token)) is not None:
        raise ModelFileError(
            f"the operator token of {who} is too weak: {weak}",
            path=where if from_file else None,
            element=None if from_file else where,
            hint="make one with: python -c 'import secrets; print(secrets.token_urlsafe(32))'",
        )
    return token
