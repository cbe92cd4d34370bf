"""Enki's error: bad input to ``anunnaki robustify``; the message says what to do."""

from __future__ import annotations

from anunnaki.errors import AnunnakiError

__all__ = ["EnkiError"]


class EnkiError(AnunnakiError):
    """Bad input to Enki (a model, an archive, a work folder); the message names the fix."""
