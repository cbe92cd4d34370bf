"""``anunnaki run`` / ``anunnaki node``: launch files, the rover end to end, signals, B5.

The rover example runs once in one process (the composed manager: one deterministic
program on an executor), once with the node classes in one process, and once with one
process per node over zenoh on loopback (both live: the replay waits for no one); all three
must take the same decisions, the live ones within a tolerance in simulated time.
Everything waits on conditions with deadlines.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from anunnaki.bus import open_bus
from anunnaki.cli.main import main
from anunnaki.errors import ModelFileError
from anunnaki.launch import (
    LaunchError,
    RunResult,
    load_launch,
    parse_launch,
    run_launch,
)
from anunnaki.managed import ScriptedKind
from anunnaki.topics import node_token, ready_service
from anunnaki.utu import NODE_NAMES, Knowledge
from live_rover import LIVE_LAG, LIVE_SPEED, live_decisions

ROVER = Path(__file__).parents[2] / "examples" / "rover"
EXAMPLE = ROVER / "utu.yaml"


def wait_for(predicate: Callable[[], bool], timeout: float = 10.0) -> bool:
    """Re-check ``predicate`` until it holds or the deadline passes (never a fixed sleep)."""
    deadline = time.monotonic() + timeout
    pause = threading.Event()
    while not predicate():
        if time.monotonic() > deadline:
            return False
        pause.wait(0.01)
    return True


def gone(pid: int) -> bool:
    """Whether a process has ended (a zombie waiting for its parent counts as ended)."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().split(")")[-1].split()[0] == "Z"
    except FileNotFoundError:
        return True


def launch_file(tmp_path: Path, text: str, name: str = "launch.yaml") -> Path:
    p = tmp_path / name
    p.write_text(text.replace("ROVER", str(ROVER)))
    return p


def looping_example(tmp_path: Path) -> Path:
    """The rover example as a launch file in ``tmp_path`` whose trace loops (runs until stopped)."""
    text = EXAMPLE.read_text().replace("loop: false", "loop: true")
    for name in ("goals.yaml", "binding.yaml", "tactics.yaml", "trace.jsonl"):
        text = text.replace(f": {name}", f": ROVER/{name}")
    return launch_file(tmp_path, text)


def node_launch_file(tmp_path: Path) -> tuple[Path, str]:
    """A launch file for one node on its own: the rover's model, zenoh on a free port."""
    from anunnaki.bus._zenoh import free_port

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    text = (
        "anunnaki: launch/1\nutu:\n  goal_model: ROVER/goals.yaml\n"
        "  binding: ROVER/binding.yaml\n  tactics: ROVER/tactics.yaml\n"
        f"knowledge: kb.db\nbus: {{kind: zenoh, listen: ['{endpoint}']}}\n"
    )
    return launch_file(tmp_path, text), endpoint


def run(launch_path: Path, **kw) -> tuple[RunResult, str]:  # type: ignore[no-untyped-def]
    out = io.StringIO()
    result = run_launch(load_launch(launch_path), out=out, handle_signals=False, **kw)
    return result, out.getvalue()


def story(result: RunResult) -> list[tuple[str, str | None]]:
    return [(d.kind, d.tactic) for d in result.decisions]


# A launch file's start, with the rover's goal model and binding inline.
HEAD = "anunnaki: launch/1\nutu: {goal_model: ROVER/goals.yaml, binding: ROVER/binding.yaml}\n"

ROVER_STORY = [
    ("selected", "fail-safe"),
    ("started", "fail-safe"),
    ("action", "fail-safe"),
    ("action", "fail-safe"),
    ("postcondition_ok", "fail-safe"),
    ("selected", "warn-pedestrians"),
    ("started", "warn-pedestrians"),
    ("action", "warn-pedestrians"),
    ("postcondition_ok", "warn-pedestrians"),
]


# -- the launch file -----------------------------------------------------------------------
def test_the_rover_launch_file_loads() -> None:
    launch = load_launch(EXAMPLE)
    assert launch.name == "rover"
    assert list(launch.nodes) == list(NODE_NAMES)
    assert launch.nodes["monitor"] == 50 and launch.nodes["knowledge"] == 10
    assert launch.bus.kind == "inproc" and launch.utu.clock == "sim"
    scripted = launch.managed
    assert isinstance(scripted, ScriptedKind) and scripted.options.publish_clock
    assert Path(scripted.options.trace) == ROVER / "trace.jsonl" and scripted.records
    assert Path(launch.utu.goal_model) == ROVER / "goals.yaml"
    processes = load_launch(ROVER / "utu-processes.yaml", read_records=False)
    assert processes.bus.kind == "zenoh"
    assert isinstance(processes.managed, ScriptedKind) and not processes.managed.records


