"""Reading a run's decision log back: replay, the goal model at an instant, trace export.

A Utu run leaves one SQLite file (see :class:`~anunnaki.utu.Knowledge`): the model texts
in force, every input in the order the manager took it, with a ``__tick__`` marker at the end
of every step that changed something and a ``__operator__`` row for every operator call,
every verdict change and every decision. That is enough to run the *same* loop again:

* :func:`replay` builds a fresh :class:`~anunnaki.utu.AutonomicManager` from the recorded
  model texts and policy settings, with a :class:`~anunnaki.utu.RecordingActuator` (nothing
  reaches a robot), feeds it the recorded inputs and operator calls and steps it at the
  recorded instants. Only when it has finished does it read the recorded decisions and
  verdicts, and compares them with what it decided itself. The manager is deterministic,
  so a faithful log replays identically; a divergence means the log was altered, the code
  changed (a regression, or an intended change of behaviour to review), or the run did
  something a replay cannot repeat (a restart, a reload) — the report says which it saw.
* :func:`rebuild_goal_state` evaluates the goal model from the recorded *inputs* up to an
  instant — not from the recorded verdicts — so ``anunnaki explain`` shows why a goal had
  its status, naming the leaf values that decided it.
* :func:`export_trace` writes the recorded inputs as a trace (``trace/1``), which
  ``anunnaki evaluate`` replays against the goal model.

What counts as the same decision: the time, the kind, the tactic and the *decisive* data.
The outcome of an action as the managed system reported it (``ok``, ``detail``) is not
decisive — the manager does not branch on it (postconditions decide) and a replay has no
managed system to ask — so :data:`OUTCOME_FIELDS` leaves it out; and decisions written when a
background job ends (:data:`ASYNC_KINDS`: a notification's delivery) are not compared at all.
Floats are compared with an absolute tolerance (default ``1e-6``).
"""

from __future__ import annotations

import json
import math
import sqlite3
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from anunnaki.errors import AnunnakiError, ModelFileError
from anunnaki.goals import Evaluator, GoalModel
from anunnaki.tactics import TacticSet
from anunnaki.trace import Phase, Record, TraceWriter
from anunnaki.utu.cycle._actions import RecordedOutcome, ReplayRunner
from anunnaki.utu.cycle._entries import (
    OPERATOR,
    RESTART,
    TICK,
    model_from_sources,
    tactics_from_sources,
)
from anunnaki.utu.cycle._knowledge import SCHEMA_VERSION, Decision, InputRow, Knowledge, VerdictRow
from anunnaki.utu.host._actuators import RecordingActuator
from anunnaki.utu.host._manager import AutonomicManager

__all__ = [
    "ASYNC_KINDS",
    "KINDS",
    "MARKERS",
    "OUTCOME_FIELDS",
    "SETTINGS_DEFAULTS",
    "Divergence",
    "GoalState",
    "ReplayReport",
    "RunLogError",
    "RunModels",
    "decisive",
    "export_trace",
    "format_data",
    "open_run",
    "reading",
    "rebuild_goal_state",
    "replay",
    "run_models",
    "run_span",
]

KINDS: tuple[str, ...] = (
    "selected",
    "deferred",
    "withdrawn",
    "pending_approval",
    "approved",
    "rejected",
    "started",
    "action",
    "completed",
    "postcondition_ok",
    "postcondition_failed",
    "action_failed",
    "escalated",
    "escalation_exhausted",
    "run_stop",
    "paused",
    "resumed_adaptation",
    "operator_refused",
    "liveliness_lost",
    "resumed",
    "restarted",
    "reloaded",
    "reload_refused",
    "reload_requested",
    "notify_result",
    "node_died",
    "random_draw",
    "assurance",
)
"""Every kind of decision the manager records (docs/decision-log.md describes each)."""

ASYNC_KINDS: frozenset[str] = frozenset({"notify_result", "node_died", "assurance"})
"""Decisions written outside the loop's steps — when a background job finishes (a
notification delivered or not), by the launch or a surviving node when a Utu node died
(and it run-stopped the platform), or by the launch's live assurance case when a top-level
claim loses or regains its support — at whatever instant the run is at then: not a choice
of the loop, so a replay neither makes nor compares them."""

