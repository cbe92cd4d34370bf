"""The one interface the web application needs from whoever performs operator actions."""

from __future__ import annotations

from typing import Any, Protocol

__all__ = ["Operator"]


class Operator(Protocol):
    """Whatever performs the operator's actions for the web application.

    ``operate`` takes ``pause``, ``resume``, ``approve``, ``reject`` or ``run_stop`` and
    returns Utu's reply, or raises :class:`~anunnaki.dashboard.OperatorError`.
    """

    def operate(
        self,
        op: str,
        *,
        caller: str,
        tactic: str | None = ...,
        reason: str | None = ...,
        timeout: float = ...,
    ) -> dict[str, Any]:
        """Call Utu's service for ``op`` on behalf of ``caller``."""
