"""Operator tokens: how strong one must be, where Utu finds its own, how one is checked.

The dashboard's token guards its HTTP operator actions; Utu's operator token guards the bus
services that change what Utu does (pause, resume, approve, reject, reload). Anyone may still
request a run-stop (guideline S4).
"""

from __future__ import annotations

import hmac
import math
from typing import Any, Final

__all__ = ["MIN_TOKEN_BITS", "OPERATOR_TOKEN_ENV", "token_matches", "token_weakness"]

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
