"""The one ``with`` protocol of everything that holds a resource: leaving the block closes it."""

from __future__ import annotations

from types import TracebackType
from typing import Self

__all__ = ["Closing"]


class Closing:
    """A mixin: ``with obj:`` gives ``obj`` and calls its :meth:`close` on the way out.

    A subclass defines :meth:`close` (idempotent: it may be called again after ``with``);
    one whose ``with`` should also start it overrides :meth:`__enter__`.
    """

    __slots__ = ()

    def close(self) -> None:
        raise NotImplementedError(f"{type(self).__name__} must define close()")

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