def test_a_utu_configuration_runs_with_every_node(tmp_path: Path) -> None:
    p = launch_file(
        tmp_path,
        "anunnaki: utu/1\ngoal_model: ROVER/goals.yaml\nbinding: ROVER/binding.yaml\n"
        "tactics: ROVER/tactics.xml\nrate: 7\n",
        "utu.yaml",
    )
    launch = load_launch(p)
    assert launch.nodes == dict.fromkeys(NODE_NAMES, 7.0) and launch.managed is None


@pytest.mark.parametrize(
    ("body", "line", "message"),
    [
        (
            HEAD + "nodes: [monitor, planner]\n",
            3,
            "nodes",
        ),
        ("anunnaki: launch/1\nutu:\n  goal_model: ROVER/goals.yaml\n  rate: -1\n", 4, "rate"),
        (
            HEAD + "bus:\n  kind: zenoh\n  listen: [localhost]\n",
            5,
            "endpoint",
        ),
        (
            "anunnaki: launch/1\nutu:\n  goal_model: ROVER/goals.yaml\n"
            "  binding: ROVER/binding.yaml\n  tactics: ROVER/tactics.yaml\n  failsafe: nope\n",
            6,
            "nope",
        ),
        (
            HEAD + "managed:\n  scripted:\n    trace: missing.jsonl\n",
            None,
            "missing.jsonl",
        ),
        ("anunnaki: launch/1\nutu: {goal_model: ROVER/missing.yaml}\n", None, "missing.yaml"),
        (
            HEAD + "nodes: [plan, plan]\n",
            3,
            "twice",
        ),
        ("anunnaki: launch/2\nutu: x\n", 1, "not a launch file"),
    ],
)
def test_bad_launch_files_name_file_and_line(
    tmp_path: Path, body: str, line: int | None, message: str
) -> None:
    p = launch_file(tmp_path, body)
    with pytest.raises(ModelFileError) as err:
        load_launch(p)
    text = str(err.value)
    assert message in text
    if line is not None:
        assert text.startswith(f"{p}:{line}:"), text


@pytest.mark.parametrize(
    "managed",
    [
        "managed:\n  scripted:\n    trace: ROVER/trace.jsonl\n    {key}: {value}\n",
        "managed:\n  kind: scripted\n  trace: ROVER/trace.jsonl\n  {key}: {value}\n",
    ],
)
@pytest.mark.parametrize(("key", "value"), [("sync", "true"), ("sync_timeout", "2.0")])
def test_a_removed_replay_option_says_so_with_its_line_and_the_fix(
    tmp_path: Path, managed: str, key: str, value: str
) -> None:
    """``sync``/``sync_timeout`` (the replay waiting for Utu) were removed: a launch file
    that still has one is told where, and what to do, before anything starts."""
    body = HEAD + managed.format(key=key, value=value)
    p = launch_file(tmp_path, body)
    with pytest.raises(ModelFileError) as err:
        load_launch(p)
    exc = err.value
    assert exc.line == body.count("\n")  # the key's own line, the last
    assert exc.message == f"'{key}' was removed"
    assert exc.element is not None and exc.element.endswith(f".{key}")
    assert exc.hint is not None and exc.hint.startswith("delete the key")
    assert "executor" in exc.hint and "rosbag play" in exc.hint
    assert str(exc).startswith(f"{p}:{exc.line}:")


def test_parse_launch_from_text() -> None:
    launch = parse_launch(
        "anunnaki: launch/1\nutu: {goal_model: goals.yaml, binding: binding.yaml}\n"
        "nodes: {analyze: {rate: 5}, monitor: null}\n",
        base=ROVER,
    )
    assert launch.path is None
    assert launch.nodes == {"monitor": 20.0, "analyze": 5.0}  # cycle order, default rate


# -- the rover, end to end -------------------------------------------------------------------
def assert_the_rover_story(result: RunResult, out: str) -> None:
    assert result.exit_code == 0 and result.reason == "trace ended"
    assert story(result) == ROVER_STORY, out
    first = result.decisions[0]
    # The fail-safe fires when the oracle's category turns 1 (t=25, trace phase dim-light)
    # and its postcondition (G3 satisfied, by manual operation) holds while it stays 1.
    assert 25.0 <= first.t < 25.5
    switched = result.decisions[2]
    assert switched.data["mode"] == "manual" and switched.data["ok"] is True
    verified = result.decisions[4]
    assert verified.t <= first.t + 5.0 and verified.t < 45.0
    assert "postcondition_ok" in out and "fail-safe" in out


