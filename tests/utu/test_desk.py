"""The host's one operator desk: both deployments answer an operator the same way.

The inline manager (standing for the five nodes) and the monitor node hold the same
:class:`~anunnaki.utu.host.OperatorDesk`: a run-stop asked on ``/utu/run_stop`` shows in
readiness at once (before the cycle applies it), enters the next cycle as an operator
entry recorded with its caller, and a resume clears it. Before the desk was written once,
the monitor node did the first and the manager did not.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from anunnaki.bus import InprocHub, open_bus
from anunnaki.cli.main import main
from anunnaki.tactics import NotifyAction
from anunnaki.tokens import OPERATOR_TOKEN_ENV, client_operator_token, default_token_file
from anunnaki.topics import OPERATOR_SERVICES, ready_service
from anunnaki.utu import (
    AutonomicManager,
    BusActuator,
    Knowledge,
    NodeConfigError,
    build_node,
    parse_config,
)
from anunnaki.utu.host import NODE_KINDS, NODE_NAMES, step_nodes
from anunnaki.utu.host._notify import Notification, NotifyResult
from anunnaki.utu.runlog import replay

ROVER = Path(__file__).parents[2] / "examples" / "rover"
CONFIG = f"""\
anunnaki: utu/1
name: rover
goal_model: {ROVER}/goals.yaml
binding: {ROVER}/binding.yaml
tactics: {ROVER}/tactics.yaml
failsafe: fail-safe
run_stop: {{service: /rover/stop}}
"""


def _ready(bus: Any, node: str) -> dict[str, Any]:
    return dict(bus.request(ready_service(node), {}, timeout=2.0).to_body())


@pytest.mark.parametrize("deployment", ["one-process", "nodes"])
def test_a_run_stop_shows_at_once_enters_the_next_cycle_and_a_resume_clears_it(
    deployment: str, tmp_path: Path
) -> None:
    cfg = parse_config(CONFIG + f"knowledge: {tmp_path / 'kb.db'}\n")
    hub = InprocHub()
    with open_bus("inproc", hub=hub) as bus, open_bus("inproc", hub=hub) as operator:
        stops: list[dict[str, Any]] = []
        operator.service("/rover/stop", lambda m: stops.append(m.to_body()) or {"ok": True})
        kb = Knowledge(tmp_path / "kb.db")
        if deployment == "one-process":
            manager = AutonomicManager.from_config(
                cfg, bus=bus, knowledge=kb, nodes=dict.fromkeys(NODE_NAMES, 20.0)
            )
            closing: list[Any] = [manager]

            def step(t: float) -> None:
                manager.step(t)

        else:
            nodes = {
                name: build_node(name, cfg, bus=bus, knowledge=kb, rate=20.0) for name in NODE_NAMES
            }
            closing = list(nodes.values())

            def step(t: float) -> None:
                step_nodes(nodes, t)

        try:
            step(1.0)
            assert _ready(operator, "monitor")["run_stopped"] is False
            asked = {"caller": "operator-1", "reason": "hands on"}
            reply = operator.request(OPERATOR_SERVICES["run_stop"], asked, timeout=2.0)
            assert reply.to_body()["ok"] is True
            assert _ready(operator, "monitor")["run_stopped"] is True  # before any cycle
            assert stops == []  # the cycle performs it
            step(1.1)
            assert stops == [{"reason": "run-stop"}]
            made = [(d.kind, d.data.get("caller")) for d in kb.decisions()]
            assert ("run_stop", "operator-1") in made
            resume = {
                "caller": "op",
                "token": client_operator_token(),
            }  # Utu's own (docs/running.md)
            reply = operator.request(OPERATOR_SERVICES["resume"], resume, timeout=2.0)
            assert reply.to_body()["ok"] is True
            step(1.2)
            assert _ready(operator, "monitor")["run_stopped"] is False
        finally:
            for c in reversed(closing):
                c.close()
            kb.close()


def test_the_node_kinds_are_one_registry() -> None:
    assert NODE_KINDS.names() == sorted(NODE_NAMES)
    with pytest.raises(NodeConfigError, match="valid names: analyze, execute, knowledge"):
        NODE_KINDS.factory("planner")


def test_a_node_on_sim_time_never_lets_its_clock_queue_fill(tmp_path: Path) -> None:
    """Issue 21: every per-node run logged ``subscriber /clock: queue of 64 full``: the
    analyze node subscribed ``/clock`` but read it only while no monitor was up, so with a
    monitor its queue filled and the bus dropped (and logged) every further tick."""
    from anunnaki.messages import Clock

    cfg = parse_config(CONFIG + f"knowledge: {tmp_path / 'kb.db'}\nclock: sim\n")
    hub = InprocHub()
    with open_bus("inproc", hub=hub) as bus, open_bus("inproc", hub=hub) as sim:
        kb = Knowledge(tmp_path / "kb.db")
        nodes = {
            name: build_node(name, cfg, bus=bus, knowledge=kb, rate=20.0)
            for name in ("monitor", "analyze", "plan", "execute")
        }
        try:
            t = 0.0
            for _ in range(10):  # 10 rounds of 20 ticks: 200 in all, more than a queue
                for _ in range(20):
                    t += 0.01
                    sim.publish("/clock", Clock(time=t))
                for node in nodes.values():
                    node.spin_once()
            assert bus.stats().dropped == {}
        finally:
            for node in reversed(nodes.values()):
                node.close()
            kb.close()


def test_only_a_host_offering_operator_services_writes_the_users_token_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A manager without a bus (a replay, a manager fed by hand) offers no operator services:
    it leaves the user's ``~/.config/anunnaki/operator-token`` alone. Before, the monitor
    stage resolved the token when built, so ``anunnaki replay`` wrote the file."""
    home, config_home = tmp_path / "home", tmp_path / "config"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.setenv("XDG_CONFIG_HOME", str(config_home))
    monkeypatch.delenv(OPERATOR_TOKEN_ENV, raising=False)
    token_file = default_token_file()
    assert token_file.is_relative_to(config_home)
    db = tmp_path / "kb.db"
    cfg = parse_config(CONFIG + f"knowledge: {db}\n")
    with AutonomicManager.from_config(cfg) as manager:  # no bus: fed by hand
        manager.feed("/rover/status", {"mode": "autonomous", "buzzer": False, "bumper": False})
        manager.step(1.0)
        manager.pause("op")  # operator calls in this process need no token
        manager.step(2.0)
        assert manager.paused
    report = replay(db)
    assert report.identical and report.steps == 2
    assert main(["replay", str(db)]) == 0
    assert "identical" in capsys.readouterr().out
    assert not config_home.exists() and not any(home.iterdir())
    # A manager that offers the services on a bus makes the token, as before.
    with open_bus("inproc") as bus, AutonomicManager.from_config(cfg, bus=bus):
        assert token_file.read_text(encoding="utf-8").strip() == client_operator_token()
        assert token_file.stat().st_mode & 0o077 == 0


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
