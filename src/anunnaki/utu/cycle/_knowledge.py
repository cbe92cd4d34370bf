"""Knowledge: the single source of truth of a Utu run (guideline N8), in SQLite.

One database file per run holds

* ``meta`` — the goal model, binding and tactics *texts* in force (and each reload), the
  configuration, the run's start;
* ``inputs`` — every input the manager took, in order: messages (topic, payload; never
  images, guideline P1), the instants at which the passing of time alone changed
  something (``__tick__``), and operator calls (``__operator__``) — enough to recompute
  rates, staleness and temporal operators, which is what ``anunnaki replay`` does;
* ``verdicts`` — every change of a goal's or obstacle's utility or status;
* ``decisions`` — every step of every tactic (selected, queued, pending approval,
  started, each action and its result, postcondition verified or failed, escalation),
  every skipped selection and why, every operator call with its caller;
* ``tactics`` — the live state of each tactic (in flight since, deadline, next action,
  cooldown until), written *before* the action it enables, so a manager killed with -9
  and restarted resumes: an in-flight tactic keeps its deadline and is not run twice, and
  cooldowns survive.

The database runs in WAL mode with ``synchronous=NORMAL``: a committed transaction survives
the process being killed (the promise here), though not necessarily a power cut. Writes are
buffered and committed together, in one transaction, by :meth:`Knowledge.flush`: the
Executor flushes before every action it dispatches (write-ahead: the tactic's state and the
decisions that led to it are on disk before the managed system is touched), the manager at
the end of every step that decided something, and any read flushes first. Inputs and
verdicts are also flushed every ``batch`` rows.

**One time base.** A run's times are Utu's clock: the simulation's seconds from its start
(``clock: sim``), or seconds since the epoch (``clock: wall``). Whatever shows a log to
people (``anunnaki run``'s lines, ``log``, ``explain``, ``replay``) shows it on one base,
:meth:`Knowledge.time_origin` subtracted from every instant (a decision's ``t`` and its
``deadline`` alike, :meth:`Decision.shifted`), and reads the times it is given on that base.
"""

from __future__ import annotations

import json
import sqlite3
import threading
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from anunnaki._closing import Closing

__all__ = ["Decision", "InputRow", "Knowledge", "TacticRow", "VerdictRow"]