def assert_the_live_rover_story(result: RunResult, out: str) -> None:
    """What a live run of the rover guarantees (:mod:`live_rover`): the same decisions in the
    same order, the switch to manual, and the fail-safe at the latest ``LIVE_LAG`` simulated
    seconds after the light dims at t=25 (it may come sooner). The exact times are the
    deterministic run's (:func:`test_rover_in_one_process_end_to_end`).
    """
    assert result.exit_code == 0 and result.reason == "trace ended"
    decisions = live_decisions(result.decisions)
    assert [(d.kind, d.tactic) for d in decisions] == ROVER_STORY, out
    first, switched, verified = decisions[0], decisions[2], decisions[4]
    assert first.t < 25.0 + LIVE_LAG, out
    assert switched.data["mode"] == "manual" and switched.data["ok"] is True
    assert verified.t <= first.t + 5.0  # the fail-safe's deadline
    assert "postcondition_ok" in out and "fail-safe" in out


def test_rover_in_one_process_end_to_end() -> None:
    result, out = run(EXAMPLE, speed=50)
    assert_the_rover_story(result, out)
    assert set(result.pids.values()) == {os.getpid()}
    assert "ready: monitor, analyze, plan, execute, knowledge" in out


@pytest.mark.slow
def test_rover_with_the_node_classes_in_one_process(tmp_path: Path) -> None:
    text = EXAMPLE.read_text().replace("  knowledge: {rate: 10}\n", "")
    p = launch_file(
        tmp_path,
        text.replace("goals.yaml", "ROVER/goals.yaml")
        .replace("binding.yaml", "ROVER/binding.yaml")
        .replace("tactics.yaml", "ROVER/tactics.yaml")
        .replace("trace.jsonl", "ROVER/trace.jsonl"),
    )
    result, out = run(p, speed=LIVE_SPEED, knowledge=str(tmp_path / "kb.db"))
    assert "4 nodes in one process" in out  # on threads of their own: a live run
    assert_the_live_rover_story(result, out)
    # In one process every input is stamped with the instant it was published in (the bus
    # delivers in publication order): no decision comes before the deterministic run's, so
    # the fail-safe waits for the light to dim (tests/live_rover.py).
    deterministic = run(EXAMPLE, speed=50)[0].decisions
    for live, exact in zip(live_decisions(result.decisions), deterministic, strict=True):
        assert exact.t <= live.t <= exact.t + LIVE_LAG, out


def test_run_until_stops_at_the_given_trace_time() -> None:
    result, _ = run(EXAMPLE, speed=50, until=27.0)
    assert result.exit_code == 0 and result.reason == "reached t=27"
    assert story(result) == ROVER_STORY[:5]


