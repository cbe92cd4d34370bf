"""Nodes started by hand: the survivors run-stop the platform when one dies (issue #12).

Five ``anunnaki node`` processes (no launch supervising them) join a zenoh session on
loopback that hosts the scripted rover — with its own liveliness guard off, so every stop
it receives comes from Utu. One node is killed with SIGKILL; exactly one survivor must
run-stop the platform, once, and record ``node_died``; the run replays identically.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sqlite3
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers_procs import ROVER, read_decisions, rover_trace, wait_until

from anunnaki.bus import open_bus
from anunnaki.bus._zenoh import free_port
from anunnaki.managed import ScriptedSystem
from anunnaki.topics import UTU_NODES
from anunnaki.utu import parse_config, replay
from anunnaki.utu.host import ACT_ORDER, PeerWatch

LAUNCH = """\
anunnaki: launch/1
name: rover
utu: {{goal_model: {rover}/goals.yaml, binding: {rover}/binding.yaml,
      tactics: {rover}/tactics.yaml, clock: wall, warmup: 1.0, failsafe: fail-safe,
      run_stop: {{service: /rover/stop}}}}
knowledge: {db}
bus: {{kind: zenoh, mode: peer, listen: ['{endpoint}']}}
nodes:
  monitor: {{rate: 20}}
  analyze: {{rate: 20}}
  plan: {{rate: 20}}
  execute: {{rate: 20}}
  knowledge: {{rate: 10}}
