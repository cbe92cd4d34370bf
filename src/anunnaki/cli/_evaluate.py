"""``anunnaki evaluate MODEL --trace TRACE``: replay a trace, show the goal tree at each change."""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

from rich.console import Console
from rich.text import Text
from rich.tree import Tree

from anunnaki.errors import AnunnakiError
from anunnaki.goals import Evaluator, GoalModel, load_goal_model, status_name
from anunnaki.trace import Phase, Record, iter_trace

_STYLE = {"satisfied": "green", "unsatisfied": "bold red", "unknown": "grey50"}
_OBSTACLE = {"satisfied": "holds", "unsatisfied": "absent", "unknown": "unknown"}


def add_parser(sub: Any) -> None:
    """Register the sub-command."""
    p: argparse.ArgumentParser = sub.add_parser(
        "evaluate",
        help="replay a trace against a goal model and print the goal tree at each change",
        description=(
            "Replay a JSONL trace (docs/traces.md) against a goal model and print the goal "
            "tree with utilities whenever a goal's status changes or a utility moves by at "
            "least --delta. Colour on a terminal, plain text when piped; --json for machines."
        ),
    )
    p.add_argument("model", help="goal-model YAML file")
    p.add_argument("--binding", "-b", help="platform-binding YAML file")
    p.add_argument(
        "--trace",
        "-t",
        required=True,
        help="JSONL trace to replay, or a ROS bag (with --bridge, unless anunnaki log wrote it)",
    )
    p.add_argument(
        "--bridge",
        metavar="BRIDGE.yaml",
        help="for a rosbag: the ROS 1 bridge file mapping its topics and fields to the bus's",
    )
    p.add_argument("--json", action="store_true", help="one JSON object per change on stdout")
    p.add_argument(
        "--delta",
        type=_delta,
        default=0.05,
        help="also report a utility change of at least this much (default 0.05)",
    )
    p.add_argument("--explain", metavar="GOAL", help="print GOAL's explanation at each change")
    p.set_defaults(run=run)


def _delta(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"must be a number of 0 or more, got {text}")
    return value


def _fmt_u(u: float | None) -> str:
    return "  ?  " if u is None else f"{u:.3f}"


def render_tree(ev: Evaluator) -> Tree:
    """The goal tree with utilities and statuses, obstacles under the goals they obstruct."""
    model = ev.model

    def label(node: str) -> Text:
        st = ev.state(node)
        name = st.status_name
        desc = model.nodes()[node].description
        if st.kind == "obstacle":
            word = _OBSTACLE[name]
            style = {"holds": "bold red", "absent": "green", "unknown": "grey50"}[word]
            return Text.assemble(
                ("⊘ ", style),
                (f"{node} ", "bold"),
                (f"{word:<11}", style),
                f" {_fmt_u(st.utility)}  ",
                (desc, "dim"),
            )
        return Text.assemble(
            (f"{node} ", "bold"),
            (f"{name:<11}", _STYLE[name]),
            f" {_fmt_u(st.utility)}  ",
            (desc, "dim"),
        )

    root = Tree(label(model.root))

    def grow(tree: Tree, node: str, depth: int) -> None:
        if depth > 64:
            return
        for oid in model.obstructed_by.get(node, []):
            tree.add(label(oid))
        for child in model.goals[node].children if node in model.goals else []:
            grow(tree.add(label(child)), child, depth + 1)

    grow(root, model.root, 0)
    return root


def run(args: argparse.Namespace) -> int:
    """Replay the trace; exit 0 when done (the goal statuses are the output, not the code)."""
    model: GoalModel = load_goal_model(args.model, args.binding)
    ev = Evaluator(model)
    if args.explain is not None and args.explain not in ev.index:
        known = ", ".join(ev.ids)
        raise AnunnakiError(
            f"--explain {args.explain}: the goal model has no goal or obstacle "
            f"'{args.explain}' (it has: {known})"
        )
    console = Console(highlight=False)
    if not console.is_terminal:
        console = Console(highlight=False, width=160)
    replay = _Replay(args, model, ev, console)
    count, seen = replay.replay(_trace_items(args))
    routes = model.topic_routes()
    silent = {
        topic: sorted({agent for agent, _ in routes[topic]}) for topic, n in seen.items() if not n
    }
    if args.json:
        out = {"summary": replay.summary, "messages": count, "silent_topics": silent}
        sys.stdout.write(json.dumps(out) + "\n")
    else:
        replay.print_summary(count, silent)
    return 0


def _trace_items(args: argparse.Namespace) -> Any:
    """The trace file, or a rosbag's records through the bridge file (anunnaki[ros])."""
    from anunnaki.ros1 import is_bag, load_bridge, read_bag

    if not is_bag(args.trace):
        return args.trace
    # Without a bridge file, a bag 'anunnaki log --export-bag' wrote (any other is refused,
    # with the hint to give --bridge).
    return read_bag(args.trace, None if args.bridge is None else load_bridge(args.bridge))