@pytest.mark.slow
def test_rover_one_process_per_node_over_zenoh(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    db = tmp_path / "run.db"
    with caplog.at_level("WARNING", logger="anunnaki"):
        result, out = run(EXAMPLE, processes=True, speed=LIVE_SPEED, knowledge=str(db))
    # A normal end is quiet: the platform's guard is down before the nodes exit (issue 21).
    assert not [r for r in caplog.records if "liveliness guard" in r.getMessage()], caplog.text
    assert_the_live_rover_story(result, out)
    deterministic = story(run(EXAMPLE, speed=50)[0])  # in one process, on the executor
    assert [(d.kind, d.tactic) for d in live_decisions(result.decisions)] == deterministic
    pids = set(result.pids.values())
    assert len(pids) == 5 and os.getpid() not in pids
    assert wait_for(lambda: all(gone(p) for p in pids))
    assert "[analyze] node analyze ready" in out
    assert db.exists()  # the shared knowledge base stays


# -- the command line ----------------------------------------------------------------------
def test_cli_run_prints_one_line_per_decision(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", str(EXAMPLE), "--speed", "50", "--until", "26"]) == 0
    out = capsys.readouterr().out
    lines = [ln for ln in out.splitlines() if re.match(r"\s+\d+\.\d{3}  ", ln)]
    assert [ln.split()[1:3] for ln in lines] == [list(k) for k in ROVER_STORY[:5]]
    assert lines[2].split()[0] == "25.000" and "mode=manual" in lines[2]


def test_cli_bad_config_exits_2_with_file_and_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = launch_file(
        tmp_path,
        "anunnaki: launch/1\nutu:\n  goal_model: ROVER/goals.yaml\n"
        "  warmup: soon\n  binding: ROVER/binding.yaml\n",
    )
    for argv in (
        ["run", str(bad)],
        ["run", str(bad), "--processes"],
        ["node", "monitor", "--config", str(bad)],
    ):
        assert main(argv) == 2
        assert f"{bad}:4:" in capsys.readouterr().err
    memory = launch_file(
        tmp_path,
        HEAD + "knowledge: ':memory:'\nbus: {kind: zenoh}\n",
        "memory.yaml",
    )
    assert main(["node", "plan", "--config", str(memory)]) == 2
    assert f"{memory}:3:" in capsys.readouterr().err
    inproc = launch_file(
        tmp_path,
        HEAD + "bus: {kind: inproc}\n",
        "inproc.yaml",
    )
    assert main(["node", "monitor", "--config", str(inproc)]) == 2
    assert f"{inproc}:3:" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:
        main(["node", "planner", "--config", str(inproc)])
    assert exit_.value.code == 2
    assert "invalid choice: 'planner'" in capsys.readouterr().err


def _anunnaki(*args: str, stdin: int | None = None) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "anunnaki.cli.main", *args],
        stdin=stdin,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )


class Lines:
    """The output of a process, read on a thread; wait for a line with a deadline."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.proc = proc
        self.lines: list[str] = []
        self._cond = threading.Condition()
        self._thread = threading.Thread(target=self._read, args=(proc,), daemon=True)
        self._thread.start()

    def _read(self, proc: subprocess.Popen[str]) -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            with self._cond:
                self.lines.append(line)
                self._cond.notify_all()

    def wait(self, pattern: str, timeout: float = 30.0) -> re.Match[str] | None:
        def found() -> re.Match[str] | None:
            return next((m for ln in self.lines if (m := re.search(pattern, ln))), None)

        with self._cond:
            self._cond.wait_for(lambda: found() is not None, timeout)
            return found()

    @property
    def text(self) -> str:
        with self._cond:
            return "".join(self.lines)

    def close(self) -> None:
        """Kill the process if it still runs; close its output."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self._thread.join(timeout=5.0)
        assert self.proc.stdout is not None
        self.proc.stdout.close()


@contextlib.contextmanager
def running_launch(tmp_path: Path) -> Iterator[tuple[subprocess.Popen[str], Lines, list[int]]]:
    """The looping rover example with ``--processes``, once ready: process, output, node pids."""
    proc = _anunnaki("run", str(looping_example(tmp_path)), "--processes", "--speed", "5")
    out = Lines(proc)
    try:
        assert out.wait(r"^ready: ", timeout=60), out.text
        pids = [int(m) for m in re.findall(r"node \w+: pid (\d+)", out.text)]
        assert len(pids) == 5
        yield proc, out, pids
    finally:
        out.close()


@pytest.mark.slow
def test_sigterm_stops_every_node_and_exits_0(tmp_path: Path) -> None:
    with running_launch(tmp_path) as (proc, out, pids):
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=15) == 0, out.text
        assert wait_for(lambda: all(gone(p) for p in pids), timeout=10), out.text
        assert out.wait(r"stopped \(stopped by a signal\)", timeout=5), out.text


@pytest.mark.slow
def test_the_nodes_of_a_launch_killed_with_sigkill_end_with_it(tmp_path: Path) -> None:
    # Every node watches the pipe on its stdin that only the launch holds (no orphans).
    with running_launch(tmp_path) as (proc, out, pids):
        proc.kill()
        assert proc.wait(timeout=15) == -signal.SIGKILL
        assert wait_for(lambda: all(gone(p) for p in pids), timeout=30), out.text


@pytest.mark.slow
def test_a_node_alone_answers_readiness_and_stops_on_sigterm(tmp_path: Path) -> None:
    p, endpoint = node_launch_file(tmp_path)
    proc = _anunnaki("node", "knowledge", "--config", str(p))
    out = Lines(proc)
    try:
        assert out.wait(r"node knowledge ready", timeout=30), out.text
        with open_bus("zenoh", connect=[endpoint]) as bus:
            reply = bus.request(ready_service("knowledge"), {}, timeout=10.0).to_body()
            assert reply["ready"] is True and reply["pid"] == proc.pid
            assert node_token("knowledge") in bus.alive_nodes(timeout=2.0)
            models = bus.request("/utu/knowledge/query", {"what": "state"}, timeout=5.0)
            assert models.to_body()["root"] == "G1"
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=15) == 0, out.text
        assert (tmp_path / "kb.db").exists()
    finally:
        out.close()


