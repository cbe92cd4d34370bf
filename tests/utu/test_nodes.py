"""Utu as five nodes: the same decisions as the composed manager, readiness, run-stop, B5.

The nodes are driven by ``step_nodes`` on an in-process bus (delivery is synchronous), the
manager by ``step``: both see the same trace at the same instants, so everything they
record must be identical — decisions, inputs, verdicts and tactic state.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from anunnaki.bus import InprocHub, RunStop, open_bus
from anunnaki.clock import ManualClock
from anunnaki.errors import ModelFileError
from anunnaki.managed import ScriptedSystem
from anunnaki.utu import AutonomicManager, Knowledge, parse_config
from anunnaki.utu._nodes import (
    DECISIONS_TOPIC,
    NODE_NAMES,
    AnalyzeNode,
    ExecuteNode,
    NodeConfigError,
    PlanNode,
    UtuNode,
    build_node,
    load_parts,
    node_token,
    ready_service,
    step_nodes,
)

ROVER = Path(__file__).parents[2] / "examples" / "rover"

CONFIG = """\
anunnaki: utu/1
name: rover
goal_model: {root}/goals.yaml
binding: {binding}
tactics: {tactics}
failsafe: fail-safe
warmup: 2.0
run_stop: {{service: /rover/stop}}
"""


def config(tactics: Path | None = None, binding: Path | None = None, **extra: Any):  # type: ignore[no-untyped-def]
    text = CONFIG.format(
        root=ROVER,
        binding=binding or ROVER / "binding.yaml",
        tactics=tactics or ROVER / "tactics.yaml",
    )
    text += "".join(f"{k}: {v}\n" for k, v in extra.items())
    return parse_config(text)


def wait_for(predicate: Callable[[], bool], timeout: float = 5.0) -> bool:
    """Re-check ``predicate`` until it holds or the deadline passes (never a fixed sleep)."""
    deadline = time.monotonic() + timeout
    pause = threading.Event()
    while not predicate():
        if time.monotonic() > deadline:
            return False
        pause.wait(0.0005)
    return True


class Twin:
    """The rover scenario run twice in lock step: composed manager (A) and five nodes (B)."""

    def __init__(self, cfg: Any, *, modes: tuple[str, ...] = ("autonomous", "manual")) -> None:
        parts = load_parts(cfg)
        self.bus_a = open_bus("inproc")
        self.bus_b = open_bus("inproc")
        self.kb_a, self.kb_b = Knowledge(), Knowledge()
        self.manager = AutonomicManager.from_config(
            cfg, bus=self.bus_a, clock=ManualClock(), knowledge=self.kb_a
        )
        self.rover_a = ScriptedSystem(self.bus_a, ROVER / "trace.jsonl", modes=modes)
        self.nodes: dict[str, UtuNode] = {}
        for name in NODE_NAMES:
            kw: dict[str, Any] = {}
            if name == "analyze":
                kw["pace"] = True
            if name == "execute":
                kw["expect_plan"] = True
            self.nodes[name] = build_node(
                name, parts, bus=self.bus_b, knowledge=self.kb_b, clock=ManualClock(), **kw
            )
        self.rover_b = ScriptedSystem(self.bus_b, ROVER / "trace.jsonl", modes=modes)

    def step(self, t: float) -> None:
        self.rover_a.step(t)
        self.manager.step(t)
        self.rover_b.step(t)
        step_nodes(self.nodes, t)
        # The rovers hear buzzer commands on a subscriber thread: let them catch up before
        # the next status goes out (both the same way).
        for rover, kb in ((self.rover_a, self.kb_a), (self.rover_b, self.kb_b)):
            sent = sum(
                1
                for d in kb.decisions()
                if d.kind == "action" and d.data.get("topic") == "/rover/buzzer"
            )
            assert wait_for(lambda r=rover, n=sent: self._heard(r) == n)

    @staticmethod
    def _heard(rover: ScriptedSystem) -> int:
        return sum(1 for c in rover.commands if c[1] == "buzzer")

    def instants(self, until: float = 53.0) -> list[float]:
        extra = [50.0 + 0.25 * i for i in range(int((until - 50.0) / 0.25) + 1)]
        return sorted({*self.rover_a.instants(), *extra})

    def assert_identical(self) -> None:
        a, b = self.kb_a, self.kb_b
        assert [(d.t, d.kind, d.tactic, d.data) for d in a.decisions()] == [
            (d.t, d.kind, d.tactic, d.data) for d in b.decisions()
        ]
        assert [(r.t, r.topic, r.msg) for r in a.inputs()] == [
            (r.t, r.topic, r.msg) for r in b.inputs()
        ]
        assert [(v.t, v.node, v.utility, v.status) for v in a.verdicts()] == [
            (v.t, v.node, v.utility, v.status) for v in b.verdicts()
        ]
        assert a.tactics() == b.tactics()
        assert a.models_at() == b.models_at()

    def close(self) -> None:
        self.manager.close()
        for node in self.nodes.values():
            node.close()
        for x in (self.rover_a, self.rover_b, self.bus_a, self.bus_b, self.kb_b):
            x.close()


def queued_ops(twin: Twin) -> tuple[int, int]:
    """Operator calls waiting for the next step: (manager, monitor node)."""
    return len(twin.manager._ops), len(twin.nodes["monitor"]._ops)  # type: ignore[attr-defined]


@pytest.fixture
def twin_factory() -> Iterator[Callable[..., Twin]]:
    made: list[Twin] = []

    def make(*args: Any, **kw: Any) -> Twin:
        made.append(Twin(*args, **kw))
        return made[-1]

    yield make
    for t in made:
        t.close()


# -- the same decisions ------------------------------------------------------------------------
def test_nodes_decide_exactly_as_the_composed_manager(twin_factory) -> None:  # type: ignore[no-untyped-def]
    twin = twin_factory(config())
    for t in twin.instants():
        twin.step(t)
    twin.assert_identical()
    got = [(d.t, d.kind, d.tactic) for d in twin.kb_b.decisions() if d.t < 50]
    assert got[:5] == [
        (25.0, "selected", "fail-safe"),
        (25.0, "started", "fail-safe"),
        (25.0, "action", "fail-safe"),
        (25.0, "action", "fail-safe"),
        (25.5, "postcondition_ok", "fail-safe"),
    ]
    assert [c[2] for c in twin.rover_b.commands if c[1] == "set_mode"] == [{"mode": "manual"}]


def test_a_failed_postcondition_escalates_to_run_stop_the_same_way(twin_factory) -> None:  # type: ignore[no-untyped-def]
    # A rover that refuses manual mode: the fail-safe's postcondition fails at its deadline.
    twin = twin_factory(config(), modes=("autonomous",))
    for t in twin.instants(until=50.0):
        twin.step(t)
    twin.assert_identical()
    kinds = [(d.t, d.kind) for d in twin.kb_b.decisions()]
    assert (30.0, "postcondition_failed") in kinds
    assert (30.0, "run_stop") in kinds
    assert twin.rover_b.state().get("stopped") is True
    execute = twin.nodes["execute"]
    assert isinstance(execute, ExecuteNode) and execute.halted


def test_operator_calls_enter_the_cycle_like_the_managers(twin_factory, tmp_path) -> None:  # type: ignore[no-untyped-def]
    tactics = tmp_path / "tactics.yaml"
    text = (ROVER / "tactics.yaml").read_text()
    tactics.write_text(
        text.replace("    priority: 100\n", "    priority: 100\n    requires_approval: true\n", 1)
    )
    twin = twin_factory(config(tactics))
    calls = {
        12.0: ("/utu/pause", {"caller": "op"}),
        14.0: ("/utu/resume", {"caller": "op"}),
        27.0: ("/utu/approve", {"caller": "op", "tactic": "fail-safe", "approve": True}),
        28.0: ("/utu/approve", {"caller": "op", "tactic": "nope"}),
    }
    for t in twin.instants(until=50.0):
        for at, (service, body) in calls.items():
            if at == t:
                for bus in (twin.bus_a, twin.bus_b):
                    assert bus.request(service, body, timeout=2.0).to_body()["ok"] is True
        if t == 40.0:  # a dashboard stops everything, then the operator resumes
            for bus in (twin.bus_a, twin.bus_b):
                bus.publish("/utu/run_stop", RunStop(reason="test", caller="dashboard"))
            # Heard on subscriber threads: both must have queued it before this step.
            assert wait_for(lambda: queued_ops(twin) == (1, 1))
        if t == 42.0:
            for bus in (twin.bus_a, twin.bus_b):
                bus.request("/utu/resume", {"caller": "op"}, timeout=2.0)
        twin.step(t)
    twin.assert_identical()
    kinds = [d.kind for d in twin.kb_b.decisions()]
    for kind in ("paused", "pending_approval", "approved", "operator_refused", "run_stop"):
        assert kind in kinds
    assert kinds.index("pending_approval") < kinds.index("approved") < kinds.index("started")


def test_a_vanished_agent_node_is_handled_like_the_manager(twin_factory) -> None:  # type: ignore[no-untyped-def]
    # The oracle (agent A4) is vouched for by the liveliness of its node /oracle.
    binding = Path(__file__).parents[1] / "data" / "utu" / "binding-liveliness.yaml"
    twin = twin_factory(config(binding=binding))
    tokens = []
    for t in twin.instants(until=50.0):
        if t == 1.0:
            tokens = [bus.liveliness_token("/oracle") for bus in (twin.bus_a, twin.bus_b)]
        if t == 10.0:  # the oracle's process dies
            for token in tokens:
                token.close()
            assert wait_for(lambda: queued_ops(twin) == (1, 1))
        twin.step(t)
    twin.assert_identical()
    lost = [d for d in twin.kb_b.decisions() if d.kind == "liveliness_lost"]
    assert [(d.t, d.data["agents"]) for d in lost] == [(10.0, ["A4"])]


# -- readiness, liveliness, bring-up -----------------------------------------------------------
def test_each_node_answers_readiness_once_up_and_holds_its_token(tmp_path) -> None:  # type: ignore[no-untyped-def]
    cfg = config(knowledge=str(tmp_path / "kb.db"))
    hub = InprocHub()
    with open_bus("inproc", hub=hub) as bus, open_bus("inproc", hub=hub) as operator:
        nodes = [build_node(name, cfg, bus=bus) for name in NODE_NAMES]
        try:
            for name in NODE_NAMES:
                reply = operator.request(ready_service(name), {}, timeout=2.0).to_body()
                assert reply["ready"] is True
                assert reply["node"] == node_token(name)
            assert {node_token(n) for n in NODE_NAMES} <= operator.alive_nodes()
        finally:
            for node in nodes:
                node.close()
        assert not {node_token(n) for n in NODE_NAMES} & operator.alive_nodes()


def test_bad_configuration_fails_at_bring_up_with_file_and_line(tmp_path) -> None:  # type: ignore[no-untyped-def]
    bad = tmp_path / "tactics.yaml"
    bad.write_text((ROVER / "tactics.yaml").read_text().replace("goal: G3", "goal: G33", 1))
    with pytest.raises(ModelFileError) as err:
        load_parts(config(bad))
    assert f"{bad}:" in str(err.value) and "G33" in str(err.value)
    with pytest.raises(ModelFileError, match="cannot read the goal model"):
        load_parts(
            parse_config(CONFIG.format(root=tmp_path, binding=ROVER / "binding.yaml", tactics=bad))
        )
    with pytest.raises(ModelFileError, match="fail-safe tactic 'nope'"):
        load_parts(
            parse_config(
                CONFIG.format(
                    root=ROVER, binding=ROVER / "binding.yaml", tactics=ROVER / "tactics.yaml"
                ).replace("failsafe: fail-safe", "failsafe: nope")
            )
        )
    with open_bus("inproc") as bus:
        with pytest.raises(NodeConfigError, match="monitor, analyze, plan, execute, knowledge"):
            build_node("planner", config(), bus=bus)
        with pytest.raises(NodeConfigError, match="':memory:'"):
            build_node("analyze", config(), bus=bus)
        with pytest.raises(NodeConfigError, match="rate"):
            build_node("monitor", config(), bus=bus, rate=0)
        assert not bus.alive_nodes()  # nothing left declared


# -- run-stop, pacing, knowledge ---------------------------------------------------------------
@pytest.fixture
def five(tmp_path) -> Iterator[tuple[Any, dict[str, UtuNode], ScriptedSystem]]:  # type: ignore[no-untyped-def]
    cfg = config(knowledge=str(tmp_path / "kb.db"))
    with open_bus("inproc") as bus:
        kb = Knowledge(cfg.knowledge)
        nodes: dict[str, UtuNode] = {}
        for name in NODE_NAMES:
            kw: dict[str, Any] = {"pace": True} if name == "analyze" else {}
            if name == "execute":
                kw["expect_plan"] = True
            nodes[name] = build_node(name, cfg, bus=bus, knowledge=kb, clock=ManualClock(), **kw)
        rover = ScriptedSystem(bus, ROVER / "trace.jsonl")
        try:
            yield bus, nodes, rover
        finally:
            rover.close()
            for node in nodes.values():
                node.close()
            kb.close()


def test_a_run_stop_on_the_topic_halts_plan_and_execute_at_once(five) -> None:  # type: ignore[no-untyped-def]
    bus, nodes, rover = five
    plan, execute = nodes["plan"], nodes["execute"]
    assert isinstance(plan, PlanNode) and isinstance(execute, ExecuteNode)
    for t in rover.instants():
        if t > 20.0:
            break
        rover.step(t)
        step_nodes(nodes, t)
    bus.publish("/utu/run_stop", RunStop(reason="e-stop pressed", caller="dashboard"))
    assert wait_for(lambda: plan.run_stopped and execute.halted)  # before any cycle
    for t in rover.instants():
        if 20.0 < t <= 30.0:
            rover.step(t)
            step_nodes(nodes, t)
    decisions = execute.knowledge.decisions()
    stop = [d for d in decisions if d.kind == "run_stop"]
    assert len(stop) == 1 and stop[0].data["caller"] == "dashboard"
    assert rover.state().get("stopped") is True
    assert not [d for d in decisions if d.kind == "started"]  # the fail-safe never started
    for name in NODE_NAMES:  # every node heard it (S4)
        assert bus.request(ready_service(name), {}, timeout=2.0).to_body()["run_stopped"]


def test_knowledge_node_answers_queries_and_publishes_decisions(five) -> None:  # type: ignore[no-untyped-def]
    bus, nodes, rover = five
    published: list[dict[str, Any]] = []
    bus.subscribe(DECISIONS_TOPIC, lambda s: published.extend(s.message.to_body()["decisions"]))
    for t in rover.instants():
        if t > 27.0:
            break
        rover.step(t)
        step_nodes(nodes, t)
    reply = bus.request("/utu/knowledge/query", {"what": "decisions"}, timeout=2.0).to_body()
    assert [d["kind"] for d in reply["decisions"]][:2] == ["selected", "started"]
    state = bus.request("/utu/knowledge/query", {"what": "state"}, timeout=2.0).to_body()
    assert state["root"] == "G1" and state["t"] is not None and state["run_stopped"] is False
    queue = bus.request("/utu/knowledge/query", {"what": "queue"}, timeout=2.0).to_body()
    assert queue["ok"] is True and isinstance(queue["queue"], list)
    assert state["queue"] == queue["queue"]  # a late display sees pending approvals too
    assert wait_for(lambda: len(published) == len(reply["decisions"]))
    assert [d["kind"] for d in published] == [d["kind"] for d in reply["decisions"]]
    unknown = bus.request("/utu/knowledge/query", {"what": "x"}, timeout=2.0).to_body()
    assert unknown["ok"] is False


def test_analyze_goes_on_when_execute_does_not_answer(tmp_path) -> None:  # type: ignore[no-untyped-def]
    cfg = config(knowledge=str(tmp_path / "kb.db"))
    with open_bus("inproc") as bus:
        analyze = AnalyzeNode(cfg, bus=bus, pace=True, timeout=0.05, clock=ManualClock())
        try:
            assert analyze.step(1.0) is True
            assert analyze.step(1.1) is False  # waits for execute's report of cycle 1
            assert wait_for(lambda: analyze.step(1.2), timeout=2.0)
            assert analyze.timeouts == 1
            assert analyze.step(1.3) is True  # no longer waits until execute answers
        finally:
            analyze.close()


def test_nodes_spin_live_in_one_process(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """Spinning nodes (the pipeline over the bus, with rates) decide as the stepped ones."""
    cfg = config(knowledge=str(tmp_path / "kb.db"), clock="wall")
    with open_bus("inproc") as bus:
        kb = Knowledge(cfg.knowledge)
        nodes = [build_node(n, cfg, bus=bus, knowledge=kb, rate=200) for n in NODE_NAMES]
        stop = threading.Event()
        threads = [threading.Thread(target=n.spin, args=(stop,), daemon=True) for n in nodes]
        for th in threads:
            th.start()
        try:
            for name in NODE_NAMES:
                assert bus.request(ready_service(name), {}, timeout=2.0).to_body()["ready"]
            bus.publish("/utu/oracle/output", {"category": 1, "confidence": 0.9})
            bus.request("/utu/pause", {"caller": "test"}, timeout=2.0)
            assert wait_for(lambda: any(d.kind == "paused" for d in kb.decisions()))
        finally:
            stop.set()
            for n in nodes:
                n.wake()
            for th in threads:
                th.join(timeout=5.0)
            for n in nodes:
                n.close()
            kb.close()
        assert not any(th.is_alive() for th in threads)