class _Replay:
    """Feeds a trace to the evaluator and reports each instant's notable changes."""

    def __init__(
        self, args: argparse.Namespace, model: GoalModel, ev: Evaluator, console: Console
    ) -> None:
        self.args = args
        self.model = model
        self.ev = ev
        self.console = console
        self.last_u: dict[str, float | None] = {n: ev.state(n).utility for n in ev.ids}
        self.last_s: dict[str, Any] = {n: ev.state(n).status for n in ev.ids}
        self.phase: str | None = None
        self.summary: list[dict[str, Any]] = []
        ev.drain_changes()

    def replay(self, trace: Any) -> tuple[int, dict[str, int]]:
        """Replay ``trace``; the number of records and the count per bound topic."""
        ev = self.ev
        seen: dict[str, int] = dict.fromkeys(self.model.topic_routes(), 0)
        t = 0.0
        count = 0
        for item in trace if isinstance(trace, list) else iter_trace(trace):
            if isinstance(item, dict):
                continue
            if item.t != t:
                self.report(t)  # everything that happened at the previous instant, as one change
                t = item.t
            ev.tick(t)
            if isinstance(item, Phase):
                self.report(t)
                self._new_phase(item, t)
                continue
            assert isinstance(item, Record)
            ev.observe(item.topic, item.msg, t)
            count += 1
            if item.topic in seen:
                seen[item.topic] += 1
        self.report(t)
        ev.tick(t)
        self.report(t)
        if self.phase is not None:
            self.summary.append({"phase": self.phase, "end": t, "root": ev.root.status_name})
        return count, seen

    def _new_phase(self, item: Phase, t: float) -> None:
        if self.phase is not None:
            self.summary.append({"phase": self.phase, "end": t, "root": self.ev.root.status_name})
        self.phase = item.phase
        if not self.args.json:
            title = f"phase {item.phase}" + (f": {item.note}" if item.note else "")
            self.console.rule(Text(title, style="bold"))

    def _notable(self) -> list[tuple[str, Any, Any, float | None, float | None]]:
        """The nodes whose status changed or whose utility moved by ``--delta`` or more."""
        ev, last_u, last_s = self.ev, self.last_u, self.last_s
        notable = []
        for n in ev.drain_changes():
            st = ev.state(n)
            prev_u = last_u[n]
            moved = (st.utility is None) != (prev_u is None) or (
                st.utility is not None
                and prev_u is not None
                and abs(st.utility - prev_u) >= self.args.delta
            )
            if st.status is not last_s[n] or moved:
                notable.append((n, last_s[n], st.status, prev_u, st.utility))
                last_u[n] = st.utility
                last_s[n] = st.status
        return notable

    def report(self, t: float) -> None:
        """Report what changed notably since the last report (nothing if nothing did)."""
        notable = self._notable()
        if not notable:
            return
        if self.args.json:
            self._report_json(t, notable)
        else:
            self._report_text(t, notable)

    def _report_json(
        self, t: float, notable: list[tuple[str, Any, Any, float | None, float | None]]
    ) -> None:
        ev = self.ev
        out = {
            "t": t,
            "phase": self.phase,
            "changed": [
                {
                    "node": n,
                    "from": status_name(a),
                    "to": status_name(b),
                    "utility_from": ua,
                    "utility": ub,
                }
                for n, a, b, ua, ub in notable
            ],
            "nodes": {
                n: {"utility": ev.util[i], "status": status_name(ev.stat[i])}
                for i, n in enumerate(ev.ids)
            },
        }
        if self.args.explain:
            out["explanation"] = ev.explain(self.args.explain).to_dict()
        sys.stdout.write(json.dumps(out) + "\n")

    def _report_text(
        self, t: float, notable: list[tuple[str, Any, Any, float | None, float | None]]
    ) -> None:
        model, console = self.model, self.console

        def word(node: str, s: Any) -> str:
            if node in model.obstacles:
                return _OBSTACLE[status_name(s)]
            return status_name(s)

        what = ", ".join(
            f"{n} {word(n, a)}→{word(n, b)}"
            if a is not b
            else f"{n} {_fmt_u(ua).strip()}→{_fmt_u(ub).strip()}"
            for n, a, b, ua, ub in notable
        )
        console.print(Text.assemble((f"t = {t:8.3f} s  ", "bold cyan"), what), soft_wrap=True)
        console.print(render_tree(self.ev))
        if self.args.explain:
            console.print(Text(self.ev.explain(self.args.explain).render()))
        console.print()

    def print_summary(self, count: int, silent: dict[str, list[str]]) -> None:
        """The root's status at the end of each phase, the count, the silent topics."""
        console, model = self.console, self.model
        console.rule(Text("summary", style="bold"))
        for row in self.summary:
            console.print(
                Text.assemble(
                    f"{row['phase']:<24} root {model.root} at end of phase: ",
                    (row["root"], _STYLE[row["root"]]),
                )
            )
        console.print(Text(f"{count} messages replayed from {self.args.trace}"))
        if silent:
            names = ", ".join(f"{t} ({', '.join(a)})" for t, a in silent.items())
            console.print(
                Text(
                    f"no message on {names}: what these agents publish stayed unknown; "
                    "does the trace come from the platform of the binding?",
                    style="yellow",
                ),
                soft_wrap=True,
            )
