"""Helpers of the failure and restart tests: child processes, the scripted rover, the log.

* :class:`Child` runs a script of ``tests/data/utu`` in a fresh interpreter, its output in a
  log file; leaving the ``with`` block always kills it (SIGKILL) and reaps it.
* :class:`Rover` is the scripted managed system, with a ``/rover/set_mode`` that can be told
  to hold the request (a command in flight) or to acknowledge without switching.
* :func:`read_decisions` / :func:`read_tactics` read a knowledge file *read-only* while
  another process writes it; :func:`wait_until` polls a condition with a deadline.

Imported by the test modules of this folder (pytest puts the folder on ``sys.path``).
"""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from contextlib import closing
from pathlib import Path
from types import TracebackType
from typing import IO, Any, Self, TypeVar

from anunnaki.managed import ScriptedSystem
from anunnaki.trace import Record
from anunnaki.utu import Decision
from anunnaki.utu.cycle import TacticRow

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data" / "utu"
ROVER = ROOT / "examples" / "rover"

T = TypeVar("T")


def wait_until(
    predicate: Callable[[], T | None],
    timeout: float,
    what: str,
    *,
    explain: Callable[[], str] | None = None,
) -> T:
    """Poll ``predicate`` until it returns something truthy, and return that.

    Raises:
        AssertionError: Nothing truthy within ``timeout`` seconds; says ``what`` was awaited
            (and ``explain()``, e.g. a child's log).

    """
    deadline = time.monotonic() + timeout
    pause = threading.Event()
    while True:
        value = predicate()
        if value:
            return value
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            detail = f"\n{explain()}" if explain is not None else ""
            raise AssertionError(f"timed out after {timeout} s waiting for {what}{detail}")
        pause.wait(min(0.02, remaining))


# --- the knowledge file, read-only ----------------------------------------------------------


def _rows(db: Path, sql: str) -> list[tuple[Any, ...]]:
    """Rows of ``sql`` on ``db`` opened read-only; none while the file or schema is missing."""
    if not db.exists():
        return []
    try:
        conn = sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=5.0)
    except sqlite3.OperationalError:
        return []
    with closing(conn):
        try:
            return conn.execute(sql).fetchall()
        except sqlite3.OperationalError as exc:  # created, but the schema is not there yet
            if "no such table" in str(exc):
                return []
            raise


def read_decisions(db: Path) -> list[Decision]:
    """Every decision in ``db`` (empty until the file exists), oldest first."""
    rows = _rows(db, "SELECT id, t, kind, tactic, data FROM decisions ORDER BY id")
    return [Decision(i, t, kind, tactic, json.loads(data)) for i, t, kind, tactic, data in rows]


def read_tactics(db: Path) -> dict[str, TacticRow]:
    """The persisted state of every tactic in ``db``."""
    rows = _rows(
        db,
        "SELECT name, state, started, deadline, next_action, cooldown_until, attempt, reason "
        "FROM tactics",
    )
    return {r[0]: TacticRow(*r) for r in rows}


def of(decisions: list[Decision], kind: str, tactic: str | None = "fail-safe") -> list[Decision]:
    """The decisions of one kind (about one tactic)."""
    return [d for d in decisions if d.kind == kind and d.tactic == tactic]


def find(db: Path, kind: str, tactic: str | None = "fail-safe", after: int = 0) -> Decision | None:
    """The first decision of ``kind`` (about ``tactic``) with an id above ``after``."""
    return next((d for d in of(read_decisions(db), kind, tactic) if d.id > after), None)


# --- child processes ------------------------------------------------------------------------


class Child:
    """A script of ``tests/data/utu`` in a child interpreter; killed on leaving ``with``.

    Args:
        script: File name in ``tests/data/utu``.
        args: Its command-line arguments.
        log: Where its stdout and stderr go.

    """

    def __init__(self, script: str, *args: str, log: Path) -> None:
        self.argv = [sys.executable, str(DATA / script), *args]
        self.log = log
        self._out: IO[str] | None = None
        self.proc: subprocess.Popen[str] | None = None

    def __enter__(self) -> Self:
        self._out = self.log.open("a", encoding="utf-8")
        self._out.write(f"$ {' '.join(self.argv)}\n")
        self._out.flush()
        try:
            self.proc = subprocess.Popen(
                self.argv,
                stdout=self._out,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                text=True,
                cwd=ROOT,
                env={**os.environ, "PYTHONUNBUFFERED": "1"},
            )
        except BaseException:
            self._out.close()
            raise
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        try:
            self.kill()
        finally:
            if self._out is not None:
                self._out.close()

    @property
    def pid(self) -> int:
        assert self.proc is not None
        return self.proc.pid

    def alive(self) -> bool:
        """Whether the process still runs."""
        return self.proc is not None and self.proc.poll() is None

    def kill(self) -> None:
        """``kill -9`` the process (if it still runs) and reap it."""
        if self.proc is None:
            return
        if self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGKILL)
        self.proc.wait(timeout=30)

    def output(self) -> str:
        """What the process printed so far (for failure messages)."""
        return self.log.read_text(encoding="utf-8", errors="replace")[-6000:]

    def ready(self) -> bool:
        """Whether it printed ``ready``; raises if it died before."""
        if "ready" in self.log.read_text(encoding="utf-8", errors="replace").splitlines():
            return True
        if not self.alive():
            raise AssertionError(f"{self.argv[1]} exited early:\n{self.output()}")
        return False


