"""Managed systems are plugins named by ``kind``: one contract for every kind, errors located."""

from __future__ import annotations

import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any, ClassVar

import pytest
from pydantic import BaseModel

from anunnaki.bus import Executor, open_bus
from anunnaki.errors import ModelFileError
from anunnaki.launch import load_launch, parse_launch, run_launch
from anunnaki.managed import (
    MANAGED,
    DecisionLike,
    ManagedContext,
    ScriptedKind,
    SimKind,
    UtuSettings,
)
from anunnaki.utu import parse_config

ROOT = Path(__file__).parents[2]
ROVER = ROOT / "examples" / "rover"
HEAD = (
    "anunnaki: launch/1\n"
    f"utu: {{goal_model: {ROVER}/goals.yaml, binding: {ROVER}/binding.yaml, "
    f"tactics: {ROVER}/tactics.yaml, failsafe: fail-safe, clock: sim}}\n"
)

#: Options of each built-in kind for the contract suite (a short, cheap run).
BUILTIN_OPTIONS: dict[str, dict[str, Any]] = {
    "scripted": {"trace": str(ROVER / "trace.jsonl"), "publish_clock": True},
    "sim": {
        "scenario": str(ROVER / "demo-scenario.yaml"),
        "models": str(ROOT / "examples" / "models" / "rover.yaml"),
        "report": False,
    },
}


def test_the_built_in_kinds_are_registered() -> None:
    assert {"scripted", "sim"} <= set(MANAGED.names())
    assert MANAGED.factory("scripted") is ScriptedKind and MANAGED.factory("sim") is SimKind


@pytest.mark.parametrize("on_executor", [False, True], ids=["threads", "executor"])
@pytest.mark.parametrize("kind", sorted(BUILTIN_OPTIONS))
def test_contract_every_kind_checks_starts_ends_and_closes(kind: str, on_executor: bool) -> None:
    """A kind runs on the bus's threads, or (``deterministic``) drains the run's executor."""
    cls = MANAGED.factory(kind)
    managed = cls(cls.Options.model_validate(BUILTIN_OPTIONS[kind]), base=ROVER)  # type: ignore[attr-defined]
    utu = parse_config(f"anunnaki: utu/1\ngoal_model: {ROVER}/goals.yaml\nclock: sim\n")
    managed.check(utu)  # B5: everything it needs is loaded now
    assert managed.speed > 0 and managed.deterministic is True
    assert all(isinstance(n, str) for n in managed.notes(utu, 2.0))
    said: list[str] = []
    heard: list[str] = []
    clocks: list[float] = []
    executor = Executor() if on_executor else None
    with open_bus("inproc", executor=executor) as bus:
        seen = threading.Event()
        bus.subscribe(
            "/rover/status", lambda s: (heard.append(threading.current_thread().name), seen.set())
        )
        bus.subscribe("/clock", lambda s: clocks.append(s.message.time))
        ctx = ManagedContext(
            bus=bus,
            stop=threading.Event(),
            speed=1000.0,
            until=2.0,
            say=said.append,
            executor=executor,
        )
        run = managed.start(ctx)
        try:
            run.thread.join(timeout=120)
            assert not run.thread.is_alive()  # it ends by itself at `until`
            assert seen.wait(10.0)  # it spoke the rover's topics
            assert said and said[0].startswith("managed: ")
            assert isinstance(run.ended, str) and run.ended
            if on_executor:  # every message delivered on the kind's thread, its /clock too
                assert set(heard) == {run.thread.name}
                assert clocks and max(clocks) <= 2.0 + 1e-9
                assert clocks == sorted(clocks)
            else:
                assert run.thread.name not in heard  # the bus's own threads deliver
            run.finish([], 1.0)
        finally:
            run.close()


def test_a_simulated_system_runs_torch_on_the_threads_it_is_given() -> None:
    """``torch_threads``: torch's threads while the system runs, the process's put back at its
    close (a test process, or a program that runs a launch among other work, keeps its own)."""
    torch = pytest.importorskip("torch")
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        options = SimKind.Options.model_validate({**BUILTIN_OPTIONS["sim"], "torch_threads": 1})
        managed = SimKind(options, base=ROVER)
        executor = Executor()
        with open_bus("inproc", executor=executor) as bus:
            stop = threading.Event()
            ctx = ManagedContext(
                bus=bus, stop=stop, speed=1000.0, until=0.5, say=[].append, executor=executor
            )
            run = managed.start(ctx)
            try:
                assert torch.get_num_threads() == 1
                run.thread.join(timeout=120)
                assert not run.thread.is_alive()
            finally:
                run.close()
            assert torch.get_num_threads() == 2
        with pytest.raises(ValueError, match="torch_threads"):
            SimKind.Options.model_validate({**BUILTIN_OPTIONS["sim"], "torch_threads": 0})
    finally:
        torch.set_num_threads(before)


def test_kind_key_and_the_older_form_load_the_same() -> None:
    new = parse_launch(HEAD + f"managed: {{kind: scripted, trace: {ROVER}/trace.jsonl}}\n")
    old = parse_launch(HEAD + f"managed: {{scripted: {{trace: {ROVER}/trace.jsonl}}}}\n")
    assert isinstance(new.managed, ScriptedKind) and isinstance(old.managed, ScriptedKind)
    assert new.managed.options == old.managed.options
    assert parse_launch(HEAD).managed is None  # no managed system: the robot is real


def test_bad_managed_sections_name_file_line_and_element(tmp_path: Path) -> None:
    bad = tmp_path / "launch.yaml"
    bad.write_text(HEAD + "managed:\n  kind: submarine\n")
    with pytest.raises(ModelFileError) as err:
        load_launch(bad)
    text = str(err.value)
    assert f"{bad}:4:" in text and "unknown managed system 'submarine'" in text
    assert "valid names: ros1, ros2, scripted, sim" in text
    bad.write_text(HEAD + "managed:\n  kind: scripted\n  trace: t.jsonl\n  sped: 2\n")
    with pytest.raises(ModelFileError, match=r":6: managed.sped: .*unknown field") as err2:
        load_launch(bad)
    assert err2.value.path == str(bad)


class _Silent:
    """A third party's kind: a robot that says nothing (for the plugin mechanism)."""

    name: ClassVar[str] = "silent"

    class Options(BaseModel):
        seconds: float = 0.01

    def __init__(self, options: Any, *, base: Path) -> None:
        self.options = options
        self.speed = 1.0
        self.started = False

    def check(self, utu: UtuSettings) -> None:
        return None

    def notes(self, utu: UtuSettings, speed: float) -> list[str]:
        return ["note: a silent robot"]

    def start(self, ctx: ManagedContext) -> Any:
        self.started = True
        thread = threading.Thread(target=ctx.stop.wait, args=(self.options.seconds,))
        thread.start()

        class Run:
            ended = "silence ended"

            def __init__(self) -> None:
                self.thread = thread

            def finish(self, decisions: Sequence[DecisionLike], ran: float) -> None:
                ctx.say(f"silent: {len(decisions)} decisions")

            def close(self) -> None:
                return None

        return Run()


def test_a_third_party_kind_runs_from_a_launch_file() -> None:
    MANAGED.register(_Silent)
    try:
        launch = parse_launch(HEAD + "managed: {kind: silent, seconds: 0.05}\n")
        assert isinstance(launch.managed, _Silent)
        import io

        out = io.StringIO()
        result = run_launch(launch, out=out, handle_signals=False)
        assert launch.managed.started and result.reason == "silence ended"
        assert "note: a silent robot" in out.getvalue() and "silent: " in out.getvalue()
    finally:
        MANAGED.unregister("silent")
