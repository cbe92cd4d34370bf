"""Findings: what static checks report about user files (shared by goals, tactics, check)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from anunnaki.errors import ModelFileError, render_location

__all__ = ["Finding", "Severity"]

Severity = Literal["error", "warning"]


@dataclass(frozen=True)
class Finding:
    """One problem found in a user file, located by file, line and element."""

    severity: Severity
    message: str
    path: str | None = None
    line: int | None = None
    element: str | None = None
    hint: str | None = None

    def render(self) -> str:
        """Render as ``file:line: severity: element: message (hint: …)``."""
        return render_location(
            self.message,
            path=self.path,
            line=self.line,
            element=self.element,
            hint=self.hint,
            severity=self.severity,
        )

    def to_error(self) -> ModelFileError:
        """Turn into the exception a strict loader raises."""
        return ModelFileError(
            self.message, path=self.path, line=self.line, element=self.element, hint=self.hint
        )

    @classmethod
    def from_error(cls, exc: ModelFileError, severity: Severity = "error") -> Finding:
        """Wrap an exception raised while loading."""
        return cls(severity, exc.message, exc.path, exc.line, exc.element, exc.hint)