MARKERS: tuple[str, str, str] = (TICK, OPERATOR, RESTART)
"""The pseudo-topics of the ``inputs`` table that are not messages: end of a step, operator
call, a part of Utu taking up the run after a restart."""

OUTCOME_FIELDS: Mapping[str, frozenset[str]] = {
    "action": frozenset({"ok", "detail"}),
    "run_stop": frozenset({"ok"}),
}
"""Per decision kind, the data fields that report the managed system's answer, not a choice."""

SETTINGS_DEFAULTS: Mapping[str, Any] = {
    "dwell": 0.0,
    "warmup": 0.0,
    "failsafe": None,
    "escalate_to_run_stop": True,
    "run_stop_service": None,
}
"""The manager's policy settings and the constructor's defaults (used when none are recorded)."""

_TABLES = frozenset({"meta", "models", "inputs", "verdicts", "decisions"})
_HINT = "give the knowledge database of a Utu run (the 'knowledge:' file of its configuration)"


class RunLogError(ModelFileError):
    """A decision log is missing, unreadable, corrupt or not a decision log at all."""


# -- opening ---------------------------------------------------------------------------------
def _readonly(path: Path) -> sqlite3.Connection:
    return sqlite3.connect(path.resolve().as_uri() + "?mode=ro", uri=True)


def open_run(path: str | Path) -> Knowledge:
    """Open the decision log of a run for reading.

    Checks, without writing, that ``path`` is an SQLite file holding the decision-log tables
    of a schema this version reads; then opens it as a :class:`Knowledge`.

    Raises:
        RunLogError: the file is missing, not a database, corrupt, or not a decision log;
            the message names the file.

    """
    p = Path(path)
    if not p.exists():
        raise RunLogError("no such file", path=p, hint=_HINT)
    if not p.is_file():
        raise RunLogError("not a file", path=p, hint=_HINT)
    try:
        con = _readonly(p)
        try:
            names = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
            missing = sorted(_TABLES - names)
            if missing:
                raise RunLogError(
                    "not an Anunnaki decision log (no table "
                    + ", ".join(repr(m) for m in missing)
                    + ")",
                    path=p,
                    hint=_HINT,
                )
            row = con.execute("SELECT value FROM meta WHERE key='schema'").fetchone()
        finally:
            con.close()
        if row is not None and str(row[0]) != str(SCHEMA_VERSION):
            raise RunLogError(
                f"decision-log schema {row[0]}; this version of Anunnaki reads schema "
                f"{SCHEMA_VERSION}",
                path=p,
                hint="read it with the Anunnaki version that wrote it",
            )
        return Knowledge(p)
    except sqlite3.Error as exc:
        raise RunLogError(f"unreadable database ({exc})", path=p, hint=_HINT) from None


def reading(path: str | Path, exc: BaseException) -> RunLogError:
    """The error to raise when reading ``path`` failed with ``exc`` (corrupt rows or pages)."""
    if isinstance(exc, RunLogError):
        return exc
    if isinstance(exc, sqlite3.Error):
        return RunLogError(f"corrupt database ({exc})", path=path)
    return RunLogError(f"corrupt record ({type(exc).__name__}: {exc})", path=path)


# -- models ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class RunModels:
    """The model texts of a run: those it started with, and when it reloaded.

    Attributes:
        initial: kind (``goal_model``, ``binding``, ``tactics``) → (path, text) at the start.
        reloads: The times of later model records (``reload``), in order.

    """

    initial: dict[str, tuple[str | None, str]]
    reloads: tuple[float, ...]

    def model(self, sources: Mapping[str, tuple[str | None, str]] | None = None) -> GoalModel:
        """Parse the goal model (with its binding) of ``sources`` (default: the initial)."""
        return model_from_sources(self.initial if sources is None else sources)

    def tactics(self) -> TacticSet:
        """Parse the initial tactics."""
        return tactics_from_sources(self.initial)


def run_models(path: str | Path) -> RunModels:
    """Read the model texts a run recorded.

    Raises:
        RunLogError: the run recorded no goal model, or its texts do not parse.

    """
    p = Path(path)
    con = _readonly(p)
    try:
        rows = con.execute("SELECT t, kind, path, text FROM models ORDER BY id").fetchall()
    finally:
        con.close()
    initial: dict[str, tuple[str | None, str]] = {}
    reloads: list[float] = []
    for t, kind, src, text in rows:
        if not reloads and kind not in initial:
            initial[str(kind)] = (src, str(text))
        elif not reloads or reloads[-1] != t:
            reloads.append(float(t))
    if "goal_model" not in initial:
        raise RunLogError(
            "the run recorded no goal-model text, so it cannot be rebuilt",
            path=p,
            hint="build the manager with AutonomicManager.from_config (or pass sources=) so "
            "it records its model texts",
        )
    return RunModels(initial, tuple(reloads))


