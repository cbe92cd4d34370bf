"""The vocabulary package: message types apart from the transport, in one slot."""

from __future__ import annotations

import logging
import subprocess
import sys
from importlib.metadata import EntryPoint
from typing import Any, ClassVar

import pytest

import anunnaki.messages as messages
from anunnaki import plugins
from anunnaki.bus import Envelope, decode_envelope, encode_envelope
from anunnaki.messages import MESSAGES, Message, MessageError
from anunnaki.plugins import Registry


def test_the_vocabulary_needs_no_transport() -> None:
    code = (
        "import sys, anunnaki.messages, anunnaki.topics; "
        "bad = sorted(m for m in sys.modules if m.startswith('anunnaki.bus')); "
        "assert not bad, bad"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_the_package_example_runs() -> None:
    doc = messages.__doc__ or ""
    block = doc.split("::\n\n", 1)[1].split("\n\n", 1)[0]
    code = "\n".join(line.removeprefix("    ") for line in block.splitlines())
    exec(compile(code, "anunnaki/messages/__init__.py", "exec"), {})


def test_every_exported_type_is_in_the_slot_under_its_type_name() -> None:
    exported = [
        v for v in vars(messages).values() if isinstance(v, type) and issubclass(v, Message)
    ]
    assert len(exported) >= 14
    for cls in exported:
        if cls is Message:
            continue
        assert MESSAGES.factory(cls.type_name()) is cls


def test_the_slot_is_a_registry_keyed_by_type_name() -> None:
    assert isinstance(MESSAGES, Registry)
    assert MESSAGES.group == "anunnaki.messages"

    class Renamed(Message):
        TYPE_NAME: ClassVar[str | None] = "RenamedOnTheWire"
        x: int

    private = MESSAGES.copy(entry_points=False)
    private.register(Renamed)
    assert private.factory("RenamedOnTheWire") is Renamed
    assert "RenamedOnTheWire" not in MESSAGES.names()  # a copy is private
    with pytest.raises(MessageError, match="unknown message type 'Renamed'"):
        private.factory("Renamed")


class Ping(Message):
    """A third party's message type, registered by entry point."""

    TYPE_NAME: ClassVar[str | None] = "ThirdPartyPing"
    n: int


def test_a_third_partys_type_registers_by_entry_point_and_travels(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    eps = [
        EntryPoint("ThirdPartyPing", f"{__name__}:Ping", "anunnaki.messages"),
        EntryPoint("broken", "anunnaki_no_such_module:Nope", "anunnaki.messages"),
    ]

    def fake_entry_points(*, group: str) -> list[EntryPoint]:
        return [ep for ep in eps if ep.group == group]

    monkeypatch.setattr(plugins, "entry_points", fake_entry_points)
    try:
        with caplog.at_level(logging.WARNING, logger="anunnaki.messages"):
            MESSAGES.load_entry_points(force=True)
        raw = encode_envelope(Envelope(Ping(n=3), 1.0, 0, "tp"))
        got: Any = decode_envelope(raw).message
        assert isinstance(got, Ping) and got.n == 3
        assert "skipping message type entry point 'broken'" in caplog.text
    finally:
        MESSAGES.unregister("ThirdPartyPing")
