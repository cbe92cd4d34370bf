"""The garbage collector around a command's bring-up (``anunnaki.cli._heap``, issue #30 item 4).

Paused while the command line is parsed; ``anunnaki run`` keeps it paused until its nodes
and managed system are up, then freezes what they made and collects again; ``main`` called
as a function hands everything back to the collector when it returns.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from pathlib import Path

import pytest

from anunnaki.cli import _heap
from anunnaki.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
LAUNCH = ROOT / "examples" / "rover" / "utu.yaml"  # the scripted rover: no network to load


@pytest.fixture(autouse=True)
def _collector() -> Iterator[None]:
    """Each test from a collecting, unfrozen heap, and back to one whatever it did."""
    gc.enable()
    gc.unfreeze()
    yield
    _heap.end(unfreeze=True)
    gc.enable()
    gc.unfreeze()


def test_pause_settle_end() -> None:
    _heap.pause()
    assert not gc.isenabled()
    _heap.settle()
    assert gc.isenabled() and gc.get_freeze_count() > 0
    _heap.end(unfreeze=False)
    assert gc.get_freeze_count() > 0  # the process's own command line keeps it frozen
    _heap.end(unfreeze=True)
    assert gc.isenabled() and gc.get_freeze_count() == 0


def test_a_collector_already_off_stays_off() -> None:
    gc.disable()
    _heap.pause()
    _heap.settle()
    _heap.end(unfreeze=True)
    assert not gc.isenabled() and gc.get_freeze_count() == 0


def test_a_command_that_does_not_settle_gets_the_collector_back_at_once(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(SystemExit):
        main(["--version"])
    assert gc.isenabled() and gc.get_freeze_count() == 0
    assert main(["check", str(LAUNCH)]) == 0
    assert gc.isenabled() and gc.get_freeze_count() == 0
    capsys.readouterr()


def test_run_freezes_its_bring_up_once_running(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    seen: list[tuple[bool, int]] = []
    settle = _heap.settle

    def spy() -> None:
        seen.append((gc.isenabled(), gc.get_freeze_count()))
        settle()
        seen.append((gc.isenabled(), gc.get_freeze_count()))

    monkeypatch.setattr(_heap, "settle", spy)
    db = tmp_path / "run.db"
    args = ["run", str(LAUNCH), "--no-case", "--knowledge", str(db), "--speed", "0"]
    assert main([*args, "--until", "1"]) == 0
    assert seen[0] == (False, 0)  # the whole bring-up without a collection
    assert seen[1][0] and seen[1][1] > 0  # then frozen, and collecting
    assert len(seen) == 2
    assert gc.isenabled() and gc.get_freeze_count() == 0  # main() called: handed back
    capsys.readouterr()