def run_span(path: str | Path) -> tuple[float, float] | None:
    """The times of the first and last recorded input (``None``: no input was recorded)."""
    con = _readonly(Path(path))
    try:
        lo, hi = con.execute("SELECT MIN(t), MAX(t) FROM inputs").fetchone()
    finally:
        con.close()
    return None if lo is None else (float(lo), float(hi))


def _parse_models(path: str | Path, models: RunModels) -> tuple[GoalModel, TacticSet]:
    try:
        return models.model(), models.tactics()
    except AnunnakiError as exc:
        raise RunLogError(
            f"the recorded model texts do not parse: {exc}",
            path=path,
            hint="was the log written by another version of Anunnaki?",
        ) from None


# -- comparing -------------------------------------------------------------------------------
def decisive(kind: str, data: Mapping[str, Any]) -> dict[str, Any]:
    """The data of a decision that a replay must reproduce (outcome fields left out)."""
    skip = OUTCOME_FIELDS.get(kind, frozenset())
    return {k: v for k, v in data.items() if k not in skip}


def _close(a: Any, b: Any, tol: float) -> bool:
    if isinstance(a, bool) or isinstance(b, bool):
        return a is b
    if isinstance(a, int | float) and isinstance(b, int | float):
        return math.isclose(a, b, rel_tol=0.0, abs_tol=tol) or a == b
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_close(a[k], b[k], tol) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_close(x, y, tol) for x, y in zip(a, b, strict=True))
    return bool(a == b)


def _fmt_value(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.3f}".rstrip("0").rstrip(".") if math.isfinite(v) else str(v)
    if isinstance(v, dict | list):
        return json.dumps(v, separators=(",", ":"), sort_keys=True)
    if v is None:
        return "null"
    if isinstance(v, str) and (not v or any(c.isspace() for c in v)):
        return json.dumps(v, ensure_ascii=False)
    return str(v).lower() if isinstance(v, bool) else str(v)


def format_data(data: Mapping[str, Any]) -> str:
    """A decision's data as ``key=value`` pairs (``index``, ``type`` first), for people."""
    first = [k for k in ("index", "type", "to", "note", "reason") if k in data]
    rest = sorted(k for k in data if k not in first)
    return " ".join(f"{k}={_fmt_value(data[k])}" for k in (*first, *rest))


def _describe_decision(d: Mapping[str, Any]) -> str:
    head = f"{d['kind']} {d['tactic']}" if d.get("tactic") else str(d["kind"])
    data = format_data(d["data"])
    return f"{head} ({data})" if data else head


def _describe_verdict(v: Mapping[str, Any]) -> str:
    u = v["utility"]
    return f"{v['node']} {v['status']} (utility {'?' if u is None else f'{u:.3f}'})"


def _decision_entry(d: Decision, origin: float) -> dict[str, Any]:
    d = d.shifted(origin)
    return {"t": d.t, "kind": d.kind, "tactic": d.tactic, "data": decisive(d.kind, d.data)}


def _verdict_entry(v: VerdictRow, origin: float) -> dict[str, Any]:
    return {"t": v.t - origin, "node": v.node, "utility": v.utility, "status": v.status}


