"""One suite for every deployment of the MAPE-K cycle (composed, five nodes); node bring-up.

The nodes are driven by ``step_nodes`` on an in-process bus (delivery is synchronous), the
manager by ``step``: both see the same trace at the same instants, so each test states
what any deployment must decide, and everything they record must be identical —
decisions, inputs, verdicts and tactic state.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from anunnaki.bus import InprocHub, open_bus
from anunnaki.clock import ManualClock
from anunnaki.errors import ModelFileError
from anunnaki.managed import ScriptedSystem
from anunnaki.messages import RunStop
from anunnaki.tokens import client_operator_token
from anunnaki.topics import DECISIONS as DECISIONS_TOPIC
from anunnaki.topics import node_token, ready_service
from anunnaki.utu import (
    NODE_NAMES,
    AutonomicManager,
    Knowledge,
    NodeConfigError,
    UtuNode,
    build_node,
    parse_config,
)
from anunnaki.utu.cycle import load_parts
from anunnaki.utu.host import AnalyzeNode, ExecuteNode, PlanNode, step_nodes

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

#: A reload's reply waits for its service to read and check the tactics file against the goal
#: model (real parsing, tenths of a second of CPU); on a starved machine that took over the bus's
#: default 2 s once. The tests assert what the reply says, not how soon it comes.
RELOAD_TIMEOUT = 30.0


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


class Deployment:
    """The rover scenario on one deployment of Utu: the composed manager, or five nodes.

    Both are driven deterministically at the trace's instants (``step`` / ``step_nodes`` on
    an in-process bus, whose delivery is synchronous), so one suite states what every
    deployment must do, and :func:`logs` compares what they recorded.
    """

    def __init__(self, kind: str, cfg: Any, *, modes: tuple[str, ...]) -> None:
        self.kind = kind
        parts = load_parts(cfg)
        self.bus = open_bus("inproc")
        self.kb = Knowledge()
        self.manager: AutonomicManager | None = None
        self.nodes: dict[str, UtuNode] = {}
        if kind == "composed":
            self.manager = AutonomicManager.from_config(
                parts, bus=self.bus, clock=ManualClock(), knowledge=self.kb
            )
        else:
            for name in NODE_NAMES:
                kw: dict[str, Any] = {}
                if name == "analyze":
                    kw["pace"] = True
                if name == "execute":
                    kw["expect_plan"] = True
                self.nodes[name] = build_node(
                    name, parts, bus=self.bus, knowledge=self.kb, clock=ManualClock(), **kw
                )
        self.rover = ScriptedSystem(self.bus, ROVER / "trace.jsonl", modes=modes)

    def step(self, t: float) -> None:
        self.rover.step(t)
        if self.manager is not None:
            self.manager.step(t)
        else:
            step_nodes(self.nodes, t)
        # The rover hears buzzer commands on a subscriber thread: let it catch up before
        # the next status goes out.
        sent = sum(
            1
            for d in self.kb.decisions()
            if d.kind == "action" and d.data.get("topic") == "/rover/buzzer"
        )
        assert wait_for(lambda: sum(1 for c in self.rover.commands if c[1] == "buzzer") == sent)

    def instants(self, until: float = 53.0) -> list[float]:
        extra = [50.0 + 0.25 * i for i in range(int((until - 50.0) / 0.25) + 1)]
        return sorted({*self.rover.instants(), *extra})

    def queued_ops(self) -> int:
        """Operator calls waiting for the next step."""
        if self.manager is not None:
            return len(self.manager.desk)
        return len(self.nodes["monitor"].desk)  # type: ignore[attr-defined]

    def halted(self) -> bool:
        if self.manager is not None:
            return self.manager.paused
        execute = self.nodes["execute"]
        assert isinstance(execute, ExecuteNode)
        return execute.halted

    def close(self) -> None:
        if self.manager is not None:
            self.manager.close()
        for node in self.nodes.values():
            node.close()
        for x in (self.rover, self.bus):
            x.close()
        if self.manager is None:
            self.kb.close()


def logs(kb: Knowledge) -> dict[str, Any]:
    """Everything a run records: decisions, inputs, verdicts, tactic state, model texts."""
    return {
        "decisions": [(d.t, d.kind, d.tactic, d.data) for d in kb.decisions()],
        "inputs": [(r.t, r.topic, r.msg) for r in kb.inputs()],
        "verdicts": [(v.t, v.node, v.utility, v.status) for v in kb.verdicts()],
        "tactics": kb.tactics(),
        "models": kb.models_at(),
    }


DEPLOYMENTS = ("composed", "nodes")


@pytest.fixture(params=DEPLOYMENTS)
def deploy(request: pytest.FixtureRequest) -> Iterator[Callable[..., Deployment]]:
    made: list[Deployment] = []

    def make(cfg: Any, *, modes: tuple[str, ...] = ("autonomous", "manual")) -> Deployment:
        made.append(Deployment(request.param, cfg, modes=modes))
        return made[-1]

    yield make
    for d in made:
        d.close()


_REFERENCE: dict[str, dict[str, Any]] = {}


def same_as_composed(name: str, d: Deployment, tmp: Path | None = None) -> None:
    """Every deployment records what the composed manager records (run first, as reference).

    Each run has its own temporary folder (``tmp``): its path is masked.
    """
    got = logs(d.kb)
    if tmp is not None:
        got = json.loads(json.dumps(got, default=repr).replace(str(tmp), "<tmp>"))
    if d.kind == "composed":
        _REFERENCE[name] = got
    elif name in _REFERENCE:
        assert got == _REFERENCE[name]


# -- what every deployment decides -------------------------------------------------------------
def test_the_fail_safe_hands_over_to_manual(deploy) -> None:  # type: ignore[no-untyped-def]
    d = deploy(config())
    for t in d.instants():
        d.step(t)
    got = [(x.t, x.kind, x.tactic) for x in d.kb.decisions() if x.t < 50]
    assert got[:5] == [
        (25.0, "selected", "fail-safe"),
        (25.0, "started", "fail-safe"),
        (25.0, "action", "fail-safe"),
        (25.0, "action", "fail-safe"),
        (25.5, "postcondition_ok", "fail-safe"),
    ]
    assert [c[2] for c in d.rover.commands if c[1] == "set_mode"] == [{"mode": "manual"}]
    same_as_composed("hand-over", d)


def test_a_refused_action_escalates_to_run_stop_at_once(deploy) -> None:  # type: ignore[no-untyped-def]
    # A rover that refuses manual mode: the fail-safe failed when its action was refused
    # (t = 25), not when its postcondition's deadline passed (t = 30; issue #12).
    d = deploy(config(), modes=("autonomous",))
    for t in d.instants(until=50.0):
        d.step(t)
    kinds = [(x.t, x.kind) for x in d.kb.decisions()]
    assert kinds.index((25.0, "action_failed")) < kinds.index((25.0, "run_stop"))
    assert not any(k == "postcondition_failed" for _, k in kinds)
    assert d.rover.state().get("stopped") is True
    assert d.halted()
    same_as_composed("escalation", d)


def test_operator_calls_enter_the_cycle(deploy, tmp_path) -> None:  # type: ignore[no-untyped-def]
    tactics = tmp_path / "tactics.yaml"
    text = (ROVER / "tactics.yaml").read_text()
    tactics.write_text(
        text.replace("    priority: 100\n", "    priority: 100\n    requires_approval: true\n", 1)
    )
    d = deploy(config(tactics))
    token = client_operator_token()  # Utu's own token (docs/running.md), as clients read it
    calls = {
        12.0: ("/utu/pause", {"caller": "op", "token": token}),
        14.0: ("/utu/resume", {"caller": "op", "token": token}),
        27.0: (
            "/utu/approve",
            {"caller": "op", "token": token, "tactic": "fail-safe", "approve": True},
        ),
        28.0: ("/utu/approve", {"caller": "op", "token": token, "tactic": "nope"}),
    }
    for t in d.instants(until=50.0):
        for at, (service, body) in calls.items():
            if at == t:
                assert d.bus.request(service, body, timeout=2.0).to_body()["ok"] is True
        if t == 40.0:  # a dashboard stops everything, then the operator resumes
            d.bus.publish("/utu/run_stop", RunStop(reason="test", caller="dashboard"))
            # Heard on a subscriber thread: it must be queued before this step.
            assert wait_for(lambda: d.queued_ops() == 1)
        if t == 42.0:
            d.bus.request("/utu/resume", {"caller": "op", "token": token}, timeout=2.0)
        d.step(t)
    kinds = [x.kind for x in d.kb.decisions()]
    for kind in ("paused", "pending_approval", "approved", "operator_refused", "run_stop"):
        assert kind in kinds
    assert kinds.index("pending_approval") < kinds.index("approved") < kinds.index("started")
    refused = d.bus.request(
        "/utu/approve",
        {"caller": "op", "token": token, "tactic": "fail-safe", "approve": "false"},
        timeout=2.0,
    )
    assert refused.to_body()["ok"] is False  # not a boolean: refused, never read as true
    same_as_composed("operator", d, tmp_path)


def test_a_vanished_agent_node_makes_its_agent_unknown(deploy) -> None:  # type: ignore[no-untyped-def]
    # The oracle (agent A4) is vouched for by the liveliness of its node /oracle.
    binding = Path(__file__).parents[1] / "data" / "utu" / "binding-liveliness.yaml"
    d = deploy(config(binding=binding))
    token = None
    for t in d.instants(until=50.0):
        if t == 1.0:
            token = d.bus.liveliness_token("/oracle")
        if t == 10.0:  # the oracle's process dies
            assert token is not None
            token.close()
            assert wait_for(lambda: d.queued_ops() == 1)
        d.step(t)
    lost = [x for x in d.kb.decisions() if x.kind == "liveliness_lost"]
    assert [(x.t, x.data["agents"]) for x in lost] == [(10.0, ["A4"])]
    same_as_composed("liveliness", d)


def test_a_hot_reload_applies_in_the_cycle(deploy, tmp_path) -> None:  # type: ignore[no-untyped-def]
    d = deploy(config(reload_dirs=f"[{tmp_path}]"))
    op = {"caller": "op", "token": client_operator_token()}
    bad = tmp_path / "bad.yaml"
    bad.write_text((ROVER / "tactics.yaml").read_text().replace("goal: G3", "goal: G33", 1))
    renamed = tmp_path / "renamed.yaml"
    renamed.write_text((ROVER / "tactics.yaml").read_text().replace("fail-safe", "hand-over"))
    good = tmp_path / "good.yaml"
    good.write_text((ROVER / "tactics.yaml").read_text().replace("priority: 100", "priority: 90"))
    for t in d.instants(until=30.0):
        if t == 5.0:
            reply = d.bus.request(
                "/utu/reload", {"tactics": str(bad), **op}, timeout=RELOAD_TIMEOUT
            ).to_body()
            assert reply["ok"] is False and reply["status"] == "refused"
            assert f"{bad}:" in reply["error"] and "G33" in reply["error"]
        if t == 6.0:
            # The configuration names the fail-safe: a tactics file without it is refused.
            body = {"tactics": str(renamed), **op}
            reply = d.bus.request("/utu/reload", body, timeout=RELOAD_TIMEOUT).to_body()
            assert reply["ok"] is False and "fail-safe tactic 'fail-safe'" in reply["error"]
        if t == 7.0:
            reply = d.bus.request(
                "/utu/reload", {"tactics": str(good), **op}, timeout=RELOAD_TIMEOUT
            ).to_body()
            assert reply == {"ok": True, "queued": "reload", "caller": "op", "status": "accepted"}
        d.step(t)
    kinds = [(x.t, x.kind) for x in d.kb.decisions()]
    assert (5.0, "reload_refused") in kinds and (6.0, "reload_refused") in kinds
    assert (7.0, "reloaded") in kinds
    assert d.kb.models_at()["tactics"][0] == str(good)
    started = [x for x in d.kb.decisions() if x.kind == "started"]
    assert started and started[0].data["priority"] == 90  # the reloaded tactic ran
    same_as_composed("reload", d, tmp_path)


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
        names = "valid names: analyze, execute, knowledge, monitor, plan"
        with pytest.raises(NodeConfigError, match=names):
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


def test_a_cycle_through_the_nodes_enters_each_stage_once_in_order(five) -> None:  # type: ignore[no-untyped-def]
    """The nodes enter their stages as the composed manager does, once each per cycle.

    Plan and execute in different processes each keep a copy of the tactic runtimes, so
    each takes the other's fields once per cycle (``mirror``) before its own stage runs;
    the analyze node ends the step when execute reports it done, without its stage.
    """
    _, nodes, rover = five
    calls: list[str] = []
    watched = {
        "monitor": ("monitor", "batch"),
        "analyze": ("analyze", "analyze"),
        "execute.begin": ("execute", "begin"),
        "plan.mirror": ("plan", "mirror"),
        "plan": ("plan", "plan"),
        "execute.mirror": ("execute", "mirror"),
        "execute.complete": ("execute", "complete"),
    }
    for label, (node, method) in watched.items():
        stage = nodes[node].stage  # type: ignore[attr-defined]
        original = getattr(stage, method)

        def entered(*args, _label=label, _original=original, **kwargs):  # type: ignore[no-untyped-def]
            calls.append(_label)
            return _original(*args, **kwargs)

        setattr(stage, method, entered)
    steps = 0
    for t in rover.instants():
        if t > 27.0:
            break
        rover.step(t)
        step_nodes(nodes, t)
        steps += 1
    assert calls == list(watched) * steps
    kinds = [d.kind for d in nodes["execute"].knowledge.decisions()]
    assert kinds[:3] == ["selected", "started", "action"]  # the fail-safe started at 25 s


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
            bus.request(
                "/utu/pause", {"caller": "test", "token": client_operator_token()}, timeout=2.0
            )
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


def test_a_forged_batch_time_is_refused_alone_by_the_analyze_node(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """A /utu/monitor/input stamped 1e12 is dropped; a real batch beside it is analysed."""
    from anunnaki import topics
    from anunnaki.messages import MonitorBatch, MonitorInput

    cfg = config(knowledge=str(tmp_path / "kb.db"))
    with open_bus("inproc") as bus:
        analyze = AnalyzeNode(cfg, bus=bus, pace=False, clock=ManualClock())
        # the monitor node's readiness says which origin its batches carry
        bus.service("/utu/monitor/ready", lambda m: {"ready": True, "origin": "m"})
        try:
            assert analyze.step(1.0)
            real = MonitorInput(topic="/rover/status", t=2.0, msg={"mode": "autonomous"})
            bus.publish(topics.MONITOR_INPUT, MonitorBatch(origin="m", seq=1, t=2.0, inputs=[real]))
            bus.publish(topics.MONITOR_INPUT, MonitorBatch(origin="m", seq=2, t=1e12, inputs=[]))
            status = analyze.stage.topic_watch.topics["/rover/status"]
            assert wait_for(lambda: analyze.step() and status.count == 1)
            assert analyze.stage.now == 2.0 and analyze.stage.refused == 1
        finally:
            analyze.close()


def test_operator_services_need_the_operator_token_but_a_run_stop_never_does(
    deploy, tmp_path, monkeypatch
) -> None:  # type: ignore[no-untyped-def]
    """An anonymous /utu/resume cleared a run-stop (issue #12); with a token it cannot."""
    token = "Op-token-for-the-test-0123456789"
    (tmp_path / "token").write_text(token + "\n")
    d = deploy(config(operator_token_file=str(tmp_path / "token")))
    refused, allowed = [], []
    for t in d.instants(until=20.0):
        if t == 5.0:  # anyone may stop the robot (S4)
            reply = d.bus.request("/utu/run_stop", {"caller": "anyone"}, timeout=2.0)
            allowed.append(reply.to_body()["ok"])
        if t == 6.0:
            for body in ({"caller": "x"}, {"caller": "x", "token": "guess"}, {"token": 7}):
                reply = d.bus.request("/utu/resume", body, timeout=2.0).to_body()
                refused.append((reply["ok"], reply.get("status")))
            reply = d.bus.request("/utu/pause", {"caller": "x"}, timeout=2.0).to_body()
            refused.append((reply["ok"], reply.get("status")))
        if t == 8.0:
            reply = d.bus.request("/utu/resume", {"caller": "op", "token": token}, timeout=2.0)
            allowed.append(reply.to_body()["ok"])
        d.step(t)
    assert refused == [(False, "unauthorised")] * 4 and allowed == [True, True]
    watched = ("run_stop", "resumed_adaptation", "paused")
    kinds = [(x.kind, x.data.get("caller")) for x in d.kb.decisions() if x.kind in watched]
    assert kinds[:2] == [("run_stop", "anyone"), ("resumed_adaptation", "op")]
    assert not any(k == "paused" for k, _ in kinds)
    assert token not in json.dumps([x.data for x in d.kb.decisions()])  # never recorded


def test_hostile_cycle_messages_neither_raise_nor_steer_any_deployment(deploy, caplog) -> None:  # type: ignore[no-untyped-def]
    """Forged, type-valid messages on Utu's internal topics (issue #12: 103 tracebacks in
    per-node mode, a forged /utu/analyze/state caused a run-stop): none raises, none changes
    a decision — the run decides what the clean run decides."""
    from hostile_cycle import hostile_cycle_messages

    d = deploy(config())
    sent = 0
    with caplog.at_level(logging.WARNING):
        for t in d.instants(until=30.0):
            if t in (3.0, 26.0):  # nominal, and with the fail-safe in flight
                for topic, message in hostile_cycle_messages(t):
                    d.bus.publish(topic, message)
                    sent += 1
            d.step(t)
    assert sent == 30
    raised = [r for r in caplog.records if r.exc_info or "Traceback" in r.getMessage()]
    assert raised == [], [r.getMessage() for r in raised]
    kinds = [(x.t, x.kind, x.tactic) for x in d.kb.decisions()]
    assert not any(k in ("run_stop", "paused", "escalated") for _, k, _ in kinds)
    assert (25.0, "started", "fail-safe") in kinds and (
        25.5,
        "postcondition_ok",
        "fail-safe",
    ) in kinds


def test_a_stuck_node_is_run_stopped_by_its_watchdog(tmp_path) -> None:  # type: ignore[no-untyped-def]
    # Issue #12: the watchdog existed only in the one-process loop. A per-node round that
    # hangs (a deadlock, a hung handler) run-stops the platform from the watchdog's thread
    # and announces it on /utu/run_stop, which the monitor records.
    cfg = config(knowledge=str(tmp_path / "kb.db"), watchdog=1.0)  # run_stop: /rover/stop
    hub = InprocHub()
    release = threading.Event()
    stops: list[dict[str, Any]] = []
    heard: list[RunStop] = []
    with open_bus("inproc", hub=hub) as bus, open_bus("inproc", hub=hub) as robot:
        robot.service("/rover/stop", lambda m: stops.append(m.to_body()) or {"ok": True})
        robot.subscribe("/utu/run_stop", lambda s: heard.append(s.message), queue=8)
        node = build_node("plan", cfg, bus=bus)
        rounds = 0
        own_round = node.spin_once

        def stuck_round() -> float:
            nonlocal rounds
            rounds += 1
            if rounds == 3:
                release.wait(30)  # stuck here
            return own_round()

        node.spin_once = stuck_round  # type: ignore[method-assign]
        stop = threading.Event()
        spinner = threading.Thread(target=node.spin, args=(stop,))
        spinner.start()
        try:
            assert wait_for(lambda: bool(stops) and bool(heard), timeout=10.0)
            assert rounds == 3  # still stuck: the platform was told from outside the round
            assert "watchdog: node plan" in heard[0].reason
            assert heard[0].caller == "watchdog:plan"
        finally:
            release.set()
            stop.set()
            node.wake()
            spinner.join(10)
            node.close()
    assert len(stops) == 1  # once per stall


def test_analyze_waits_for_the_nodes_it_expects_before_its_first_cycle(tmp_path) -> None:  # type: ignore[no-untyped-def]
    # Issue #12's fault benchmark: with the platform running first, a per-node run analysed
    # (and recorded) inputs before plan and execute were up, and its replay — every part
    # there from the start — acted earlier. A launch's analyze node now waits for them.
    from anunnaki.utu import Knowledge

    kb_path = tmp_path / "kb.db"
    cfg = config(knowledge=str(kb_path))
    hub = InprocHub()
    with open_bus("inproc", hub=hub) as bus, open_bus("inproc", hub=hub) as later:
        analyze = build_node("analyze", cfg, bus=bus, expect=("execute",), pace=False)
        try:
            assert analyze.step(1.0) is False  # execute not up: no cycle, nothing recorded
            assert analyze.stage.cycles == 0
            token = later.liveliness_token(node_token("execute"))
            assert wait_for(lambda: analyze.step(2.0))  # up: the first cycle runs
            token.close()
        finally:
            analyze.close()
    with Knowledge(kb_path) as kb:
        assert [r.t for r in kb.inputs() if r.topic == "__tick__"] == [2.0]
