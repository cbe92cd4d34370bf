"""A block of work on a set number of BLAS threads (threadpoolctl), restored after.

Small matrix products split over two BLAS threads on a two-core machine whose other core is
busy make the calling thread wait for its helper at every product: the fog's noise fields
(:mod:`anunnaki.phenomena._fog`) and the enlil oracle's context lookup
(:mod:`anunnaki.enlil._oracle_plugin`) run on one thread instead.
"""

from __future__ import annotations

import contextlib
from functools import lru_cache
from typing import Any

from anunnaki.errors import MissingExtraError

__all__ = ["blas_limit"]


@lru_cache(maxsize=4)
def _controller(extra: str, with_scipy: bool) -> Any:
    """The loaded BLAS libraries, as threadpoolctl sees them (found once: a millisecond)."""
    if with_scipy:
        import scipy.linalg  # noqa: F401  # its own BLAS, loaded before it is looked for
    try:
        from threadpoolctl import ThreadpoolController  # type: ignore[import-untyped]
    except ImportError as exc:
        raise MissingExtraError("threadpoolctl", extra) from exc
    return ThreadpoolController().select(user_api="blas")


def blas_limit(
    threads: int | None, *, extra: str, with_scipy: bool = False
) -> contextlib.AbstractContextManager[Any]:
    """At most ``threads`` BLAS threads in the block (a no-op with ``None``).

    Args:
        threads: The limit; ``None`` leaves the process's setting.
        extra: The extra that installs threadpoolctl, named when it is missing.
        with_scipy: Load SciPy's BLAS first, so that it is limited too.

    """
    if threads is None:
        return contextlib.nullcontext()
    limiter: contextlib.AbstractContextManager[Any] = _controller(extra, with_scipy).limit(
        limits=threads
    )
    return limiter
