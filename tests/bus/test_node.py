"""The node kit: the framework owns bring-up, readiness, liveliness, spin and close."""

from __future__ import annotations

import threading
from typing import Any

import pytest

from anunnaki.bus import InprocHub, Node, open_bus
from anunnaki.messages import Generic


class Echo(Node):
    def __init__(self, bus: Any, *, fail: bool = False) -> None:
        self.fail = fail
        self.rounds = 0
        self.released = False
        super().__init__(bus, token="/echo", ready="/echo/ready")

    def declare(self) -> None:
        self.inbox = self.pull("/echo/in", queue=4, expect=Generic)
        if self.fail:
            raise RuntimeError("bad configuration")

    def spin_once(self) -> float:
        self.rounds += 1
        if self.rounds == 1:
            raise ValueError("one bad round")  # contained: the node lives on
        while (sample := self.inbox.try_recv()) is not None:
            self.bus.publish("/echo/out", sample.message)
            self.cycles += 1
        return 30.0  # nothing time-driven: only a message wakes it

    def ready_info(self) -> dict[str, Any]:
        return {"rounds": self.rounds}

    def release(self) -> None:
        self.released = True


def test_lifecycle_readiness_token_spin_close() -> None:
    hub = InprocHub()
    with open_bus("inproc", hub=hub) as bus, open_bus("inproc", hub=hub) as other:
        out: list[Any] = []
        got = threading.Event()
        other.subscribe("/echo/out", lambda s: (out.append(s.message.to_body()), got.set()))
        node = Echo(bus)
        stop = threading.Event()
        spinner = threading.Thread(target=node.spin, args=(stop,), daemon=True)
        spinner.start()
        try:
            reply = other.request("/echo/ready", {}, timeout=2.0).to_body()
            assert reply["ready"] is True and reply["node"] == "/echo" and "pid" in reply
            assert "/echo" in other.alive_nodes()
            other.publish("/echo/in", {"x": 1})  # wakes the node at once (waits 30 s else)
            assert got.wait(5.0) and out == [{"x": 1}]
            other.publish("/echo/in", {"x": 2})
            assert got.wait(5.0)
        finally:
            stop.set()
            node.wake()
            spinner.join(5.0)
            node.close()
        assert not spinner.is_alive() and node.released and node.rounds >= 2
        assert "/echo" not in other.alive_nodes()
        assert node.closed


def test_a_node_that_fails_to_come_up_leaves_nothing_declared() -> None:
    with open_bus("inproc") as bus:
        with pytest.raises(RuntimeError, match="bad configuration"):
            Echo(bus, fail=True)
        assert "/echo" not in bus.alive_nodes()
        bus.publish("/echo/in", {"x": 1})  # no subscriber left behind
        assert bus.stats().totals()["delivered"] == 0
