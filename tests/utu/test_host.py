"""What every host has, written once (``anunnaki.utu.host._host``), seen from both hosts.

The inline manager and the execute node hold the same execute side: a notification's
delivery, reported later from the notifier's thread, is recorded as a ``notify_result``
decision by either host, committed at once, and closing the host stops its notifier and
records no more. Before, each host had its own callback and close-down, and they differed:
the manager's left the row for its next step's commit, and the execute node wired none to
an actuator it was given.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from anunnaki.bus import open_bus
from anunnaki.tactics import NotifyAction
from anunnaki.utu import AutonomicManager, BusActuator, Knowledge, build_node, parse_config
from anunnaki.utu.host import NODE_NAMES
from anunnaki.utu.host._notify import Notification, NotifyResult

ROVER = Path(__file__).parents[2] / "examples" / "rover"
CONFIG = f"""\
anunnaki: utu/1
name: rover
goal_model: {ROVER}/goals.yaml
binding: {ROVER}/binding.yaml
tactics: {ROVER}/tactics.yaml
"""


class Courier:
    """A notifier that delivers at once, in the caller's thread, and says when it is closed."""

    def __init__(self) -> None:
        self.closed = False

    def send_in_background(self, note: Notification, callback: Any = None) -> None:
        if callback is not None:
            callback(NotifyResult(True, note.channel, note.to, None, 0.0))

    def close(self) -> None:
        self.closed = True


@pytest.mark.parametrize("host", ["manager", "execute node"])
def test_a_delivery_is_recorded_until_the_host_closes(host: str, tmp_path: Path) -> None:
    db = tmp_path / "kb.db"
    cfg = parse_config(CONFIG + f"knowledge: {db}\n")
    courier = Courier()
    action = NotifyAction(channel="log", to="ops", subject="s", message="m")

    def results() -> list[tuple[str | None, bool, str]]:
        with Knowledge(db) as kb:
            rows = [d for d in kb.decisions() if d.kind == "notify_result"]
        return [(d.tactic, d.data["ok"], d.data["to"]) for d in rows]

    with open_bus("inproc") as bus:
        actuator = BusActuator(bus, courier)
        kb = Knowledge(db)
        if host == "manager":
            nodes = dict.fromkeys(NODE_NAMES, 20.0)
            built: Any = AutonomicManager.from_config(
                cfg, bus=bus, knowledge=kb, actuator=actuator, nodes=nodes
            )
        else:
            built = build_node("execute", cfg, bus=bus, knowledge=kb, actuator=actuator)
        with built:
            assert actuator.notify(action, "fail-safe", 1.0).ok
            assert results() == [("fail-safe", True, "ops")]
        kb.close()
        assert courier.closed  # the host's close stopped its notifier
        actuator.notify(action, "fail-safe", 2.0)  # delivered after the close: not recorded
        assert results() == [("fail-safe", True, "ops")]
