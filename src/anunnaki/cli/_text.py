"""Plain text for ``--help`` from a module docstring written in reStructuredText.

A sub-command's docstring is its documentation page in the API docs (reStructuredText:
````anunnaki robustify````, ``:func:`x```); ``--help`` is read in a terminal, where that markup
is noise. :func:`plain` drops it, so one text serves both.
"""

from __future__ import annotations

import re

__all__ = ["plain"]

# :role:`text <target>`, :role:`~a.b.c`, :role:`a.b` (roles may have a domain: :py:func:)
_ROLE = re.compile(r":(?:[A-Za-z]+:)?[A-Za-z]+:`([^`]+)`")
_LITERAL = re.compile(r"``(.+?)``", re.DOTALL)
_LINK = re.compile(r"`([^`<]+?)(?:\s*<[^>]+>)?`_{1,2}")


def _role(match: re.Match[str]) -> str:
    text = match.group(1)
    shown = re.fullmatch(r"(.+?)\s*<[^>]+>", text)
    if shown is not None:
        return shown.group(1)
    if text.startswith("~"):
        return text[1:].rsplit(".", 1)[-1]
    return text


def plain(text: str | None) -> str:
    """*text* without reStructuredText markup: literals, roles and links become their text."""
    if not text:
        return ""
    out = _ROLE.sub(_role, text)
    out = _LITERAL.sub(r"\1", out)
    return _LINK.sub(r"\1", out)