@dataclass(frozen=True)
class Divergence:
    """Where a replay first departed from the record.

    Attributes:
        stream: ``"decision"`` or ``"verdict"``.
        index: 0-based position in that stream (the ``index``-th decision or verdict).
        t: The time of the first differing entry (seconds, the run's time).
        expected: The recorded entry there (``None``: the record ends; the replay did more).
        got: The replayed entry there (``None``: the replay ends; it did less).
        missing: Recorded at ``t`` but not reproduced, described for people.
        extra: Reproduced at ``t`` but not recorded.

    """

    stream: Literal["decision", "verdict"]
    index: int
    t: float
    expected: dict[str, Any] | None
    got: dict[str, Any] | None
    missing: tuple[str, ...] = ()
    extra: tuple[str, ...] = ()

    def _describe(self, entry: Mapping[str, Any] | None) -> str:
        if entry is None:
            return "nothing"
        text = _describe_decision(entry) if self.stream == "decision" else _describe_verdict(entry)
        return f"{text} at t = {entry['t']:.3f} s"

    def render(self, limit: int = 8) -> str:
        """Several lines: where, expected vs got, what is missing and extra at that time."""
        lines = [
            f"{self.stream} #{self.index} (t = {self.t:.3f} s): "
            f"expected {self._describe(self.expected)}, got {self._describe(self.got)}"
        ]
        for label, items in (
            ("recorded but not replayed", self.missing),
            ("replayed but not recorded", self.extra),
        ):
            if items:
                shown = list(items[:limit]) + (
                    [f"… {len(items) - limit} more"] if len(items) > limit else []
                )
                lines.append(f"  {label} at t = {self.t:.3f} s: " + "; ".join(shown))
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready form."""
        return {
            "stream": self.stream,
            "index": self.index,
            "t": self.t,
            "expected": self.expected,
            "got": self.got,
            "missing": list(self.missing),
            "extra": list(self.extra),
        }


def _first_divergence(
    stream: Literal["decision", "verdict"],
    recorded: Sequence[dict[str, Any]],
    replayed: Sequence[dict[str, Any]],
    tol: float,
) -> Divergence | None:
    n = min(len(recorded), len(replayed))
    i = next((k for k in range(n) if not _close(recorded[k], replayed[k], tol)), n)
    if i == len(recorded) == len(replayed):
        return None
    expected = recorded[i] if i < len(recorded) else None
    got = replayed[i] if i < len(replayed) else None
    t = min(e["t"] for e in (expected, got) if e is not None)
    at_rec = [e for e in recorded[i:] if _close(e["t"], t, tol)]
    at_rep = [e for e in replayed[i:] if _close(e["t"], t, tol)]
    describe = _describe_decision if stream == "decision" else _describe_verdict

    def minus(a: list[dict[str, Any]], b: list[dict[str, Any]]) -> tuple[str, ...]:
        left = list(b)
        out = []
        for e in a:
            match = next((k for k, o in enumerate(left) if _close(e, o, tol)), None)
            if match is None:
                out.append(describe(e))
            else:
                del left[match]
        return tuple(out)

    return Divergence(stream, i, t, expected, got, minus(at_rec, at_rep), minus(at_rep, at_rec))


# -- replay ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class ReplayReport:
    """What :func:`replay` found.

    Attributes:
        path: The decision log.
        inputs: Recorded messages and operator calls fed to the fresh manager.
        steps: Steps run (one per recorded ``__tick__``, plus one for a log ending mid-step).
        decisions: Decisions in the record.
        verdicts: Verdict changes in the record.
        replayed_decisions: Decisions the fresh manager made.
        replayed_verdicts: Verdict changes it recorded.
        settings: The policy settings the replay ran with.
        divergence: The first decision that differs, if any.
        verdict_divergence: The first verdict change that differs, if any.
        notes: What a reader should know (settings not recorded, reloads, restarts, …).
        origin: The log's time origin (:meth:`Knowledge.time_origin`): every time in the
            report is on the log's base, seconds after it.

    """

    path: str
    inputs: int
    steps: int
    decisions: int
    verdicts: int
    replayed_decisions: int
    replayed_verdicts: int
    settings: dict[str, Any]
    divergence: Divergence | None = None
    verdict_divergence: Divergence | None = None
    notes: tuple[str, ...] = field(default=())
    origin: float = 0.0

    @property
    def identical(self) -> bool:
        """Whether the replay reproduced every decision and verdict."""
        return self.divergence is None and self.verdict_divergence is None

    @property
    def empty(self) -> bool:
        """Whether the run recorded nothing at all to replay."""
        return self.inputs == 0 and self.steps == 0 and self.decisions == 0

    @property
    def exit_code(self) -> int:
        """0 identical, 1 diverged (2, unreadable, is raised as :class:`RunLogError`)."""
        return 0 if self.identical else 1

    def summary(self) -> str:
        """One line: ``identical (N decisions, M verdicts)`` or where it first diverged."""
        if self.identical:
            text = f"identical ({self.decisions} decisions, {self.verdicts} verdicts)"
            return text + (": empty run, nothing was recorded" if self.empty else "")
        first = [d for d in (self.divergence, self.verdict_divergence) if d is not None]
        first.sort(key=lambda d: (d.t, d.stream != "decision"))
        d = first[0]
        return f"diverged at {d.stream} #{d.index} (t = {d.t:.3f} s)"

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready form."""
        return {
            "path": self.path,
            "identical": self.identical,
            "summary": self.summary(),
            "inputs": self.inputs,
            "steps": self.steps,
            "decisions": self.decisions,
            "verdicts": self.verdicts,
            "replayed_decisions": self.replayed_decisions,
            "replayed_verdicts": self.replayed_verdicts,
            "settings": self.settings,
            "divergence": None if self.divergence is None else self.divergence.to_dict(),
            "verdict_divergence": (
                None if self.verdict_divergence is None else self.verdict_divergence.to_dict()
            ),
            "notes": list(self.notes),
            "origin": self.origin,
        }


