"""A block of work on a set number of BLAS threads (threadpoolctl), restored after.

Small matrix products split over two BLAS threads on a two-core machine whose other core is
busy make the calling thread wait for its helper at every product: the fog's noise fields
(:mod:`anunnaki.phenomena._fog`) and the enlil oracle's context lookup
(:mod:`anunnaki.enlil._oracle_plugin`) run on one thread instead.

:func:`torch_threads` does the same for torch's intra-op threads: a command that computes
on ``--threads`` threads, called in a process that goes on (a test, a notebook, a
benchmark measuring in-process), leaves that process's torch as it found it.
"""

from __future__ import annotations

import contextlib
import importlib.util
from collections.abc import Iterator
from functools import lru_cache
from typing import Any

from anunnaki.errors import MissingExtraError

__all__ = ["blas_limit", "torch_threads"]


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


@contextlib.contextmanager
def torch_threads(threads: int | None) -> Iterator[None]:
    """Torch computes on ``threads`` intra-op threads in the block, as before it after.

    A no-op with ``None`` or 0, or where torch is not installed (a plugin's model may not
    need it); torch is imported only when a number is given.
    """
    if not threads or importlib.util.find_spec("torch") is None:
        yield
        return
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        yield
    finally:
        torch.set_num_threads(before)
