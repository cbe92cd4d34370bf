"""The managed-system kind ``ros1``: checked at bring-up, refuses a bus the bridge can't join."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from ros1_support import DEADLINE, Proc, RosSetup, free_port, need_ros, running

from anunnaki.bus import open_bus
from anunnaki.errors import ModelFileError
from anunnaki.managed import MANAGED, ManagedContext
from anunnaki.utu import parse_config

ROVER = Path(__file__).parents[2] / "examples" / "rover"
UTU = parse_config(f"anunnaki: utu/1\ngoal_model: {ROVER}/goals.yaml\nclock: sim\n")


def kind(**options: object):  # type: ignore[no-untyped-def]
    cls = MANAGED.factory("ros1")
    return cls(cls.Options.model_validate(options), base=ROVER)  # type: ignore[attr-defined]


def context(bus: Any, say: Callable[[str], None]) -> ManagedContext:
    """What a launch gives a managed system it starts (no executor: a live robot)."""
    return ManagedContext(
        bus=bus,
        stop=threading.Event(),
        speed=1.0,
        until=None,
        say=say,
    )


def test_the_kind_is_registered_and_checks_its_files_at_bring_up(tmp_path: Path) -> None:
    good = kind(bridge="ros1/bridge.yaml", models="../models/rover.yaml", oracle={"name": "light"})
    good.check(UTU)
    notes = good.notes(UTU, 2.0)
    assert any("clock: sim" in n for n in notes) and any("speed 2" in n for n in notes)
    bad = tmp_path / "bridge.yaml"
    bad.write_text(
        "anunnaki: ros1-bridge/1\ntopics:\n  - {ros: /a, type: x/Y, direction: to_bus}\n"
    )
    with pytest.raises(ModelFileError, match=r"bridge.yaml:3: topics\[/a\].type: unknown ROS"):
        kind(bridge=str(bad)).check(UTU)
    with pytest.raises(ModelFileError, match="unknown oracle 'crystal_ball'"):
        kind(bridge="ros1/bridge.yaml", oracle={"name": "crystal_ball"}).check(UTU)


def test_an_in_process_bus_is_refused_with_the_fix() -> None:
    with open_bus("inproc") as bus:
        ctx = context(bus, print)
        with pytest.raises(ModelFileError, match=r"needs the zenoh bus.*bus: \{kind: zenoh\}"):
            kind(bridge="ros1/bridge.yaml").start(ctx)


def test_the_bridge_says_when_no_master_answers() -> None:
    need_ros()
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["ROS_MASTER_URI"] = f"http://127.0.0.1:{free_port()}"  # nobody listens there
    args = [sys.executable, "-m", "anunnaki.ros1", str(ROVER / "ros1" / "bridge.yaml")]
    done = subprocess.run(
        [*args, "--wait-master", "0.5"], env=env, capture_output=True, text=True, check=False
    )
    assert done.returncode == 2
    assert "waiting for the ROS master at" in done.stdout
    assert "no ROS master answers at" in done.stderr and "start roscore" in done.stderr


PARENT = """
import sys, threading
from pathlib import Path
from anunnaki.bus import open_bus
from anunnaki.managed import MANAGED, ManagedContext

cls = MANAGED.factory("ros1")
kind = cls(cls.Options.model_validate({"bridge": "ros1/bridge.yaml"}), base=Path(sys.argv[1]))
with open_bus("zenoh") as bus:
    ctx = ManagedContext(bus=bus, stop=threading.Event(), speed=1.0, until=None, say=print)
    link = kind.connect(ctx)
    # one write: a print is two (text, then newline), and the context's own say=print lines,
    # from the bridge's threads, could land between them
    sys.stdout.write(f"bridge pid {link.proc.pid}\\n")
    sys.stdout.flush()
    threading.Event().wait()
"""


@pytest.mark.slow
def test_the_bridge_process_ends_with_the_launch_that_started_it(ros: RosSetup) -> None:
    # Issue 21: a launch killed under load (kill -9 after a test's deadline) left its bridge
    # running. The bridge watches the pipe on its stdin that only the launch holds.
    parent = Proc([sys.executable, "-c", PARENT, str(ROVER)], ros.env, "launch")
    ros.procs.append(parent)
    line = parent.wait_for("bridge pid ")
    found = re.search(r"bridge pid (\d+)", line)
    assert found, line
    bridge = int(found.group(1))
    assert running(bridge)
    os.kill(parent.p.pid, signal.SIGKILL)
    assert parent.p.wait(timeout=DEADLINE) == -signal.SIGKILL
    end, pause = time.monotonic() + DEADLINE, threading.Event()
    while running(bridge):  # polling a process state, with a deadline (no message to wait on)
        assert time.monotonic() < end, f"the bridge (pid {bridge}) outlived its launch"
        pause.wait(0.05)


@pytest.mark.slow
def test_the_bridges_last_words_are_said_before_its_pipe_closes(
    ros: RosSetup, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Issue 21: under load the launch's reader of the bridge's output came late; closing the
    # bridge closed the pipe under it and "ros1 bridge stopped" was lost (the example test
    # waits for that line). The reader is held up here until the bridge has exited.
    said: list[str] = []
    release = threading.Event()

    def say(line: str) -> None:
        if "ros1 bridge ready" in line:
            release.wait(DEADLINE)  # the reader stalls, as a starved thread would
        said.append(line)

    for name in ("ROS_MASTER_URI", "ROS_IP", "ROS_HOME"):
        monkeypatch.setenv(name, ros.env[name])
    with open_bus("zenoh") as bus:
        ctx = context(bus, say)
        link = kind(bridge="ros1/bridge.yaml").connect(ctx)
        closing = threading.Thread(target=link.close)
        closing.start()
        end, pause = time.monotonic() + DEADLINE, threading.Event()
        while link.proc.poll() is None:  # the bridge exits while its reader is held up
            assert time.monotonic() < end, "the bridge did not stop"
            pause.wait(0.05)
        closing.join(1.0)  # let close go as far as it goes without the reader (not a sync)
        release.set()
        closing.join(DEADLINE)
        assert not closing.is_alive()
    assert any(line.startswith("ros1: ros1 bridge stopped") for line in said), said