def manager_process(
    db: Path, endpoint: str, log: Path, *, dwell: float | None = None, config: str = ""
) -> Child:
    """A Utu manager (``run_manager.py``) on ``db``, joining the bus at ``endpoint``."""
    args = [str(DATA / (config or "utu-rover.yaml")), "--connect", endpoint]
    args += ["--knowledge", str(db)]
    if dwell is not None:
        args += ["--dwell", str(dwell)]
    return Child("run_manager.py", *args, log=log)


# --- the scripted rover -----------------------------------------------------------------------


class Rover(ScriptedSystem):
    """The scripted rover, with a ``/rover/set_mode`` the test controls.

    Args:
        obey: Switch mode on a request (else acknowledge it and stay as it is).
        hold: Keep each request in the handler until :attr:`release` is set (a command in
            flight); :attr:`entered` is set when one arrives.

    Attributes:
        received: Every ``set_mode`` request body, in arrival order.

    """

    def __init__(self, bus: Any, trace: list[Record], *, obey: bool = True, hold: bool = False):
        self.obey = obey
        self.hold = hold
        self.entered = threading.Event()
        self.release = threading.Event()
        self.received: list[dict[str, Any]] = []
        self._received_lock = threading.Lock()
        super().__init__(bus, trace)

    def _set_mode(self, message: Any) -> dict[str, Any]:
        body = _body(message)
        with self._received_lock:
            self.received.append(body)
        self.entered.set()
        if self.hold and not self.release.wait(60):
            return {"ok": False, "error": "never released"}
        if not self.obey:
            return {"ok": True, "mode": self.state().get("mode", "autonomous")}
        return super()._set_mode(message)

    def mode_requests(self, mode: str = "manual") -> int:
        """How many ``set_mode`` requests for ``mode`` arrived."""
        with self._received_lock:
            return sum(1 for b in self.received if b.get("mode") == mode)


def _body(message: Any) -> dict[str, Any]:
    to_body = getattr(message, "to_body", None)
    body = to_body() if callable(to_body) else message
    return dict(body) if isinstance(body, dict) else {}


def rover_trace(
    duration: float, *, rate: int = 20, oracle: int | None = None, oracle_until: float = 1e9
) -> list[Record]:
    """A rover trace: status, camera and ultrasonic at ``rate`` Hz, all nominal.

    Args:
        duration: Seconds of trace.
        rate: Messages per second on each topic (the rover's rate goal needs 5 Hz).
        oracle: The behavior category the oracle reports at the same rate (``None``: no
            oracle messages; another node publishes them).
        oracle_until: The last instant the oracle speaks.

    """
    out: list[Record] = []
    for i in range(round(duration * rate) + 1):
        t = i / rate
        out += [
            Record(t, "/rover/status", {"mode": "autonomous", "buzzer": False, "bumper": False}),
            Record(t, "/rover/camera/info", {"seq": i, "width": 128, "height": 128}),
            Record(t, "/rover/ultrasonic", {"range": 3.0}),
        ]
        if oracle is not None and t <= oracle_until:
            out.append(Record(t, "/utu/oracle/output", {"category": oracle, "confidence": 0.9}))
    return out


class LiveRover:
    """Runs a :class:`Rover` live (its trace at wall-clock speed) on a thread; ``with`` block."""

    def __init__(self, rover: Rover) -> None:
        self.rover = rover
        self._stop = threading.Event()
        self._thread = threading.Thread(
            target=rover.run, args=(self._stop,), name="scripted-rover", daemon=True
        )

    def __enter__(self) -> Rover:
        self._thread.start()
        return self.rover

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self.rover.release.set()  # a held set_mode request must not block closing
        self._thread.join(timeout=30)
        self.rover.close()