def _operator(manager: AutonomicManager, op: Mapping[str, Any]) -> None:
    """Repeat one recorded operator call (applied, as it was, at the next step)."""
    kind = op.get("op")
    keys = set(op)
    caller = str(op.get("caller", "unknown"))
    if kind == "pause" and keys == {"op", "caller"}:
        manager.pause(caller)
    elif kind == "resume" and keys == {"op", "caller"}:
        manager.resume(caller)
    elif kind == "approve" and keys == {"op", "caller", "tactic", "approve"}:
        manager.approve(str(op["tactic"]), approve=bool(op["approve"]), caller=caller)
    elif kind == "run_stop" and keys == {"op", "caller", "reason"}:
        manager.run_stop(caller=caller, reason=str(op["reason"]))
    else:  # node_lost (liveliness) and anything else: the queued entry exactly as recorded
        manager.desk.enqueue(dict(op))


def _action_outcomes(knowledge: Knowledge) -> list[RecordedOutcome]:
    """Each recorded action's outcome and when it was taken (the replay's come back then)."""
    return [
        RecordedOutcome(
            d.t,
            str(d.tactic),
            int(d.data.get("index", 0)),
            bool(d.data.get("ok", True)),
            str(d.data.get("detail", "")),
            d.data["attempt"] if isinstance(d.data.get("attempt"), int) else None,
        )
        for d in knowledge.decisions()
        if d.kind == "action"
    ]


def replay(
    db_path: str | Path,
    *,
    overrides: Mapping[str, Any] | None = None,
    tolerance: float = 1e-6,
) -> ReplayReport:
    """Re-run a recorded run on a fresh manager and compare its decisions with the record.

    The fresh manager is built from the model texts the run started with and the policy
    settings it recorded (``meta`` key ``settings``; ``overrides`` replace some, for a
    what-if), acts through a :class:`RecordingActuator` and keeps its own in-memory
    knowledge. It is fed the recorded inputs in order — a message with ``feed``, an operator
    call through the same call or queue, a ``__tick__`` marker as ``step(t)`` — and never sees
    the recorded decisions: they are read only afterwards, for the comparison.

    Args:
        db_path: The run's knowledge database.
        overrides: Settings to use instead of the recorded ones (keys of
            :data:`SETTINGS_DEFAULTS`).
        tolerance: Absolute tolerance for floats (times, utilities, deadlines).

    Returns:
        The report: identical, or the first divergence of decisions and of verdicts.

    Raises:
        RunLogError: the database is missing, corrupt, not a decision log, or holds no
            model texts to rebuild the manager from.

    """
    unknown = sorted(set(overrides or {}) - set(SETTINGS_DEFAULTS))
    if unknown:
        raise AnunnakiError(
            f"unknown setting(s) {', '.join(unknown)}; settings: {', '.join(SETTINGS_DEFAULTS)}"
        )
    path = str(db_path)
    with open_run(db_path) as knowledge:
        try:
            return _replay(knowledge, path, overrides or {}, tolerance)
        except (sqlite3.Error, json.JSONDecodeError) as exc:
            raise reading(path, exc) from None