@pytest.mark.slow
def test_a_node_watching_its_parent_exits_0_on_sigterm_while_its_stdin_is_open(
    tmp_path: Path,
) -> None:
    # Issue 21: a launch SIGTERMs a node, then closes its stdin; a node that ended in between
    # aborted at interpreter exit (code -6) because its parent watch, a daemon thread, held
    # the lock of sys.stdin while blocked in a read.
    p, _ = node_launch_file(tmp_path)
    proc = _anunnaki(
        "node", "execute", "--config", str(p), "--exit-with-parent", stdin=subprocess.PIPE
    )
    out = Lines(proc)
    try:
        assert out.wait(r"node execute ready", timeout=30), out.text
        proc.send_signal(signal.SIGTERM)  # stdin stays open until the node has exited
        assert proc.wait(timeout=15) == 0, out.text
        assert "Fatal Python error" not in out.text, out.text
    finally:
        assert proc.stdin is not None
        proc.stdin.close()
        out.close()


def test_a_node_process_failing_at_bring_up_stops_the_launch() -> None:
    from anunnaki.launch import Children as _Children
    from anunnaki.launch import LaunchError
    from anunnaki.launch import wait_ready as _wait_ready

    out, err = io.StringIO(), io.StringIO()
    children = _Children(out, err)
    fail = "import sys; sys.stderr.write('x.yaml:3: tactics[0]: bad\\n'); sys.exit(2)"
    with open_bus("inproc") as bus:
        try:
            children.start("plan", [sys.executable, "-c", fail])
            with pytest.raises(LaunchError, match="node plan exited with code 2"):
                _wait_ready(bus, ["plan"], timeout=30, stop=threading.Event(), procs=children.procs)
            with pytest.raises(LaunchError, match=r"not ready within 0.2 s: execute"):
                _wait_ready(bus, ["execute"], timeout=0.2, stop=threading.Event())
        finally:
            children.stop(5.0)
    assert "[plan] x.yaml:3: tactics[0]: bad" in err.getvalue()


def test_docs_show_the_example_launch_file_as_it_is() -> None:
    docs = (Path(__file__).parents[2] / "docs" / "running.md").read_text(encoding="utf-8")
    blocks = re.findall(r"^```yaml\n(anunnaki: launch/1\n.*?)^```", docs, re.M | re.S)
    example = EXAMPLE.read_text(encoding="utf-8")
    assert blocks and blocks[0] == example[example.index("anunnaki: launch/1") :]
    assert load_launch(EXAMPLE).config == parse_launch(blocks[0], base=ROVER).config


def test_speed_0_means_as_fast_as_possible_as_for_anunnaki_sim() -> None:
    result, out = run(EXAMPLE, speed=0)
    assert result.exit_code == 0 and result.reason == "trace ended", out
    # The hand-over at 25 s; later tactics depend on how fast the rover's buzzer status
    # comes back at this speed (lockstep waits for Utu, not for the rover's own threads).
    assert story(result)[:5] == ROVER_STORY[:5], out
    assert "at 1e+04×" in out or "at 10000×" in out
    with pytest.raises(LaunchError, match="speed must be >= 0"):
        run(EXAMPLE, speed=-1)


@pytest.mark.slow
def test_a_node_joins_a_running_launch_as_a_client(tmp_path: Path) -> None:
    """``anunnaki node NAME --config LAUNCH --mode client``: connects where the launch listens."""
    p, endpoint = node_launch_file(tmp_path)
    with open_bus("zenoh", listen=[endpoint]) as launch_session:  # the running launch's
        proc = _anunnaki("node", "knowledge", "--config", str(p), "--mode", "client")
        out = Lines(proc)
        try:
            assert out.wait(r"node knowledge ready", timeout=30), out.text
            reply = launch_session.request(ready_service("knowledge"), {}, timeout=10.0)
            assert reply.to_body()["ready"] is True and reply.to_body()["pid"] == proc.pid
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(timeout=15) == 0, out.text
        finally:
            out.close()


