"""``anunnaki assurance build | check | status``: a launch's assurance case (docs/assurance.md).

``build LAUNCH.yaml --out case/`` argues the launch's goal model in GSN and develops each
claim with the project's own measurements (the criteria file ``assurance.yaml`` beside the
launch says which), then writes case.json, case.gsn.yaml (gsn2x), case.svg and case.html.
When ``--out`` already holds a case, a figure whose measurement is unchanged while an
artefact it rests on changed is stale. ``check case/`` hashes every artefact again and
names what changed. ``status`` prints the case's live statuses: from a running launch
(over its bus) or from a run's knowledge file (``--knowledge``, at ``--at T``).
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from anunnaki.cli._text import plain

__all__ = ["add_parser"]


def add_parser(sub: Any) -> None:
    """Register ``assurance`` and its sub-commands."""
    p: argparse.ArgumentParser = sub.add_parser(
        "assurance",
        help="an assurance case from the goal model and measured evidence: build, check, status",
        description=plain(__doc__),
    )
    asub = p.add_subparsers(dest="assurance_command", metavar="SUBCOMMAND")
    asub.required = True
    b: argparse.ArgumentParser = asub.add_parser(
        "build",
        help="build the case of a launch file (case.json, .gsn.yaml, .svg, .html)",
        description=(
            "Argue the launch's goal model in GSN and develop every claim with the "
            "measurements the criteria file names; write case.json, case.gsn.yaml (the "
            "layout gsn2x reads), case.svg and case.html into --out. Exit 0 when the "
            "top-level claim is supported, 1 when it is not (undeveloped, unverified, stale "
            "or failed: the case is written either way), 2 on a bad file."
        ),
    )
    b.add_argument("launch", help="launch file (anunnaki: launch/1)")
    b.add_argument("--out", required=True, help="folder to write the case into")
    b.add_argument(
        "--criteria",
        help="criteria file (anunnaki: assurance/1; default: assurance.yaml beside the launch)",
    )
    b.add_argument(
        "--root",
        help="project root the criteria's paths are relative to (default: the working folder)",
    )
    b.add_argument(
        "--run-tests",
        action="store_true",
        help="run the tests the criteria name (one pytest process) and record their outcome; "
        "otherwise they are 'not run' and support nothing",
    )
    b.add_argument(
        "--fresh",
        action="store_true",
        help="ignore a case already in --out (no comparison with it)",
    )
    b.set_defaults(run=_build)
    c: argparse.ArgumentParser = asub.add_parser(
        "check",
        help="hash a case's artefacts again; exit 1 when any changed (stale)",
        description=(
            "Hash every artefact the case's evidence rests on again. Each one that changed "
            "or is gone makes its evidence stale: printed with the claims that lose their "
            "support, and written back into the case with --update. Exit 0 when nothing "
            "changed, 1 when something did, 2 when the case cannot be read."
        ),
    )
    c.add_argument("case", help="a folder 'assurance build' wrote (or its case.json)")
    c.add_argument("--root", help="where the artefacts lie (default: the root it was built from)")
    c.add_argument(
        "--update", action="store_true", help="rewrite the case's files with the stale marks"
    )
    c.set_defaults(run=_check)
    st: argparse.ArgumentParser = asub.add_parser(
        "status",
        help="the case's statuses now: from a running launch, or from a run's knowledge file",
        description=(
            "Print each claim's live status (supported, degraded, undeveloped, unverified, "
            "stale, failed, violated) and why. Without --knowledge it asks the running launch "
            "of CONFIG over its bus (/utu/assurance/query; the bus must reach other processes: "
            "zenoh). With --knowledge FILE it evaluates the case at --at T (default: the end) "
            "from the run's recorded goal states, active model and oracle context, and lists "
            "the top-level claims' recorded support changes. Exit 0 when the top-level claim "
            "holds (supported or degraded), 1 when not, 2 on a bad file or no answer."
        ),
    )
    st.add_argument("config", nargs="?", help="launch file (the running one, or to build the case)")
    st.add_argument("--case", metavar="DIR", help="a built case (default: built from CONFIG)")
    st.add_argument("--knowledge", metavar="FILE", help="a run's knowledge file (decision log)")
    st.add_argument(
        "--at", type=float, metavar="T", help="with --knowledge: seconds from the run's start"
    )
    st.add_argument(
        "--all", action="store_true", help="strategies and solutions too, not only goals"
    )
    st.add_argument("--json", action="store_true", help="print the statuses as JSON")
    st.add_argument(
        "--connect", action="append", metavar="ENDPOINT", help="zenoh endpoint to connect to"
    )
    st.add_argument("--listen", action="append", metavar="ENDPOINT", help=argparse.SUPPRESS)
    st.add_argument("--mode", choices=("peer", "client", "router"), help="zenoh mode")
    st.add_argument("--timeout", type=float, default=5.0, help="seconds to wait for the answer")
    st.set_defaults(run=_status)


def _build(args: argparse.Namespace) -> int:
    from pathlib import Path

    from anunnaki.assurance import build_case, read_case, write_case

    prior = None
    if not args.fresh and (Path(args.out) / "case.json").is_file():
        prior = read_case(args.out)
    case = build_case(
        args.launch, criteria=args.criteria, root=args.root, tests=args.run_tests, prior=prior
    )
    files = write_case(case, args.out)
    cov = case.coverage()
    share = "—" if cov["share"] is None else f"{100 * cov['share']:.0f} %"
    print(
        f"{case.name}: top-level claim {case.root} {case.nodes[case.root].status}; "
        f"{cov['supported']} of {cov['leaf_goals']} leaf goals supported ({share}); "
        f"{cov['solutions']} evidence items {cov['solutions_by_status']}; "
        f"built in {case.build_seconds:.2f} s"
    )
    for note in case.notes:
        print(f"  note: {note}")
    for status, ids in cov["by_status"].items():
        if status != "supported":
            print(f"  {status}: {', '.join(ids)}")
    for n in case.solutions():
        if n.evidence is not None and n.evidence.stale:
            print(f"  stale {n.id}: {n.evidence.stale}")
    print(f"wrote {', '.join(str(f) for f in files.values())}")
    return 0 if case.nodes[case.root].status == "supported" else 1


def _check(args: argparse.Namespace) -> int:
    from anunnaki.assurance import check_case, read_case, write_case

    case = read_case(args.case)
    before = {n.id: n.status for n in case}
    changes = check_case(case, args.root)
    if not changes:
        print(
            f"{case.name}: every artefact is as recorded ({len(case.solutions())} evidence items)"
        )
        return 0
    for ch in changes:
        now = "gone" if ch.now is None else f"now {ch.now[:12]}…"
        what = "the argument" if ch.node == "(argument)" else f"stale {ch.node}"
        print(f"{what}: {ch.role} {ch.path} was {ch.recorded[:12]}…, {now}")
    if any(ch.node == "(argument)" for ch in changes):
        print(f"the argument was built from files that changed: build it again ({case.launch})")
    lost = [n.id for n in case if before.get(n.id) == "supported" and n.status != "supported"]
    if lost:
        print(f"claims no longer supported: {', '.join(lost)}")
    if args.update:
        from pathlib import Path

        folder = Path(args.case)
        write_case(case, folder if folder.is_dir() else folder.parent)
    sys.stdout.flush()
    return 1


def _status(args: argparse.Namespace) -> int:
    import json

    from anunnaki.assurance import HOLDING

    body = _status_from_log(args) if args.knowledge else _status_from_bus(args)
    if body is None:
        return 2
    nodes: dict[str, list[str]] = body["nodes"]
    root = body["root"]
    holds = nodes.get(root, [""])[0] in HOLDING
    if args.json:
        print(json.dumps(body, indent=1, sort_keys=True))
        return 0 if holds else 1
    t = body.get("t")
    when = "" if t is None else f" at t = {t:.3f} s"
    print(
        f"{body['case']}{when}: top-level claim {root} {nodes[root][0]}; active model "
        f"{body.get('active_model') or '?'}, perceived {body.get('perceived') or '?'}"
    )
    kinds = body.get("kinds", {})
    for nid, (status, reason) in nodes.items():
        if not args.all and kinds.get(nid, "goal") != "goal":
            continue
        mark = "*" if nid in body.get("claims", []) else " "
        print(f" {mark}{nid:<18} {status:<12} {reason}".rstrip())
    for row in body.get("changes", []):
        why = f": {row['reason']}" if row.get("reason") else ""
        print(f"  {row['t']:9.3f}  {row['claim']} support {row['support']} ({row['status']}){why}")
    return 0 if holds else 1


def _case_for(args: argparse.Namespace) -> Any:
    from anunnaki.assurance import build_case, read_case

    if args.case:
        return read_case(args.case)
    if not args.config:
        raise SystemExit("error: give the launch file (CONFIG) or --case DIR")
    return build_case(args.config)


def _status_from_log(args: argparse.Namespace) -> dict[str, Any] | None:
    """Evaluate the case at ``--at`` from what the run recorded (verdicts and inputs)."""
    from anunnaki import topics
    from anunnaki.assurance import LiveCase, perceived_of
    from anunnaki.utu.runlog import open_run

    case = _case_for(args)
    kb = open_run(args.knowledge)
    try:
        origin = kb.time_origin()
        t = kb.last_t() if args.at is None else origin + args.at
        live = LiveCase(case)
        state = kb.state_at(t)
        live.take_analysis({"t": t, "nodes": {k: list(v) for k, v in state.items()}})
        for row in kb.inputs(until=t):
            if row.topic == topics.ACTIVE_MODEL:
                live.take_active_model(row.msg)
            elif row.topic == topics.ORACLE_OUTPUT and perceived_of(row.msg) is not None:
                live.take_assessment(row.msg)
        live.update()
        changes = [
            {"t": d.t - origin, **d.data}
            for d in kb.decisions(until=t)
            if d.kind == "assurance" and d.data.get("support") != "initial"
        ]
    finally:
        kb.close()
    body = live.snapshot()
    body["t"] = t - origin
    body["changes"] = changes
    body["kinds"] = {n.id: n.type for n in case}
    return body


def _status_from_bus(args: argparse.Namespace) -> dict[str, Any] | None:
    """Ask the running launch's case over its bus."""
    from anunnaki import topics
    from anunnaki.bus import BusError, open_bus
    from anunnaki.cli._dashboard import joining_bus
    from anunnaki.launch import load_launch
    from anunnaki.messages import body_of

    if not args.config:
        raise SystemExit("error: give the running launch's file (CONFIG), or --knowledge FILE")
    launch = load_launch(args.config, read_records=False)
    config = joining_bus(launch, args, role="anunnaki assurance status")
    with open_bus(config, name=f"{launch.name}-assurance-status") as bus:
        try:
            reply = body_of(bus.request(topics.ASSURANCE_QUERY, {}, timeout=args.timeout))
        except BusError as exc:
            print(
                f"error: no live assurance case answered on {topics.ASSURANCE_QUERY} ({exc}); "
                f"is '{launch.name}' running with a case (anunnaki run … without --no-case)?",
                file=sys.stderr,
            )
            return None
    return dict(reply)