class _Feeder:
    """Feeds recorded inputs to a replaying manager, restarting it where the run restarted."""

    def __init__(
        self, build: Callable[[Knowledge], AutonomicManager], decided_at: set[float]
    ) -> None:
        self.build = build
        self.decided_at = decided_at  # the instants at which the run recorded decisions
        self.manager = build(Knowledge(":memory:"))
        self.fed = self.steps = 0
        self.pending: float | None = None  # the time of inputs fed since the last step
        self.stepped: float | None = None  # the time of the last recorded step end

    def finish_time_steps(self, verdicts: Sequence[VerdictRow]) -> list[float]:
        """Analyse the cycles of time alone the log ends with (their end markers never came).

        A node stopped with a cycle unanswered (the analyze node had recorded its verdicts,
        execute never reported it done) leaves verdicts after the last step end and no input
        after it. Each instant of those verdicts is stepped, executed only if the run
        recorded decisions then. Returns the instants stepped.
        """
        last = self.stepped
        if self.pending is not None or last is None:
            return []
        instants = sorted({v.t for v in verdicts if v.t > last})
        for t in instants:
            self.manager.step(t, execute=t in self.decided_at)
            self.steps += 1
        return instants

    def finish_step(self, analysed_until: float | None = None) -> bool:
        """Step at the time of the inputs fed since the last step, if the run decided then.

        A step the kill cut short after it had recorded decisions (an action's write-ahead
        flushes them) is finished, so the replay makes them too; inputs of a step that had
        decided nothing when it was cut short (or an operator call the run ended on) are
        not stepped: the run never acted on them — except that the log's last step, cut short
        after its analysis had recorded verdicts (``analysed_until``: the last of them, at or
        after the step's inputs) and before any decision, is analysed as far as it went.
        Returns whether it stepped.
        """
        if self.pending is None:
            return False
        if self.pending in self.decided_at:
            self.manager.step(self.pending)
        elif analysed_until is not None:
            self.manager.step(analysed_until, execute=False)
        else:
            return False
        self.steps += 1
        self.pending = None
        return True

    def feed(self, rows: Sequence[InputRow]) -> None:
        """Feed every row: messages, operator calls, step ends and restarts."""
        for row in rows:
            if row.topic == TICK:
                self.pending = None
                self.stepped = row.t
                # A step execute never acted on (it had died) is analysed only, unless the
                # run recorded decisions then (execute acted before it went).
                unexecuted = row.msg.get("executed") is False and row.t not in self.decided_at
                self.manager.step(row.t, execute=not unexecuted)
                self.steps += 1
            elif row.topic == RESTART:  # the run was killed and restarted here: so is the replay
                part = str(row.msg.get("node", "manager"))
                if part in ("analyze", "plan", "execute"):
                    # One node came up (again): the cycle in progress goes on after it.
                    self.manager.restart_part(part)
                else:  # a whole manager: what it had not written is gone with it
                    self.finish_step()  # the step the kill cut short: what it had recorded
                    self.pending = None
                    self.manager = self.build(self.manager.knowledge)
            else:
                if row.topic == OPERATOR:
                    _operator(self.manager, row.msg)
                else:
                    self.manager.feed(row.topic, row.msg, t=row.t)
                self.fed += 1
                self.pending = row.t


def _restart_notes(
    rows: Sequence[InputRow], theirs: Sequence[Mapping[str, Any]], origin: float
) -> list[str]:
    restarts = [r for r in rows if r.topic == RESTART]
    if restarts:
        return [
            "the run was restarted at t = "
            + ", ".join(f"{r.t - origin:.3f} ({r.msg.get('node', 'manager')})" for r in restarts)
            + " s; the replay restarted the same parts there"
        ]
    if any(d["kind"] == "resumed" for d in theirs):
        return [
            "the run resumed in-flight tactics without a restart marker (a log from an older "
            "version): a replay runs one manager from the start, so it diverges there"
        ]
    return []


