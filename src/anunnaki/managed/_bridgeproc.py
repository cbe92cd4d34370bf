"""A bridge process a robot kind starts (``ros1``; ``ros2`` with ``flavour: rclpy``).

:func:`start_bridge` starts ``python -m anunnaki.ros1|ros2 BRIDGE --connect EP
--exit-with-parent`` (it stops once the launch is gone, even after a ``kill -9``: the pipe on
its standard input closes), says its status lines through the launch (``ros1: ros1 bridge
ready ...``), waits until it is ready and returns it as the kind's :class:`BridgeProcess`
link: the robot is reachable while the process runs.
"""

from __future__ import annotations

import subprocess
import threading
from collections.abc import Callable

from anunnaki.errors import AnunnakiError

__all__ = ["BridgeProcess", "start_bridge"]

_NAMES = {"ros1": "ROS 1", "ros2": "ROS 2"}


class BridgeProcess:
    """The started bridge process: the robot is reachable while it runs."""

    gone = "the bridge process exited"

    def __init__(self, proc: subprocess.Popen[str], reader: threading.Thread) -> None:
        self.proc = proc
        self.reader = reader  # says its output lines; ends at the end of its output

    def alive(self) -> bool:
        return self.proc.poll() is None

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        # Its last lines ("ros1 bridge stopped: ...") are said before the pipe closes: the
        # reader, late under load, read from a closed file and lost them.
        self.reader.join(timeout=10)
        for stream in (self.proc.stdin, self.proc.stdout):
            if stream is not None:
                stream.close()


def start_bridge(
    args: list[str],
    env: dict[str, str],
    label: str,
    ready_timeout: float,
    say: Callable[[str], None],
) -> BridgeProcess:
    """Start a bridge process and wait until it prints ``<label> bridge ready``.

    Raises:
        AnunnakiError: It exited, or was not ready within ``ready_timeout`` seconds (its
            last lines say why).

    """
    proc = subprocess.Popen(
        [*args, "--exit-with-parent"],  # it stops once this process is gone (any way)
        env=env,
        stdin=subprocess.PIPE,  # its other end: only here; it closes when we end
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        bufsize=1,
    )
    ready = threading.Event()
    lines: list[str] = []
    marker = f"{label} bridge ready"

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            text = line.rstrip("\n")
            lines.append(text)
            if marker in text:
                ready.set()
            if text.startswith((f"{label} bridge", "error", "WARNING", "ERROR")):
                say(f"{label}: {text}")
        ready.set()  # the process ended: stop waiting

    reader = threading.Thread(target=read, name=f"anunnaki-{label}-out", daemon=True)
    reader.start()
    ready.wait(ready_timeout)
    if proc.poll() is not None or not any(marker in x for x in lines):
        proc.kill()
        proc.wait()
        reader.join(timeout=10)
        raise AnunnakiError(
            f"the {_NAMES.get(label, label)} bridge did not start: "
            + (" | ".join(lines[-5:]) or "no output")
        )
    return BridgeProcess(proc, reader)