@pytest.mark.slow
def test_a_killed_node_run_stops_the_platform_before_the_launch_ends(tmp_path: Path) -> None:
    # Issue #12: kill -9 of a Utu node ended the run with no run-stop at the platform.
    # The execute node is the one that would otherwise send it: the launch must.
    p = looping_example(tmp_path)
    db = tmp_path / "run.db"
    proc = _anunnaki("run", str(p), "--processes", "--speed", "5", "--knowledge", str(db))
    out = Lines(proc)
    try:
        assert out.wait(r"^ready: ", timeout=60), out.text
        pid = out.wait(r"node execute: pid (\d+)", timeout=5)
        assert pid is not None, out.text
        os.kill(int(pid.group(1)), signal.SIGKILL)
        assert proc.wait(timeout=30) == 1, out.text
        assert re.search(
            r"node execute exited with code -9: run-stop sent to /rover/stop \(ok\)", out.text
        ), out.text
    finally:
        out.close()
    with Knowledge(db) as kb:
        died = [d for d in kb.decisions() if d.kind == "node_died"]
    assert len(died) == 1 and died[0].data["ok"] is True, died
    assert died[0].data["service"] == "/rover/stop"


@pytest.mark.slow
def test_a_launch_run_stops_the_platform_when_a_node_started_by_hand_dies(
    tmp_path: Path,
) -> None:
    # Issue #12: in a mixed deployment (a launch runs analyze, plan, execute and knowledge;
    # the monitor was started by hand next to the sensors) the monitor's death left only the
    # platform's own guard. The launch watches the nodes it does not run, as survivors do.
    from anunnaki.bus._zenoh import free_port

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    text = looping_example(tmp_path).read_text()
    text = text.replace("bus: {kind: inproc}", f"bus: {{kind: zenoh, listen: ['{endpoint}']}}")
    text = text.replace("  monitor: {rate: 50}\n", "")
    p = launch_file(tmp_path, text)
    db = tmp_path / "run.db"
    # --speed 5: the loop decides within seconds, not 25 (a fail-safe: the dim light at trace
    # time 25, or the inputs still unknown when the warm-up ends if the monitor is slow to come)
    launch = Lines(_anunnaki("run", str(p), "--knowledge", str(db), "--speed", "5"))
    monitor = None
    try:
        assert launch.wait(r"^ready: ", timeout=60), launch.text
        monitor = Lines(_anunnaki("node", "monitor", "--config", str(p), "--mode", "client"))
        assert monitor.wait(r"node monitor ready", timeout=60), monitor.text
        # The loop is deciding (a fail-safe) before the monitor is killed.
        assert launch.wait(r"started\s+fail-safe", timeout=120), launch.text
        monitor.proc.kill()
        monitor.proc.wait(timeout=10)
        said = launch.wait(r"node monitor is gone .*: run-stop sent to /rover/stop \((ok)\)", 30)
        assert said is not None, launch.text
    finally:
        if monitor is not None:
            monitor.close()
        if launch.proc.poll() is None:
            launch.proc.send_signal(signal.SIGTERM)
            launch.proc.wait(timeout=30)
        launch.close()
    with Knowledge(db) as kb:
        died = [d for d in kb.decisions() if d.kind == "node_died"]
    assert len(died) == 1, died
    assert died[0].data["by"] == "execute" and died[0].data["ok"] is True
    assert "/utu_monitor" in died[0].data["problem"]


def test_a_run_closes_its_dashboard_observer_before_its_bus_with_every_decision_shown(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Issue #34, item 9: the observer ``run --dashboard`` attaches is closed when the run ends,
    while Utu still answers, so the page holds the run's last decisions and nothing of the
    dashboard asks the bus after it closed (the warning 'knowledge … does not answer (bus …
    is closed)' at the end of ``make demo``)."""
    pytest.importorskip("fastapi")
    from anunnaki.cli._dashboard import dashboard_for_launch

    launch = load_launch(EXAMPLE)
    dash = dashboard_for_launch(launch, port=0)  # not started: the page itself is not needed
    try:
        with caplog.at_level("WARNING", logger="anunnaki"):
            result = run_launch(
                launch, speed=50, out=io.StringIO(), handle_signals=False, on_bus=dash.attach
            )
        observer = dash.observer
        assert observer is not None and observer.closed
        shown = [(d["kind"], d["tactic"]) for d in dash.state.snapshot()["decisions"]]
        assert shown == story(result) == ROVER_STORY
        assert not [r for r in caplog.records if "does not answer" in r.getMessage()]
    finally:
        dash.close()