def _replay(
    knowledge: Knowledge, path: str, overrides: Mapping[str, Any], tol: float
) -> ReplayReport:
    notes: list[str] = []
    recorded_settings = knowledge.meta("settings")
    if not isinstance(recorded_settings, dict):
        recorded_settings = {}
        notes.append(
            "the run did not record its policy settings; replayed with the defaults "
            + format_data(SETTINGS_DEFAULTS)
            + " unless overridden"
        )
    settings = {**SETTINGS_DEFAULTS, **recorded_settings, **overrides}
    settings = {k: settings[k] for k in SETTINGS_DEFAULTS}
    counts = knowledge.counts()
    if counts["inputs"] == 0 and counts["decisions"] == 0:
        return ReplayReport(path, 0, 0, 0, counts["verdicts"], 0, 0, settings, notes=tuple(notes))
    origin = knowledge.time_origin()
    models = run_models(path)
    model, tactics = _parse_models(path, models)
    if models.reloads:
        notes.append(
            "the run reloaded its models at t = "
            + ", ".join(f"{t - origin:.3f}" for t in models.reloads)
            + " s; the replay keeps the models it started with, so it may diverge from there"
        )
    actions = ReplayRunner(_action_outcomes(knowledge))

    def build(kb: Knowledge) -> AutonomicManager:
        return AutonomicManager(
            model,
            tactics,
            knowledge=kb,
            actuator=RecordingActuator(),
            actions=actions,
            dwell=float(settings["dwell"]),
            warmup=float(settings["warmup"]),
            failsafe=settings["failsafe"],
            escalate_to_run_stop=bool(settings["escalate_to_run_stop"]),
            run_stop_service=settings["run_stop_service"],
            publish_state=False,
            sources=models.initial,
        )

    # The loop's decisions (a launch's or survivor's node_died is not one of them).
    feeder = _Feeder(build, {d.t for d in knowledge.decisions() if d.kind not in ASYNC_KINDS})
    rows = list(knowledge.inputs())  # read (and decoded) first: a bad row is no replay error
    try:
        feeder.feed(rows)
        if feeder.pending is not None:
            at = feeder.pending
            # The verdicts the cut step recorded: only the log's tail, not the whole table.
            analysed = knowledge.verdicts(since=at)
            finished = feeder.finish_step(analysed[-1].t if analysed else None)
            notes.append(
                f"the log ends mid-step at t = {at - origin:.3f} s (the run was killed?); "
                "the replay "
                + (
                    "finished that step as far as the run went"
                    if finished
                    else "left it: the run decided nothing in it"
                )
            )
        elif feeder.stepped is not None:
            cut = feeder.finish_time_steps(knowledge.verdicts(since=feeder.stepped))
            if cut:
                notes.append(
                    f"the log ends with a cycle of time alone at t = {cut[-1] - origin:.3f} s "
                    "whose end was never recorded (the run was stopped in it); the replay "
                    "analysed it as far as the run went"
                )
        # The replay is over: only now read what the run decided.
        kb = feeder.manager.knowledge
        mine = [_decision_entry(d, origin) for d in kb.decisions() if d.kind not in ASYNC_KINDS]
        mine_v = [_verdict_entry(v, origin) for v in kb.verdicts()]
    finally:
        feeder.manager.close()
    fed, steps = feeder.fed, feeder.steps
    theirs = [
        _decision_entry(d, origin) for d in knowledge.decisions() if d.kind not in ASYNC_KINDS
    ]
    theirs_v = [_verdict_entry(v, origin) for v in knowledge.verdicts()]
    notes.extend(_restart_notes(rows, theirs, origin))
    return ReplayReport(
        path=path,
        inputs=fed,
        steps=steps,
        decisions=len(theirs),
        verdicts=len(theirs_v),
        replayed_decisions=len(mine),
        replayed_verdicts=len(mine_v),
        settings=settings,
        divergence=_first_divergence("decision", theirs, mine, tol),
        verdict_divergence=_first_divergence("verdict", theirs_v, mine_v, tol),
        notes=tuple(notes),
        origin=origin,
    )


# -- the goal model at an instant ------------------------------------------------------------
#: How far past the instant asked for a step still counts as at it (s): times are printed to
#: the millisecond, so a decision printed at 7.800 s may have been taken at 7.8004 s.
PRINTED_RESOLUTION = 5e-4