"""


NODE = [sys.executable, "-m", "anunnaki.cli.main", "node"]


class Nodes:
    """The five nodes as processes started by hand; every one killed on leaving."""

    def __init__(self, launch: Path, folder: Path) -> None:
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self.logs = {name: folder / f"{name}.log" for name in UTU_NODES}
        for name in UTU_NODES:
            with self.logs[name].open("wb") as out:
                self.procs[name] = subprocess.Popen(
                    [*NODE, name, "-c", str(launch), "--mode", "client"],
                    stdout=out,
                    stderr=subprocess.STDOUT,
                    stdin=subprocess.DEVNULL,
                    env={**os.environ, "PYTHONUNBUFFERED": "1"},
                )

    def output(self) -> str:
        return "\n".join(
            f"--- {n}\n{p.read_text(errors='replace')[-3000:]}" for n, p in self.logs.items()
        )

    def ready(self) -> bool:
        for name, proc in self.procs.items():
            if proc.poll() is not None:
                raise AssertionError(f"node {name} exited early:\n{self.output()}")
        return all(f"node {n} ready" in p.read_text(errors="replace") for n, p in self.logs.items())

    def kill(self, name: str) -> None:
        os.kill(self.procs[name].pid, signal.SIGKILL)
        self.procs[name].wait(timeout=30)

    def close(self) -> None:
        for proc in self.procs.values():
            if proc.poll() is None:
                proc.kill()
        for proc in self.procs.values():
            proc.wait(timeout=30)


@contextlib.contextmanager
def rover_and_nodes(tmp_path: Path) -> Iterator[tuple[ScriptedSystem, Nodes, Path]]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    db = tmp_path / "run.db"
    launch = tmp_path / "launch.yaml"
    launch.write_text(LAUNCH.format(rover=ROVER, db=db, endpoint=endpoint))
    stop = threading.Event()
    with open_bus("zenoh", listen=[endpoint]) as bus:
        rover = ScriptedSystem(bus, rover_trace(120.0, oracle=0), stop_without_utu=None)
        player = threading.Thread(target=rover.run, args=(stop,), daemon=True)
        nodes = Nodes(launch, tmp_path)
        try:
            wait_until(nodes.ready, 90.0, "five nodes ready", explain=nodes.output)
            player.start()
            yield rover, nodes, db
        finally:
            stop.set()
            nodes.close()
            if player.is_alive():
                player.join(timeout=30)
            rover.close()


def stops(rover: ScriptedSystem) -> int:
    return sum(1 for c in rover.commands if c[1] == "stop")


def snapshot(db: Path, to: Path) -> Path:
    """A consistent copy of the knowledge base while the nodes still write it."""
    with (
        contextlib.closing(sqlite3.connect(f"file:{db}?mode=ro", uri=True)) as src,
        contextlib.closing(sqlite3.connect(to)) as dst,
    ):
        src.backup(dst)
    return to


@pytest.mark.slow
@pytest.mark.parametrize(
    ("victim", "actor", "via"),
    [("plan", "execute", "execute"), ("execute", "analyze", "analyze")],
)
def test_survivors_run_stop_the_platform_once_when_a_node_is_killed(
    tmp_path: Path, victim: str, actor: str, via: str
) -> None:
    with rover_and_nodes(tmp_path) as (rover, nodes, db):
        # The loop is running: it recorded the rover's messages and ended steps.
        wait_until(
            lambda: _ticks(db) >= 5,
            60.0,
            "the loop's first steps",
            explain=nodes.output,
        )
        assert stops(rover) == 0
        nodes.kill(victim)
        died = wait_until(
            lambda: [d for d in read_decisions(db) if d.kind == "node_died"],
            30.0,
            "a node_died decision",
            explain=nodes.output,
        )
        if via == "execute":  # the loop performs it: its run_stop decision comes after
            wait_until(
                lambda: [d for d in read_decisions(db) if d.kind == "run_stop"],
                30.0,
                "the execute node's run-stop",
                explain=nodes.output,
            )
        else:  # the survivor's own request came before its record; its announcement too
            wait_until(lambda: _operator_calls(db), 30.0, "the run-stop recorded as an op")
        copy = snapshot(db, tmp_path / "copy.db")
        assert stops(rover) == 1, rover.commands
        assert len(died) == 1, died
        assert died[0].data["by"] == actor and died[0].data["via"] == via
        assert f"/utu_{victim}" in died[0].data["problem"]
        if via == "analyze":
            assert died[0].data["ok"] is True and died[0].data["service"] == "/rover/stop"
        said = nodes.logs[actor].read_text(errors="replace")
        assert f"{actor}: node {victim} is gone" in said, nodes.output()
    report = replay(copy)
    assert report.identical, report.summary()
    with contextlib.closing(sqlite3.connect(copy)) as conn:
        kinds = [k for (k,) in conn.execute("SELECT kind FROM decisions ORDER BY id")]
    assert ("run_stop" in kinds) == (via == "execute"), kinds


def _ticks(db: Path) -> int:
    return _count(db, "SELECT count(*) FROM inputs WHERE topic = '__tick__'")


def _operator_calls(db: Path) -> int:
    return _count(db, "SELECT count(*) FROM inputs WHERE topic = '__operator__'")


def _count(db: Path, sql: str) -> int:
    if not db.exists():
        return 0
    try:
        with contextlib.closing(sqlite3.connect(f"file:{db}?mode=ro", uri=True)) as conn:
            return int(conn.execute(sql).fetchone()[0])
    except sqlite3.OperationalError:
        return 0


def test_the_first_survivor_in_order_acts_once_per_death() -> None:
    """On an in-process bus: which watch acts, and that a supervised node would not watch."""
    cfg = parse_config(
        "anunnaki: utu/1\nname: rover\n"
        f"goal_model: {ROVER}/goals.yaml\nbinding: {ROVER}/binding.yaml\n"
        f"tactics: {ROVER}/tactics.yaml\nrun_stop: {{service: /rover/stop}}\n"
    )
    assert ACT_ORDER[0] == "execute" and set(ACT_ORDER) == set(UTU_NODES)
    with open_bus("inproc") as bus:
        said: list[str] = []
        tokens = {n: bus.liveliness_token(f"/utu_{n}") for n in ("analyze", "plan", "knowledge")}
        watches = {n: PeerWatch(n, bus, cfg, say=said.append) for n in tokens}
        try:
            wait_until(
                lambda: all(len(w._alive) == 2 for w in watches.values()), 10.0, "the tokens"
            )
            watches.pop("plan").close()
            tokens.pop("plan").close()  # plan dies: analyze is the first survivor in order
            wait_until(lambda: said, 10.0, "a survivor to act")
            # Each watch handles the event on its own thread: wait for the other one too.
            wait_until(lambda: "plan" not in watches["knowledge"]._alive, 10.0, "knowledge")
            assert [w.name for w in watches.values() if w.acted] == ["analyze"]
            assert said[0].startswith(
                "analyze: node plan is gone (its token /utu_plan vanished): run-stop sent to "
                "/rover/stop (FAILED"  # no platform on this bus
            ), said
            assert len(said) == 1
            tokens.pop("knowledge").close()  # another death: analyze acts again, once
            wait_until(lambda: len(said) == 2, 10.0, "the second death")
            assert watches["analyze"].acted == [
                "node plan is gone (its token /utu_plan vanished)",
                "node knowledge is gone (its token /utu_knowledge vanished)",
            ]
        finally:
            for w in watches.values():
                w.close()
            for tok in tokens.values():
                tok.close()
