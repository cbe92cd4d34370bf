"""The exceptions Anunnaki raises.

Every error derives from :class:`AnunnakiError`. Errors about a file a user wrote
(goal model, binding, tactics, trace, config) are :class:`ModelFileError`: they carry
the file, the line, the element and a hint on what to do, and render as one
``file:line: element: message (hint)`` line that editors and terminals understand.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = [
    "AnunnakiError",
    "ExpressionError",
    "MissingExtraError",
    "ModelFileError",
    "render_location",
    "validation_message",
]

#: What pydantic puts before the text of an exception a validator raised: its wording,
#: not ours (``Value error, unknown phenomenon 'smog'``).
_PYDANTIC_PREFIXES = ("Value error, ", "Assertion failed, ")


def render_location(
    message: str,
    *,
    path: str | None = None,
    line: int | None = None,
    element: str | None = None,
    hint: str | None = None,
    severity: str | None = None,
) -> str:
    """Render ``file:line: [severity: ]element: message (hint: …)``.

    The one shape of every problem found in a user file: errors and
    :class:`~anunnaki._findings.Finding`.
    """
    where = path or "<input>"
    if line is not None:
        where += f":{line}"
    text = f"{where}: "
    if severity:
        text += f"{severity}: "
    if element:
        text += f"{element}: "
    text += message
    if hint:
        text += ("\n" if "\n" in message else " ") + f"(hint: {hint})"
    return text


def validation_message(error: Mapping[str, Any]) -> str:
    """The message of one pydantic validation error (an item of ``exc.errors()``), as we say it.

    Every message built from a pydantic ``ValidationError`` goes through here: a validator's
    own text is printed as it was written, without the library's ``Value error,`` (or
    ``Assertion failed,``) in front.
    """
    msg = str(error.get("msg", ""))
    for prefix in _PYDANTIC_PREFIXES:
        if msg.startswith(prefix):
            return msg[len(prefix) :]
    return msg


class AnunnakiError(Exception):
    """Base class of every error Anunnaki raises on purpose."""


class ModelFileError(AnunnakiError):
    """A user-written file is unreadable, hostile or invalid.

    Args:
        message: What is wrong, in one sentence.
        path: The file, when there is one (``None`` for text given in memory).
        line: 1-based line number of the offending element, when known.
        element: The element at fault, e.g. ``goals[G6].utility`` or ``tactic fail-safe``.
        hint: What to do about it.

    """

    def __init__(
        self,
        message: str,
        *,
        path: str | Path | None = None,
        line: int | None = None,
        element: str | None = None,
        hint: str | None = None,
    ) -> None:
        self.message = message
        self.path = str(path) if path is not None else None
        self.line = line
        self.element = element
        self.hint = hint
        super().__init__(self.render())

    def render(self) -> str:
        """Return ``file:line: element: message (hint: …)``."""
        return render_location(
            self.message, path=self.path, line=self.line, element=self.element, hint=self.hint
        )


class ExpressionError(ModelFileError):
    """A utility or precondition expression does not parse or is out of bounds."""


class MissingExtraError(AnunnakiError, ImportError):
    """An optional dependency is missing; the message names the ``pip install`` command."""

    def __init__(self, module: str, extra: str) -> None:
        super().__init__(
            f"{module} is not installed; install it with: pip install 'anunnaki[{extra}]'"
        )
