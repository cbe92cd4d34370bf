"""Helpers of the ROS 1 tests: a real master, the example rover and the bridge, as processes.

``rosmaster --core`` runs on a free loopback port with a temporary ``ROS_HOME``; the rover
(``examples/rover/ros1/rover_robot.py``) runs under Debian's python3 as a plain rospy node;
the bridge runs as ``python -m anunnaki.ros1`` from this virtual environment (it appends
Debian's ROS folder to its own ``sys.path``; this test process never imports rospy). The
tests skip only when rospy or rosmaster is missing, saying why; with
``ANUNNAKI_REQUIRE_ROS=1`` (CI) that is a failure instead.
"""

from __future__ import annotations

import functools
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
import xmlrpc.client
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[2]
ROVER = ROOT / "examples" / "rover"
REQUIRE_ROS = "ANUNNAKI_REQUIRE_ROS"
#: A deadline against a hung test on a loaded machine, never a measurement.
DEADLINE = 60.0


@functools.cache
def ros_missing() -> str | None:
    """Why the ROS 1 tests cannot run here (``None``: they can)."""
    if shutil.which("rosmaster") is None:
        return "rosmaster is not installed (scripts/setup-ros.sh installs python3-rosmaster)"
    if not Path("/usr/bin/python3").exists():
        return "Debian's /usr/bin/python3 (which runs the example rover) is missing"
    probe = subprocess.run(
        [sys.executable, "-c", "from anunnaki.ros1 import import_rospy; import_rospy()"],
        capture_output=True,
        text=True,
        check=False,
    )
    if probe.returncode != 0:
        return "rospy cannot be imported: " + (probe.stderr.strip().splitlines() or ["?"])[-1]
    return None


def need_ros() -> None:
    """Skip (or, with ANUNNAKI_REQUIRE_ROS=1, fail) when ROS 1 is not here."""
    missing = ros_missing()
    if missing is None:
        return
    if os.environ.get(REQUIRE_ROS) == "1":
        pytest.fail(f"{REQUIRE_ROS}=1 requires the ROS 1 tests. {missing}", pytrace=False)
    pytest.skip(f"{missing} (with {REQUIRE_ROS}=1 this is a failure)")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def running(pid: int) -> bool:
    """Whether process ``pid`` still runs (a zombie, ended but not yet reaped, does not)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
    state = next(ln for ln in status.splitlines() if ln.startswith("State:"))
    return state.split()[1] not in ("Z", "X")


class Proc:
    """A child process whose output lines are kept and can be waited for."""

    def __init__(self, args: list[str], env: dict[str, str], name: str) -> None:
        self.name = name
        self.lines: list[str] = []
        self._changed = threading.Condition()
        self.p = subprocess.Popen(
            args,
            env=env,
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            bufsize=1,
        )
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.p.stdout is not None
        for line in self.p.stdout:
            with self._changed:
                self.lines.append(line.rstrip("\n"))
                self._changed.notify_all()
        with self._changed:
            self._changed.notify_all()

    def printed(self, text: str) -> bool:
        """Whether an output line so far contains ``text`` (does not wait)."""
        with self._changed:
            return any(text in line for line in self.lines)

    def wait_for(self, text: str, timeout: float = DEADLINE) -> str:
        """The first output line containing ``text`` (fails the test after ``timeout``)."""
        end = time.monotonic() + timeout
        with self._changed:
            while True:
                for line in self.lines:
                    if text in line:
                        return line
                left = end - time.monotonic()
                if left <= 0 or (self.p.poll() is not None and not self._reader.is_alive()):
                    break
                self._changed.wait(min(left, 1.0))
        out = "\n".join(self.lines[-30:])
        raise AssertionError(f"{self.name} never printed {text!r}; its output:\n{out}")

    def stop(self) -> None:
        if self.p.poll() is None:
            self.p.terminate()
            try:
                self.p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.p.kill()
                self.p.wait()
        self._reader.join(timeout=10)
        if self.p.stdout is not None:
            self.p.stdout.close()


class RosSetup:
    """A master on a free port, and helpers to start the rover and the bridge against it."""

    def __init__(self, home: Path) -> None:
        self.port = free_port()
        self.uri = f"http://127.0.0.1:{self.port}"
        self.env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        self.env.update(
            ROS_MASTER_URI=self.uri, ROS_IP="127.0.0.1", ROS_HOME=str(home), PYTHONUNBUFFERED="1"
        )
        self.procs: list[Proc] = []
        self.master: Proc | None = None
        self.start_master()

    def start_master(self) -> None:
        self.master = self._start(["rosmaster", "--core", "-p", str(self.port)], "rosmaster")
        end = time.monotonic() + DEADLINE
        while self.master_pid() is None:
            assert time.monotonic() < end, "the ROS master did not answer"
            assert self.master.p.poll() is None, "\n".join(self.master.lines)
            time.sleep(0.05)  # polling the master's port until it answers: not a sync sleep

    def stop_master(self) -> None:
        assert self.master is not None
        self.master.stop()

    def master_pid(self) -> int | None:
        try:
            with xmlrpc.client.ServerProxy(self.uri) as master:
                code, _, pid = master.getPid("/test")
        except OSError:
            return None
        return int(pid) if code == 1 else None

    def system_state(self) -> list[list[tuple[str, list[str]]]]:
        with xmlrpc.client.ServerProxy(self.uri) as master:
            code, _, state = master.getSystemState("/test")
        assert code == 1
        return [[(t, list(n)) for t, n in part] for part in state]

    def _start(self, args: list[str], name: str) -> Proc:
        proc = Proc(args, self.env, name)
        self.procs.append(proc)
        return proc

    def rover(self, *args: str) -> Proc:
        script = str(ROVER / "ros1" / "rover_robot.py")
        proc = self._start(["/usr/bin/python3", script, *args], "rover")
        proc.wait_for("rover ready")
        return proc

    def bridge(self, bridge: Path = ROVER / "ros1" / "bridge.yaml") -> tuple[Proc, str]:
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        args = [sys.executable, "-m", "anunnaki.ros1", str(bridge), "--listen", endpoint]
        proc = self._start([*args, "--watch-every", "0.2"], "bridge")
        proc.wait_for("ros1 bridge ready")
        return proc, endpoint

    def close(self) -> None:
        for proc in reversed(self.procs):
            proc.stop()