@dataclass
class GoalState:
    """The goal model as the manager saw it at an instant, rebuilt from the recorded inputs.

    Attributes:
        evaluator: The evaluator holding the state (``state``, ``explain``, ``values``).
        at: The instant asked for.
        as_of: The last step at or before ``at`` (``None``: no step had run yet).
        inputs: How many recorded messages were taken.
        recorded: The recorded verdicts at ``at``: node → (utility, status).

    """

    evaluator: Evaluator
    at: float
    as_of: float | None
    inputs: int
    recorded: dict[str, tuple[float | None, str]]

    def disagreements(self, tol: float = 1e-6) -> list[str]:
        """Nodes whose rebuilt state differs from the recorded verdicts, described."""
        out = []
        for node, (utility, status) in sorted(self.recorded.items()):
            if node not in self.evaluator.index:
                continue
            st = self.evaluator.state(node)
            if st.status_name != status or not _close(st.utility, utility, tol):
                out.append(
                    f"{node}: rebuilt {st.status_name} {_fmt_value(st.utility)}, "
                    f"recorded {status} {_fmt_value(utility)}"
                )
        return out


def rebuild_goal_state(knowledge: Knowledge, path: str | Path, at: float) -> GoalState:
    """Evaluate the goal model at ``at`` from the recorded inputs (not the recorded verdicts).

    The goal model is the one in force at ``at``. The recorded messages of every step that
    ended by ``at`` are observed at their recorded times and the passing of time applied at
    each step, as the manager did; an operator's ``node_lost`` (liveliness) expires the
    topics of the node's agents. The messages of a step not ended by ``at`` are not taken
    (the manager had not analysed them), so the result is the manager's view after its last
    step at or before ``at`` and compares with the verdicts it recorded there. A step up to
    :data:`PRINTED_RESOLUTION` after ``at`` counts as at ``at``: the time a decision is
    printed with explains that decision.

    Raises:
        RunLogError: no goal-model text was recorded, or it does not parse.

    """
    until = at + PRINTED_RESOLUTION
    models = run_models(path)
    sources = knowledge.models_at(until) or models.initial
    try:
        model = models.model(sources)
    except AnunnakiError as exc:
        raise RunLogError(f"the recorded goal model does not parse: {exc}", path=path) from None
    ev = Evaluator(model)
    as_of: float | None = None
    taken = 0
    ops: list[Mapping[str, Any]] = []
    messages: list[InputRow] = []  # taken by a step that has not ended yet
    for row in knowledge.inputs(until=until):
        if row.topic == TICK:
            for m in messages:
                ev.observe(m.topic, m.msg, m.t)
            taken += len(messages)
            messages.clear()
            ev.tick(row.t)
            for op in ops:
                _expire(ev, model, op, row.t)
            ops.clear()
            as_of = row.t
        elif row.topic == OPERATOR:
            ops.append(row.msg)
        else:
            messages.append(row)
    recorded = knowledge.state_at(as_of) if as_of is not None else {}
    return GoalState(ev, at, as_of, taken, recorded)


def _expire(ev: Evaluator, model: GoalModel, op: Mapping[str, Any], t: float) -> None:
    if op.get("op") != "node_lost":
        return
    for agent in model.agents.values():
        if agent.node == op.get("node"):
            for tb in agent.topics:
                ev.expire(tb.topic, t)


# -- export ----------------------------------------------------------------------------------
def export_trace(
    knowledge: Knowledge,
    out: str | Path,
    *,
    since: float | None = None,
    until: float | None = None,
    header: Mapping[str, Any] | None = None,
    mark_ticks: bool = False,
) -> int:
    """Write the recorded input messages as a trace; returns how many records were written.

    The ``__tick__`` and ``__operator__`` markers are not messages and are left out. With
    ``mark_ticks``, a step in which only time passed (no message; e.g. a topic went stale
    or a deadline passed) is written as a phase marker ``tick``, so ``anunnaki evaluate``
    applies the passing of time at the same instant the manager did.

    Raises:
        RunLogError: a recorded input cannot be written as a trace record.

    """
    count = 0
    with TraceWriter(out, header) as writer:
        messages_in_step = 0
        for row in knowledge.inputs(since=since, until=until):
            if row.topic == TICK:
                if mark_ticks and messages_in_step == 0:
                    writer.write(Phase(row.t, "tick", "time alone changed the goal model"))
                messages_in_step = 0
                continue
            if row.topic == OPERATOR:
                continue
            try:
                writer.write(Record(row.t, row.topic, row.msg))
            except ValueError as exc:
                raise RunLogError(
                    f"input #{row.id} cannot be written as a trace record: {exc}",
                    path=knowledge.path,
                ) from None
            messages_in_step += 1
            count += 1
    return count
