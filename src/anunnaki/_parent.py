"""A child process that ends with its parent: it watches the pipe on its standard input.

A process started by a launch (a Utu node, the ROS 1 bridge) gets a pipe as standard input
whose other end only the parent holds; the pipe reads end-of-file once the parent is gone,
however it ended (``kill -9`` included), and the child then stops as on SIGTERM.

The watch reads the file descriptor itself (``os.read``), never ``sys.stdin``: a daemon
thread blocked in ``sys.stdin.buffer.read`` holds the buffer's lock, and an interpreter that
exits meanwhile aborts (``Fatal Python error: _enter_buffered_busy``, exit code -6).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable

__all__ = ["stop_with_parent"]


def stop_with_parent(stop: Callable[[], object], *, fd: int = 0) -> threading.Thread:
    """Call ``stop()`` once ``fd`` (standard input) reads end-of-file or fails.

    The parent must start the process with a pipe on ``fd`` and keep its write end open
    (``subprocess.Popen(..., stdin=subprocess.PIPE)``). Returns the watching daemon thread.
    """

    def watch() -> None:
        try:
            while os.read(fd, 4096):
                pass
        except OSError:
            pass
        stop()

    thread = threading.Thread(target=watch, name="anunnaki-parent-watch", daemon=True)
    thread.start()
    return thread
