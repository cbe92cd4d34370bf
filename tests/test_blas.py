"""anunnaki._blas: a block on a set number of BLAS threads, the process's setting restored."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from anunnaki._blas import blas_limit, torch_threads
from anunnaki.errors import MissingExtraError

threadpoolctl = pytest.importorskip("threadpoolctl")


def _blas_threads() -> set[int]:
    return {i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"}


def test_the_block_runs_on_the_limit_and_the_setting_comes_back() -> None:
    np.ones((4, 4)) @ np.ones((4, 4))  # numpy's BLAS loaded
    before = _blas_threads()
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        with blas_limit(1, extra="phenomena"):
            assert _blas_threads() == {1}
        assert _blas_threads() == {2}
        with blas_limit(None, extra="phenomena"):  # no limit: the setting as it is
            assert _blas_threads() == {2}
    assert _blas_threads() == before


def test_a_missing_threadpoolctl_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    from anunnaki import _blas

    _blas._controller.cache_clear()
    monkeypatch.setitem(sys.modules, "threadpoolctl", None)  # import fails
    try:
        with pytest.raises(MissingExtraError, match=r"pip install 'anunnaki\[oracle\]'"):
            blas_limit(1, extra="oracle")
    finally:
        _blas._controller.cache_clear()


def test_torch_computes_on_the_threads_asked_and_as_before_after() -> None:
    torch = pytest.importorskip("torch")
    before = torch.get_num_threads()
    with torch_threads(before + 1):
        assert torch.get_num_threads() == before + 1
    assert torch.get_num_threads() == before
    with pytest.raises(RuntimeError, match="boom"), torch_threads(before + 2):
        raise RuntimeError("boom")
    assert torch.get_num_threads() == before  # after a failure too
    for none in (None, 0):
        with torch_threads(none):
            assert torch.get_num_threads() == before
