"""``anunnaki log | explain | replay RUN.db``: read a Utu run's decision log back.

* ``log`` — the decisions as a table (filters by time, tactic, kind; ``--verdicts`` mixes
  in the verdict changes; ``--json`` one object per line), or ``--export-trace`` the
  recorded inputs as a trace for ``anunnaki evaluate``;
* ``explain`` — the goal model at an instant, rebuilt from the recorded inputs, with the
  explanation of a goal and the decisions around that instant;
* ``replay`` — run the recorded inputs through a fresh manager and compare its decisions
  with the record: exit 0 identical, 1 diverged, 2 unreadable.

See docs/decision-log.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sqlite3
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from rich import box
from rich.console import Console
from rich.table import Table
from rich.text import Text

from anunnaki.errors import AnunnakiError
from anunnaki.utu import Decision, Knowledge, RunLogError, VerdictRow, replay
from anunnaki.utu.runlog import (
    KINDS,
    export_trace,
    format_data,
    open_run,
    reading,
    rebuild_goal_state,
    run_models,
    run_span,
)

_STATUS = {"satisfied": "green", "unsatisfied": "bold red", "unknown": "grey50"}
_KIND_STYLE = {
    "postcondition_failed": "bold red",
    "action_failed": "bold red",
    "escalation_exhausted": "bold red",
    "operator_refused": "red",
    "reload_refused": "red",
    "escalated": "bold yellow",
    "run_stop": "bold white on red",
    "liveliness_lost": "yellow",
    "paused": "cyan",
    "resumed_adaptation": "cyan",
    "resumed": "cyan",
    "postcondition_ok": "green",
    "completed": "green",
    "started": "bold",
    "deferred": "dim",
    "withdrawn": "dim",
}


def add_parser(sub: Any) -> None:
    """Register the ``log``, ``explain`` and ``replay`` sub-commands."""
    p: argparse.ArgumentParser = sub.add_parser(
        "log",
        help="show a run's decision log (or export its inputs as a trace)",
        description=(
            "Print the decisions a Utu run recorded in its knowledge database: time, kind, "
            "tactic and details, failures and escalations in colour (plain text when piped). "
            "With --export-trace, write the recorded inputs as a JSONL trace instead, which "
            "'anunnaki evaluate' replays. Exit 0, or 2 when the file is unreadable."
        ),
    )
    p.add_argument("db", metavar="RUN.db", help="the run's knowledge database")
    p.add_argument("--since", type=_seconds, metavar="T", help="from time T (s) on")
    p.add_argument("--until", type=_seconds, metavar="T", help="up to time T (s)")
    p.add_argument("--tactic", metavar="NAME", help="only decisions about tactic NAME")
    p.add_argument(
        "--kind",
        action="append",
        metavar="K",
        help="only decisions of kind K (repeat, or K1,K2); e.g. started,escalated,run_stop",
    )
    p.add_argument("--verdicts", action="store_true", help="interleave the verdict changes")
    p.add_argument("--json", action="store_true", help="one JSON object per row on stdout")
    p.add_argument(
        "--export-trace",
        metavar="OUT.jsonl",
        help="write the recorded inputs (within --since/--until) as a trace and exit",
    )
    p.add_argument(
        "--export-bag",
        metavar="OUT.bag|OUT",
        help="write the recorded inputs and decisions (within --since/--until) to a ROS 1 "
        "bag (OUT.bag) or a rosbag2 folder (OUT; MCAP unless --bag-storage says otherwise), "
        "std_msgs/String JSON, decisions on /utu/decisions, and exit (anunnaki[ros])",
    )
    p.add_argument(
        "--bag-storage",
        choices=["ros1", "mcap", "sqlite3"],
        default=None,
        help="with --export-bag: ros1 (the default for OUT.bag), mcap (else) or sqlite3",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="with --export-trace or --export-bag: replace an existing file",
    )
    p.add_argument(
        "--mark-ticks",
        action="store_true",
        help="with --export-trace: mark steps where only time passed as 'tick' phases",
    )
    p.set_defaults(run=run_log)

    e: argparse.ArgumentParser = sub.add_parser(
        "explain",
        help="the goal model at time T, rebuilt from the recorded inputs, and why",
        description=(
            "Rebuild the goal model's state at time T from the inputs the run recorded (not "
            "from its recorded verdicts), print the goal tree with utilities and statuses, "
            "explain a goal (default the root) by the leaf values that decided it, and list "
            "the decisions around T."
        ),
    )
    e.add_argument("db", metavar="RUN.db", help="the run's knowledge database")
    e.add_argument("--at", type=_seconds, required=True, metavar="T", help="the time (s)")
    e.add_argument("--goal", "-g", metavar="G", help="goal or obstacle to explain (default root)")
    e.add_argument(
        "--window",
        type=_nonnegative,
        default=5.0,
        metavar="S",
        help="show the decisions within S seconds of T (default 5)",
    )
    e.add_argument("--json", action="store_true", help="print one JSON object")
    e.set_defaults(run=run_explain)

    r: argparse.ArgumentParser = sub.add_parser(
        "replay",
        help="re-run a recorded run and compare; exit 0 identical, 1 diverged, 2 unreadable",
        description=(
            "Build a fresh manager from the model texts and settings a run recorded, feed it "
            "the recorded inputs and operator calls at the recorded instants (no bus, nothing "
            "reaches a robot) and compare its decisions and verdicts with the record. Prints "
            "'identical' or the first divergence. Exit 0 identical, 1 diverged, 2 unreadable."
        ),
    )
    r.add_argument("db", metavar="RUN.db", help="the run's knowledge database")
    r.add_argument("--json", action="store_true", help="print the report as one JSON object")
    r.add_argument("--dwell", type=_nonnegative, metavar="S", help="what if: another dwell")
    r.add_argument("--warmup", type=_nonnegative, metavar="S", help="what if: another warm-up")
    r.add_argument("--failsafe", metavar="TACTIC", help="what if: another fail-safe tactic")
    r.add_argument(
        "--tolerance",
        type=_nonnegative,
        default=1e-6,
        metavar="X",
        help="absolute tolerance for floats (default 1e-6)",
    )
    r.set_defaults(run=run_replay)


def _utc(t: float) -> str:
    """An epoch instant as a UTC date and time (what a wall-clock log's times count from)."""
    return datetime.fromtimestamp(t, tz=UTC).strftime("%Y-%m-%d %H:%M:%S UTC")


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number of seconds: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number of seconds, got {text}")
    return value


def _nonnegative(text: str) -> float:
    value = _seconds(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {text}")
    return value


def _console() -> Console:
    console = Console(highlight=False)
    if not console.is_terminal:
        console = Console(highlight=False, width=200)
    return console


@contextmanager
def _run(path: str) -> Iterator[Knowledge]:
    """Open the log; turn a failure while reading it into an error naming the file."""
    with open_run(path) as knowledge:
        try:
            yield knowledge
        except (sqlite3.Error, json.JSONDecodeError) as exc:
            raise reading(path, exc) from None


def _show(console: Console, renderable: Any) -> None:
    """Print; when piped, without the padding rich adds at the end of table lines."""
    if console.is_terminal:
        console.print(renderable)
        return
    with console.capture() as captured:
        console.print(renderable)
    sys.stdout.write("".join(line.rstrip() + "\n" for line in captured.get().splitlines()))


def _fmt_u(u: float | None) -> str:
    return "?" if u is None else f"{u:.3f}"


def _decision_json(d: Decision) -> dict[str, Any]:
    return {"type": "decision", "t": d.t, "kind": d.kind, "tactic": d.tactic, "data": d.data}


def _verdict_json(v: VerdictRow) -> dict[str, Any]:
    return {"type": "verdict", "t": v.t, "node": v.node, "utility": v.utility, "status": v.status}


def _decision_style(d: Decision) -> str:
    if d.kind in ("action", "notify_result") and d.data.get("ok") is False:
        return "red"
    return _KIND_STYLE.get(d.kind, "")


def _table(console: Console, rows: Sequence[Decision | VerdictRow], mark: float | None) -> Table:
    table = Table(box=box.SIMPLE_HEAD if console.is_terminal else None, pad_edge=False)
    table.add_column("t (s)", justify="right", no_wrap=True)
    table.add_column("kind", no_wrap=True)
    table.add_column("tactic", no_wrap=True)
    table.add_column("details", overflow="fold")
    for row in rows:
        t = f"{row.t:.3f}"
        if mark is not None:
            t = ("▶ " if math.isclose(row.t, mark) else "  ") + t
        if isinstance(row, VerdictRow):
            table.add_row(
                Text(t, style="dim"),
                Text("verdict", style="dim"),
                Text(row.node, style="dim"),
                Text.assemble(
                    (f"{row.status:<11}", _STATUS.get(row.status, "")),
                    f" utility {_fmt_u(row.utility)}",
                ),
            )
            continue
        style = _decision_style(row)
        table.add_row(
            t,
            Text(row.kind, style=style),
            row.tactic or "",
            Text(format_data(row.data), style=style if style.endswith("red") else ""),
        )
    return table


def _kinds(values: list[str] | None, present: set[str]) -> set[str] | None:
    if not values:
        return None
    kinds = {k.strip() for v in values for k in v.split(",") if k.strip()}
    unknown = sorted(k for k in kinds if k not in KINDS and k not in present)
    if unknown:
        raise AnunnakiError(
            f"--kind {', '.join(unknown)}: no such kind of decision; kinds: {', '.join(KINDS)}"
        )
    return kinds


def _merge(
    decisions: Sequence[Decision], verdicts: Sequence[VerdictRow]
) -> list[Decision | VerdictRow]:
    # Within one step the verdicts are recorded before the decisions they lead to.
    def key(row: Decision | VerdictRow) -> tuple[float, int, int]:
        return (row.t, 1 if isinstance(row, Decision) else 0, row.id)

    return sorted([*decisions, *verdicts], key=key)


def _write_jsonl(rows: Sequence[Decision | VerdictRow]) -> None:
    for row in rows:
        obj = _verdict_json(row) if isinstance(row, VerdictRow) else _decision_json(row)
        sys.stdout.write(json.dumps(obj, sort_keys=True) + "\n")


def run_log(args: argparse.Namespace) -> int:
    """Print the decision log, or export the recorded inputs as a trace."""
    path: str = args.db
    console = _console()
    with _run(path) as knowledge:
        counts = knowledge.counts()
        origin = knowledge.time_origin()
        span = run_span(path)
        since, until = (None if x is None else x + origin for x in (args.since, args.until))
        if args.export_trace is not None:
            return _export(console, knowledge, path, args, (since, until))
        if getattr(args, "export_bag", None) is not None:
            return _export_bag(console, knowledge, args, (since, until))
        decisions = [d.shifted(origin) for d in knowledge.decisions(since, until)]
        kinds = _kinds(args.kind, {d.kind for d in decisions})
        shown = [
            d
            for d in decisions
            if (kinds is None or d.kind in kinds)
            and (args.tactic is None or args.tactic in (d.tactic, d.data.get("to")))
        ]
        verdicts = (
            [dataclasses.replace(v, t=v.t - origin) for v in knowledge.verdicts(since, until)]
            if args.verdicts
            else []
        )
    rows = _merge(shown, verdicts)
    if args.json:
        if counts["inputs"] == 0 and counts["decisions"] == 0:
            print(f"{path}: empty run: nothing was recorded", file=sys.stderr)
        _write_jsonl(rows)
        return 0
    if counts["inputs"] == 0 and counts["decisions"] == 0:
        console.print(Text(f"{path}: empty run: nothing was recorded (no inputs, no decisions)"))
        return 0
    when = f" from t = {span[0] - origin:.3f} to {span[1] - origin:.3f} s" if span else ""
    if origin:
        when += f" after the start ({_utc(origin)})"
    console.print(
        Text(
            f"{path}: {counts['inputs']} inputs, {counts['decisions']} decisions, "
            f"{counts['verdicts']} verdict changes{when}",
            style="bold",
        ),
        soft_wrap=True,
    )
    if not rows:
        console.print(Text(f"no decisions match (of {counts['decisions']} in the log)"))
        return 0
    _show(console, _table(console, rows, None))
    filtered = len(shown) != counts["decisions"]
    if filtered:
        console.print(Text(f"{len(shown)} of {counts['decisions']} decisions shown", style="dim"))
    return 0


def _export_bag(
    console: Console,
    knowledge: Knowledge,
    args: argparse.Namespace,
    span: tuple[float | None, float | None],
) -> int:
    """Write the run's inputs and decisions to a bag (ROS 1 or rosbag2), at their own times."""
    from anunnaki.rosbridge import write_bag
    from anunnaki.trace import Record

    inputs = [
        Record(row.t, row.topic, row.msg)
        for row in knowledge.inputs(*span)
        if not row.topic.startswith("__")  # the tick and operator markers are no messages
    ]
    decisions = [
        (d.t, {"kind": d.kind, "tactic": d.tactic, **d.data}) for d in knowledge.decisions(*span)
    ]
    n = write_bag(
        args.export_bag, inputs, decisions, overwrite=args.force, storage=args.bag_storage
    )
    hint = _evaluate_hint(args.db, args.export_bag)
    console.print(
        Text(f"wrote {n} messages ({len(decisions)} decisions) to {args.export_bag}{hint}"),
        soft_wrap=True,
    )
    return 0


def _evaluate_hint(path: str, out: str) -> str:
    """``; replay it: anunnaki evaluate …`` for an exported trace or bag ('' if unknown)."""
    try:
        models = run_models(path).initial
    except RunLogError:
        return ""
    gm, bd = models.get("goal_model", (None, ""))[0], models.get("binding", (None, ""))[0]
    if not gm:
        return ""
    return (
        f"; replay it: anunnaki evaluate {gm}"
        + (f" --binding {bd}" if bd else "")
        + (f" --trace {out}")
    )


def _export(
    console: Console,
    knowledge: Knowledge,
    path: str,
    args: argparse.Namespace,
    span: tuple[float | None, float | None],
) -> int:
    out: str = args.export_trace
    if Path(out).exists() and not args.force:
        raise AnunnakiError(f"{out} exists already; give another name, or --force")
    header = {
        "name": Path(path).stem,
        "description": f"inputs recorded in the decision log {path}",
        "source": path,
    }
    try:
        n = export_trace(
            knowledge,
            out,
            since=span[0],
            until=span[1],
            header=header,
            mark_ticks=args.mark_ticks,
        )
    except OSError as exc:
        raise AnunnakiError(f"{out}: cannot write the trace: {exc.strerror}") from None
    what = "empty run: wrote no messages" if n == 0 else f"wrote {n} messages"
    console.print(Text(f"{what} from {path} to {out}{_evaluate_hint(path, out)}"), soft_wrap=True)
    return 0


def run_explain(args: argparse.Namespace) -> int:
    """Print the goal model at ``--at`` rebuilt from the recorded inputs, and why."""
    from anunnaki.cli._evaluate import render_tree

    path: str = args.db
    at: float = args.at  # on the log's time base, as printed
    with _run(path) as knowledge:
        origin = knowledge.time_origin()
        state = rebuild_goal_state(knowledge, path, at + origin)
        lo, hi = at - args.window, at + args.window
        around = [d.shifted(origin) for d in knowledge.decisions(lo + origin, hi + origin)]
        claims = _claims_at(knowledge, at + origin, origin)
        span = run_span(path)
    as_of = None if state.as_of is None else state.as_of - origin
    ev = state.evaluator
    goal = args.goal or ev.model.root
    if goal not in ev.index:
        raise AnunnakiError(
            f"--goal {goal}: the goal model has no goal or obstacle {goal!r} "
            f"(it has: {', '.join(ev.ids)})"
        )
    explanation = ev.explain(goal)
    differ = state.disagreements()
    if args.json:
        out = {
            "path": path,
            "at": at,
            "as_of": as_of,
            "origin": origin,
            "inputs": state.inputs,
            "nodes": {
                n: {"utility": s.utility, "status": s.status_name} for n, s in ev.states().items()
            },
            "values": ev.values(),
            "goal": goal,
            "explanation": explanation.to_dict(),
            "agrees_with_record": not differ,
            "disagreements": differ,
            "decisions": [_decision_json(d) for d in around],
            "assurance": claims,
        }
        sys.stdout.write(json.dumps(out, sort_keys=True) + "\n")
        return 0
    console = _console()
    if span is None:
        console.print(Text(f"{path}: empty run: nothing was recorded (no inputs)"))
    if as_of is None:
        first = f" (the first at t = {span[0] - origin:.3f} s)" if span else ""
        where = f"no step had run by t = {at:.3f} s{first}: every goal is unknown"
    else:
        where = (
            f"as of the manager's step at t = {as_of:.3f} s, rebuilt from "
            f"{state.inputs} recorded messages"
        )
    console.print(Text.assemble((f"{path} at t = {at:.3f} s", "bold"), f": {where}"))
    _show(console, render_tree(ev))
    console.print()
    console.print(Text(f"why {goal} is {_word(explanation.kind, explanation.status)}:"))
    console.print(Text(explanation.render("  ")))
    if explanation.leaves:
        console.print(Text("deciding values: " + format_data(explanation.leaves), style="dim"))
    console.print()
    if differ:
        console.print(
            Text(
                f"{len(differ)} node(s) differ from the recorded verdicts (was the log "
                "altered, or the evaluator changed?): " + "; ".join(differ),
                style="yellow",
            ),
            soft_wrap=True,
        )
    elif state.recorded:
        console.print(Text("the rebuilt state agrees with the recorded verdicts", style="dim"))
    if claims:
        parts = [
            f"{c} {d['status']} ({d['support']} at {d['t']:.3f} s"
            + (f": {d['reason']})" if d.get("reason") else ")")
            for c, d in claims.items()
        ]
        console.print(
            Text("assurance case, top-level claims as recorded: " + "; ".join(parts)),
            soft_wrap=True,
        )
    if around:
        console.print(Text(f"decisions from t = {lo:.3f} to {hi:.3f} s:", style="bold"))
        _show(console, _table(console, around, as_of))
    else:
        console.print(Text(f"no decisions from t = {lo:.3f} to {hi:.3f} s"))
    return 0


def _claims_at(knowledge: Knowledge, t: float, origin: float) -> dict[str, dict[str, Any]]:
    """Each top-level claim of the run's live assurance case as last recorded by ``t``."""
    out: dict[str, dict[str, Any]] = {}
    for d in knowledge.decisions(None, t):
        claim = d.data.get("claim")
        if d.kind == "assurance" and isinstance(claim, str):
            out[claim] = {"t": d.t - origin, **d.data}
    return out


def _word(kind: str, status: bool | None) -> str:
    if kind == "obstacle":
        return {True: "present (it holds)", False: "absent", None: "unknown"}[status]
    return {True: "satisfied", False: "unsatisfied", None: "unknown"}[status]


def run_replay(args: argparse.Namespace) -> int:
    """Replay the run; exit 0 identical, 1 diverged (2 unreadable, raised)."""
    overrides: dict[str, Any] = {}
    for key in ("dwell", "warmup", "failsafe"):
        value = getattr(args, key)
        if value is not None:
            overrides[key] = value
    report = replay(args.db, overrides=overrides, tolerance=args.tolerance)
    if args.json:
        sys.stdout.write(json.dumps(report.to_dict(), sort_keys=True) + "\n")
        return report.exit_code
    console = _console()
    say: Callable[..., None] = console.print
    if report.empty:
        say(Text(f"{report.path}: empty run: nothing was recorded, nothing to replay"))
        return 0
    say(
        Text(
            f"replayed {report.path}: {report.steps} steps, {report.inputs} inputs; settings "
            + format_data(report.settings)
            + (f" (what if: {format_data(overrides)})" if overrides else ""),
        ),
        soft_wrap=True,
    )
    for note in report.notes:
        say(Text(f"note: {note}", style="yellow"), soft_wrap=True)
    if report.identical:
        say(Text(report.summary(), style="bold green"))
        return 0
    say(Text(report.summary(), style="bold red"))
    say(
        Text(
            f"recorded {report.decisions} decisions and {report.verdicts} verdict changes; "
            f"the replay made {report.replayed_decisions} and {report.replayed_verdicts}"
        )
    )
    for label, d in (
        ("first decision divergence", report.divergence),
        ("first verdict divergence", report.verdict_divergence),
    ):
        if d is not None:
            say(Text(f"{label}: {d.render()}"), soft_wrap=True)
    return report.exit_code