SCHEMA_VERSION = 1

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS models (
    id INTEGER PRIMARY KEY, t REAL NOT NULL, kind TEXT NOT NULL, path TEXT, text TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS inputs (
    id INTEGER PRIMARY KEY, t REAL NOT NULL, topic TEXT NOT NULL, msg TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS verdicts (
    id INTEGER PRIMARY KEY, t REAL NOT NULL, node TEXT NOT NULL, utility REAL, status TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS decisions (
    id INTEGER PRIMARY KEY, t REAL NOT NULL, kind TEXT NOT NULL, tactic TEXT,
    data TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS tactics (
    name TEXT PRIMARY KEY, state TEXT NOT NULL, started REAL, deadline REAL,
    next_action INTEGER NOT NULL DEFAULT 0, cooldown_until REAL, attempt INTEGER NOT NULL
    DEFAULT 0, reason TEXT
);
CREATE INDEX IF NOT EXISTS inputs_t ON inputs (t);
CREATE INDEX IF NOT EXISTS verdicts_t ON verdicts (t);
CREATE INDEX IF NOT EXISTS decisions_t ON decisions (t);
"""


@dataclass(frozen=True)
class InputRow:
    """One recorded input."""

    id: int
    t: float
    topic: str
    msg: dict[str, Any]


@dataclass(frozen=True)
class VerdictRow:
    """One recorded verdict change."""

    id: int
    t: float
    node: str
    utility: float | None
    status: str


#: A recorded instant past this (2001-09-09) is seconds since the epoch: a wall-clock run.
EPOCH_AFTER = 1e9

#: Fields of a decision's data that hold an instant (shown on the log's base, like ``t``).
TIME_FIELDS = frozenset({"deadline"})


@dataclass(frozen=True)
class Decision:
    """One recorded decision."""

    id: int
    t: float
    kind: str
    tactic: str | None
    data: dict[str, Any]

    def shifted(self, origin: float) -> Decision:
        """A copy with ``origin`` subtracted from its time and from its time fields."""
        if not origin:
            return self
        data = {
            k: v - origin
            if k in TIME_FIELDS and isinstance(v, int | float) and not isinstance(v, bool)
            else v
            for k, v in self.data.items()
        }
        return Decision(self.id, self.t - origin, self.kind, self.tactic, data)


@dataclass(frozen=True)
class TacticRow:
    """The persisted state of one tactic."""

    name: str
    state: str  # idle | pending | running | awaiting | (done states are idle)
    started: float | None
    deadline: float | None
    next_action: int
    cooldown_until: float | None
    attempt: int
    reason: str | None


_encode = json.JSONEncoder(separators=(",", ":"), ensure_ascii=False).encode


def _dumps(obj: Any) -> str:
    try:
        return _encode(obj)
    except (TypeError, ValueError):  # an odd value: keep the record, stringified
        return json.dumps(obj, separators=(",", ":"), default=str)


class Knowledge(Closing):
    """The SQLite knowledge base of one run.

    Args:
        path: The database file (created if missing), or ``":memory:"``.
        batch: Flush buffered inputs and verdicts after this many rows.

    Thread-safe: one connection guarded by a lock (writes from the MAPE loop, reads from
    service threads such as knowledge queries and the dashboard).

    """

    def __init__(self, path: str | Path = ":memory:", *, batch: int = 256) -> None:
        self.path = str(path)
        self._lock = threading.RLock()
        self._db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=NORMAL")
        self._db.execute("PRAGMA busy_timeout=5000")
        self._db.executescript(_SCHEMA)
        self._batch = batch
        self.decisions_written = 0
        self._inputs: list[tuple[float, str, str]] = []
        self._verdicts: list[tuple[float, str, float | None, str]] = []
        self._decisions: list[tuple[float, str, str | None, str]] = []
        self._tactics: dict[str, TacticRow] = {}
        self._db.execute(
            "INSERT OR IGNORE INTO meta (key, value) VALUES ('schema', ?)", (str(SCHEMA_VERSION),)
        )
        self._checkpointer: _Checkpointer | None = None
        if self.path != ":memory:" and not self.path.startswith("file::memory:"):
            # A checkpoint syncs the file (milliseconds on a VM disk): never on the loop's
            # commits. A background connection copies the WAL into the database instead.
            self._db.execute("PRAGMA wal_autocheckpoint=0")
            self._checkpointer = _Checkpointer(self.path)

    # -- writing ------------------------------------------------------------------------
    def set_meta(self, key: str, value: Any) -> None:
        """Store a metadata value (JSON)."""
        with self._lock:
            self._db.execute(
                "INSERT INTO meta (key, value) VALUES (?, ?) "
                "ON CONFLICT(key) DO UPDATE SET value=excluded.value",
                (key, _dumps(value)),
            )

    def meta(self, key: str, default: Any = None) -> Any:
        """Read a metadata value."""
        with self._lock:
            row = self._db.execute("SELECT value FROM meta WHERE key=?", (key,)).fetchone()
        return default if row is None else json.loads(row[0])

    def record_model(self, t: float, kind: str, path: str | None, text: str) -> None:
        """Store the text of a goal model, binding or tactics file now in force."""
        with self._lock:
            self._flush()
            self._db.execute(
                "INSERT INTO models (t, kind, path, text) VALUES (?, ?, ?, ?)",
                (t, kind, path, text),
            )

    def models_at(self, t: float | None = None) -> dict[str, tuple[str | None, str]]:
        """The model texts in force at ``t`` (latest if ``None``): kind → (path, text)."""
        q = "SELECT kind, path, text FROM models"
        args: tuple[Any, ...] = ()
        if t is not None:
            q += " WHERE t <= ?"
            args = (t,)
        out: dict[str, tuple[str | None, str]] = {}
        with self._lock:
            for kind, path, text in self._db.execute(q + " ORDER BY id", args):
                out[kind] = (path, text)
        return out

    def record_input(self, t: float, topic: str, msg: Mapping[str, Any]) -> None:
        """Buffer one input (flushed in batches)."""
        with self._lock:
            self._inputs.append((t, topic, _dumps(msg)))
            if len(self._inputs) >= self._batch:
                self._flush()

    def record_verdict(self, t: float, node: str, utility: float | None, status: str) -> None:
        """Buffer one verdict change."""
        with self._lock:
            self._verdicts.append((t, node, utility, status))
            if len(self._verdicts) >= self._batch:
                self._flush()

    def record_decision(self, t: float, kind: str, tactic: str | None = None, **data: Any) -> int:
        """Buffer one decision (committed by the next :meth:`flush`); returns how many so far.

        Decisions get their ids when they are committed: several processes may write one
        knowledge base (one process per Utu node).
        """
        with self._lock:
            self._decisions.append((t, kind, tactic, _dumps(data)))
            self.decisions_written += 1
            return self.decisions_written

    def save_tactic(self, row: TacticRow) -> None:
        """Buffer a tactic's state (committed by the next :meth:`flush`)."""
        with self._lock:
            self._tactics[row.name] = row

    def _flush(self) -> None:
        if not (self._inputs or self._verdicts or self._decisions or self._tactics):
            return
        db = self._db
        db.execute("BEGIN")
        try:
            if self._inputs:
                db.executemany("INSERT INTO inputs (t, topic, msg) VALUES (?, ?, ?)", self._inputs)
            if self._verdicts:
                db.executemany(
                    "INSERT INTO verdicts (t, node, utility, status) VALUES (?, ?, ?, ?)",
                    self._verdicts,
                )
            if self._decisions:
                db.executemany(
                    "INSERT INTO decisions (t, kind, tactic, data) VALUES (?, ?, ?, ?)",
                    self._decisions,
                )
            if self._tactics:
                db.executemany(
                    "INSERT INTO tactics (name, state, started, deadline, next_action, "
                    "cooldown_until, attempt, reason) VALUES (?, ?, ?, ?, ?, ?, ?, ?) "
                    "ON CONFLICT(name) DO UPDATE SET state=excluded.state, "
                    "started=excluded.started, deadline=excluded.deadline, "
                    "next_action=excluded.next_action, cooldown_until=excluded.cooldown_until, "
                    "attempt=excluded.attempt, reason=excluded.reason",
                    [
                        (
                            r.name,
                            r.state,
                            r.started,
                            r.deadline,
                            r.next_action,
                            r.cooldown_until,
                            r.attempt,
                            r.reason,
                        )
                        for r in self._tactics.values()
                    ],
                )
            db.execute("COMMIT")
        except BaseException:
            db.execute("ROLLBACK")
            raise
        self._inputs.clear()
        self._verdicts.clear()
        self._decisions.clear()
        self._tactics.clear()

    def flush(self) -> None:
        """Write buffered inputs and verdicts now."""
        with self._lock:
            self._flush()

    def close(self) -> None:
        """Flush and close the database (the last connection checkpoints the WAL)."""
        if self._checkpointer is not None:
            self._checkpointer.close()
        with self._lock:
            try:
                self._flush()
            finally:
                self._db.close()

    # -- reading ------------------------------------------------------------------------
    def tactics(self) -> dict[str, TacticRow]:
        """The persisted state of every tactic."""
        self.flush()
        with self._lock:
            rows = self._db.execute(
                "SELECT name, state, started, deadline, next_action, cooldown_until, attempt, "
                "reason FROM tactics"
            ).fetchall()
        return {r[0]: TacticRow(*r) for r in rows}

    def inputs(self, since: float | None = None, until: float | None = None) -> Iterator[InputRow]:
        """Recorded inputs in order (buffered ones included)."""
        self.flush()
        q, args = _range("SELECT id, t, topic, msg FROM inputs", since, until)
        with self._lock:
            rows = self._db.execute(q + " ORDER BY id", args).fetchall()
        for i, t, topic, msg in rows:
            yield InputRow(i, t, topic, json.loads(msg))

    def verdicts(self, since: float | None = None, until: float | None = None) -> list[VerdictRow]:
        """Recorded verdict changes in order."""
        self.flush()
        q, args = _range("SELECT id, t, node, utility, status FROM verdicts", since, until)
        with self._lock:
            rows = self._db.execute(q + " ORDER BY id", args).fetchall()
        return [VerdictRow(*r) for r in rows]

    def decisions(
        self,
        since: float | None = None,
        until: float | None = None,
        limit: int | None = None,
        *,
        after_id: int | None = None,
    ) -> list[Decision]:
        """Recorded decisions in order (the last ``limit`` if given; ids above ``after_id``)."""
        self.flush()
        q, args = _range("SELECT id, t, kind, tactic, data FROM decisions", since, until)
        if after_id is not None:
            q += (" AND" if args else " WHERE") + " id > ?"
            args = (*args, after_id)
        with self._lock:
            if limit is not None:
                rows = self._db.execute(
                    f"SELECT * FROM ({q} ORDER BY id DESC LIMIT ?) ORDER BY id",
                    (*args, limit),
                ).fetchall()
            else:
                rows = self._db.execute(q + " ORDER BY id", args).fetchall()
        return [Decision(i, t, k, tac, json.loads(d)) for i, t, k, tac, d in rows]

    def holds_run(self) -> bool:
        """Whether a run was recorded here: a decision, or an input that is not a marker."""
        self.flush()
        with self._lock:
            row = self._db.execute(
                "SELECT EXISTS(SELECT 1 FROM decisions) OR "
                "EXISTS(SELECT 1 FROM inputs WHERE substr(topic, 1, 2) != '__')"
            ).fetchone()
        return bool(row[0])

    def has_input(self, topic: str) -> bool:
        """Whether an input on ``topic`` (or a marker such as ``__tick__``) was recorded."""
        self.flush()
        with self._lock:
            row = self._db.execute(
                "SELECT EXISTS(SELECT 1 FROM inputs WHERE topic = ?)", (topic,)
            ).fetchone()
        return bool(row[0])

    def first_input_t(self) -> float | None:
        """The instant of the first recorded input (markers included), if any."""
        self.flush()
        with self._lock:
            row = self._db.execute("SELECT t FROM inputs ORDER BY id LIMIT 1").fetchone()
        return None if row is None else float(row[0])

    def time_origin(self) -> float:
        """The instant, on Utu's clock, from which this log's times are shown to people.

        ``0`` on simulated time (its times already count from the simulation's start); on
        the wall clock (the first recorded instant is past :data:`EPOCH_AFTER`), the first
        recorded input or decision, so a run's times read as seconds from its start.
        """
        self.flush()
        with self._lock:
            firsts = self._db.execute(
                "SELECT (SELECT min(t) FROM inputs), (SELECT min(t) FROM decisions)"
            ).fetchone()
        first = min((float(t) for t in firsts if t is not None), default=0.0)
        return first if first >= EPOCH_AFTER else 0.0

    def last_t(self) -> float:
        """The latest instant an input or a decision was recorded at (0 for an empty run)."""
        self.flush()
        with self._lock:
            row = self._db.execute(
                "SELECT max(COALESCE((SELECT max(t) FROM inputs), 0), "
                "COALESCE((SELECT max(t) FROM decisions), 0))"
            ).fetchone()
        return float(row[0] or 0.0)

    def state_at(self, t: float) -> dict[str, tuple[float | None, str]]:
        """Each node's (utility, status) as last recorded at or before ``t``."""
        self.flush()
        out: dict[str, tuple[float | None, str]] = {}
        with self._lock:
            for node, utility, status in self._db.execute(
                "SELECT node, utility, status FROM verdicts WHERE t <= ? ORDER BY id", (t,)
            ):
                out[node] = (utility, status)
        return out

    def counts(self) -> dict[str, int]:
        """Row counts per table."""
        self.flush()
        with self._lock:
            return {
                name: int(self._db.execute(f"SELECT COUNT(*) FROM {name}").fetchone()[0])
                for name in ("inputs", "verdicts", "decisions", "models")
            }


def _range(q: str, since: float | None, until: float | None) -> tuple[str, tuple[Any, ...]]:
    clauses = []
    args: list[Any] = []
    if since is not None:
        clauses.append("t >= ?")
        args.append(since)
    if until is not None:
        clauses.append("t <= ?")
        args.append(until)
    if clauses:
        q += " WHERE " + " AND ".join(clauses)
    return q, tuple(args)


class _Checkpointer:
    """Copies the WAL into the database from a background thread, off the loop's commits.

    A passive checkpoint every ``period`` seconds on its own connection: it never blocks a
    writer, and what a reader still needs stays in the WAL until the next round. The
    loop's connection runs with ``wal_autocheckpoint=0``, so a commit never pays for the
    file sync a checkpoint does (measured: 5–10 ms on this project's machine, the whole
    tail of Utu's reaction latency).
    """

    def __init__(self, path: str, *, period: float = 1.0) -> None:
        self._stop = threading.Event()
        self._period = period
        self._db = sqlite3.connect(path, check_same_thread=False, isolation_level=None)
        self._db.execute("PRAGMA busy_timeout=5000")
        self._thread = threading.Thread(
            target=self._run, name="anunnaki-knowledge-checkpoint", daemon=True
        )
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self._period):
            try:
                self._db.execute("PRAGMA wal_checkpoint(PASSIVE)")
            except sqlite3.Error:  # busy or closing: the next round tries again
                continue

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self._db.close()
