"""Helpers of the live ROS 2 tests: rclpy processes in a loopback-only network namespace.

Every ROS 2 process of the tests runs in ONE network namespace that has only loopback, so no
DDS packet leaves the machine: :class:`Netns` starts a holder (``unshare -rn``, then ``ip
link set lo up``) and each process joins it (``nsenter``). The processes are the ROS 2
environment's Python (``.venv-ros2``, scripts/setup-ros2.sh; ``$ANUNNAKI_ROS2_PYTHON``
overrides): the bridge (``python -m anunnaki.ros2``) and plain rclpy nodes. This test process
never imports rclpy; it reaches the bridge's bus through a unix socket (the file system is
shared across network namespaces; TCP on the namespace's loopback is not).

The tests skip only when the ROS 2 environment or user namespaces are missing, saying why;
with ``ANUNNAKI_REQUIRE_ROS2=1`` (CI) that is a failure instead.
"""

from __future__ import annotations

import functools
import os
import random
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "ros1"))
from ros1_support import DEADLINE, Proc

ROOT = Path(__file__).parents[2]
REQUIRE_ROS2 = "ANUNNAKI_REQUIRE_ROS2"
ROS2_PYTHON = Path(os.environ.get("ANUNNAKI_ROS2_PYTHON", ROOT / ".venv-ros2" / "bin" / "python"))

__all__ = ["DEADLINE", "REQUIRE_ROS2", "ROOT", "ROS2_PYTHON", "Netns", "Proc", "need_ros2"]


@functools.cache
def ros2_missing() -> str | None:
    """Why the live ROS 2 tests cannot run here (``None``: they can)."""
    if not ROS2_PYTHON.exists():
        return f"no ROS 2 environment at {ROS2_PYTHON} (scripts/setup-ros2.sh builds it, no root)"
    for tool in ("unshare", "nsenter", "ip"):
        if shutil.which(tool) is None:
            return f"{tool} is missing (util-linux / iproute2): ROS 2 runs in a loopback-only netns"
    probe = subprocess.run(
        ["unshare", "-rn", "sh", "-c", "ip link set lo up"],
        capture_output=True,
        text=True,
        check=False,
    )
    if probe.returncode != 0:
        return f"no user network namespace here (unshare -rn: {probe.stderr.strip()})"
    probe = subprocess.run(
        [str(ROS2_PYTHON), "-c", "import rclpy, anunnaki.ros2._native"],
        capture_output=True,
        text=True,
        check=False,
    )
    if probe.returncode != 0:
        last = (probe.stderr.strip().splitlines() or ["?"])[-1]
        return f"rclpy or anunnaki cannot be imported in {ROS2_PYTHON}: {last}"
    return None


def need_ros2() -> None:
    """Skip (or, with ANUNNAKI_REQUIRE_ROS2=1, fail) when the ROS 2 environment is not here."""
    missing = ros2_missing()
    if missing is None:
        return
    if os.environ.get(REQUIRE_ROS2) == "1":
        pytest.fail(f"{REQUIRE_ROS2}=1 requires the live ROS 2 tests. {missing}", pytrace=False)
    pytest.skip(f"{missing} (with {REQUIRE_ROS2}=1 this is a failure)")


class Netns:
    """A loopback-only network namespace, and ROS 2 processes started in it."""

    def __init__(self, home: Path) -> None:
        home.mkdir(parents=True, exist_ok=True)
        self.home = home
        self.holder = subprocess.Popen(
            ["unshare", "-rn", "sh", "-c", "ip link set lo up && echo up && exec cat"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.holder.stdout is not None
        assert self.holder.stdout.readline().strip() == "up", "the network namespace did not start"
        self.env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        self.env.update(
            PYTHONUNBUFFERED="1",
            ROS_HOME=str(home),
            ROS_LOG_DIR=str(home / "log"),
            # a domain of its own: Fast DDS's shared-memory ports (/dev/shm, not isolated by
            # the network namespace) then differ from another test worker's
            ROS_DOMAIN_ID=str(random.randint(1, 100)),
            ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        )
        self.env.pop("ROS_DISTRO", None)
        self.procs: list[Proc] = []
        self._socket = 0

    def socket(self) -> str:
        """A fresh zenoh unix-socket endpoint (reachable from both sides of the namespace)."""
        self._socket += 1
        return f"unixsock-stream/{self.home / f'bus{self._socket}.sock'}"

    def start(self, args: list[str], name: str, *, ready: str | None = None) -> Proc:
        """Start ``args`` inside the namespace (and wait for the line ``ready``)."""
        enter = ["nsenter", "-t", str(self.holder.pid), "-U", "-n", "--preserve-credentials"]
        proc = Proc([*enter, *args], self.env, name)
        self.procs.append(proc)
        if ready is not None:
            proc.wait_for(ready)
        return proc

    def python(self, *args: str, name: str, ready: str | None = None) -> Proc:
        """Run the ROS 2 environment's Python with ``args`` inside the namespace."""
        return self.start([str(ROS2_PYTHON), *args], name, ready=ready)

    def bridge(self, bridge: Path, endpoint: str, *extra: str) -> Proc:
        """``python -m anunnaki.ros2 BRIDGE --connect ENDPOINT`` (ready once it says so)."""
        args = ["-m", "anunnaki.ros2", str(bridge), "--connect", endpoint, *extra]
        return self.python(*args, name="bridge", ready="ros2 bridge ready")

    def close(self) -> None:
        for proc in reversed(self.procs):
            proc.stop()
        self.procs.clear()
        if self.holder.stdin is not None:
            self.holder.stdin.close()  # cat ends, and the namespace with it
        try:
            self.holder.wait(timeout=DEADLINE)
        except subprocess.TimeoutExpired:
            self.holder.kill()
            self.holder.wait()
        if self.holder.stdout is not None:
            self.holder.stdout.close()


def wait_until(check: object, what: str, timeout: float = DEADLINE) -> None:
    """Poll ``check()`` until true (a deadline against a hung test, never a measurement)."""
    end = time.monotonic() + timeout
    while not check():  # type: ignore[operator]
        assert time.monotonic() < end, f"{what} did not happen within {timeout:g} s"
        time.sleep(0.05)
