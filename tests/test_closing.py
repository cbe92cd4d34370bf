"""anunnaki._closing: the one ``with`` protocol of the resource holders."""

from __future__ import annotations

import pytest

from anunnaki._closing import Closing
from anunnaki.bus import InprocBus
from anunnaki.trace import TraceWriter


class _Holder(Closing):
    def __init__(self) -> None:
        self.closed = 0

    def close(self) -> None:
        self.closed += 1


def test_with_gives_the_object_and_closes_it_on_the_way_out() -> None:
    with _Holder() as h:
        assert isinstance(h, _Holder)
        assert h.closed == 0
    assert h.closed == 1


def test_an_exception_in_the_block_still_closes_and_propagates() -> None:
    h = _Holder()
    with pytest.raises(ValueError, match="boom"), h:
        raise ValueError("boom")
    assert h.closed == 1


def test_a_subclass_without_close_says_so() -> None:
    class NoClose(Closing):
        pass

    with pytest.raises(NotImplementedError, match="NoClose must define close"), NoClose():
        pass


def test_the_resource_holders_close_at_the_end_of_with(tmp_path) -> None:
    with InprocBus() as bus:
        assert not bus.closed
    assert bus.closed
    with TraceWriter(tmp_path / "t.jsonl", {"source": "test"}) as w:
        pass
    assert w._fh.closed
    assert (tmp_path / "t.jsonl").read_text().strip()
