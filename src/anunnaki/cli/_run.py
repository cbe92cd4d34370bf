"""``anunnaki run CONFIG`` and ``anunnaki node NAME --config CONFIG``: Utu as nodes.

``run`` is the launch file of ROS: it brings up the configured Utu nodes (in this process,
or with ``--processes`` one process per node), waits until each answers its readiness
service, starts the managed system, prints one line per decision and stops everything on
Ctrl-C/SIGTERM, at ``--until`` or when the scripted trace ends. ``node`` runs one node on
its own, e.g. on another machine. See docs/running.md.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import threading
from pathlib import Path
from typing import Any

from anunnaki._parent import stop_with_parent
from anunnaki.bus import BusConfig, open_bus
from anunnaki.cli import _dashboard, _heap
from anunnaki.launch import MailSink, load_launch, run_launch, signals_to
from anunnaki.managed import DrawsScenarios, WritesReports
from anunnaki.tokens import OPERATOR_TOKEN_ENV, user_operator_token
from anunnaki.utu import MANAGERS, NODE_NAMES, NodeConfigError, PeerWatch, build_node

__all__ = ["add_parser", "run", "run_node"]


def add_parser(sub: Any) -> None:
    """Register the ``run`` and ``node`` sub-commands."""
    _add_run_parser(sub)
    _add_node_parser(sub)


def _add_run_parser(sub: Any) -> None:
    """``anunnaki run CONFIG``: a launch file's nodes and managed system."""
    p: argparse.ArgumentParser = sub.add_parser(
        "run",
        help="run Utu's nodes (and a scripted managed system) from a launch file",
        description=(
            "Start the Utu nodes a launch file (anunnaki: launch/1) or Utu configuration "
            "(anunnaki: utu/1) names, in this process or one process per node, wait until "
            "each answers /utu/<node>/ready, start the managed system, and print one line "
            "per decision (time, kind, tactic, detail). Ctrl-C or SIGTERM stops everything "
            "cleanly (exit 0). Configuration errors exit 2 with file:line."
        ),
    )
    p.add_argument("config", help="launch file (launch/1) or Utu configuration (utu/1)")
    p.add_argument(
        "--processes",
        action="store_true",
        help="one process per node, over zenoh (default: all nodes in this process)",
    )
    p.add_argument(
        "--until",
        type=float,
        metavar="SECONDS",
        help="stop when the scripted trace reaches this time (without one: after SECONDS)",
    )
    p.add_argument(
        "--speed",
        type=float,
        metavar="X",
        help="managed system speed: 10 = 10x real time, 0 = as fast as possible",
    )
    p.add_argument("--knowledge", metavar="FILE", help="knowledge base file (overrides)")
    p.add_argument("--fresh", action="store_true", help="delete the knowledge base file first")
    p.add_argument("-v", "--verbose", action="store_true", help="log what the nodes do")
    p.add_argument(
        "--report",
        metavar="FILE.json",
        help="with a simulated managed system: write the run as data (frames, assessments, "
        "tactics; overrides managed.sim.report_file)",
    )
    p.add_argument(
        "--plot",
        metavar="FILE.png",
        help="with a simulated managed system: draw the run (windowed F1 per model, oracle "
        "category, tactics; overrides managed.sim.plot_file)",
    )
    p.add_argument(
        "--seed",
        type=int,
        metavar="N",
        help="with a simulated managed system: draw the scenario again from seed N as its "
        "vary: section says (overrides managed.sim.scenario_seed)",
    )
    p.add_argument(
        "--until-landed",
        action="store_true",
        help="with a simulated UAV: end the run at its touch-down after the flight",
    )
    _dashboard.add_run_options(p)
    p.add_argument(
        "--manager",
        choices=MANAGERS,
        help="who chooses the tactics: utu (the default), or a baseline to compare it with: "
        "none (no adaptation) or random (a startable tactic drawn uniformly whenever Utu would "
        "start one; docs/whole-loop.md)",
    )
    p.add_argument(
        "--manager-seed", type=int, metavar="N", help="the random manager's seed (default 0)"
    )
    p.add_argument(
        "--case",
        metavar="DIR",
        help="the assurance case to evaluate live (a folder 'anunnaki assurance build' wrote; "
        "default: built at the start when an assurance.yaml lies beside the launch file)",
    )
    p.add_argument(
        "--no-case",
        action="store_true",
        help="no live assurance case (neither built nor read)",
    )
    p.add_argument(
        "--mail-sink",
        type=int,
        metavar="PORT",
        help="start a local SMTP sink on 127.0.0.1:PORT for the run (the launch's notify.smtp "
        "points there) and print the mail it received at the end",
    )
    p.set_defaults(run=run, settles_heap=True)  # _heap.settle once the run is up


def _add_node_parser(sub: Any) -> None:
    """``anunnaki node NAME --config CONFIG``: one Utu node on its own."""
    n: argparse.ArgumentParser = sub.add_parser(
        "node",
        help="run one Utu node (monitor, analyze, plan, execute, knowledge) on its own",
        description=(
            "Run one Utu node with the configuration of a launch file (or Utu configuration) "
            "until Ctrl-C/SIGTERM. It joins the bus the file names (kind: zenoh), holds the "
            "liveliness token /utu_<node> and answers /utu/<node>/ready once it is up."
        ),
    )
    n.add_argument("name", choices=NODE_NAMES, help="the node to run")
    n.add_argument("--config", "-c", required=True, help="launch file or Utu configuration")
    n.add_argument("--knowledge", metavar="FILE", help="knowledge base file (overrides)")
    n.add_argument("--rate", type=float, metavar="HZ", help="cycles per second (overrides)")
    n.add_argument(
        "--connect", action="append", metavar="ENDPOINT", help="zenoh endpoint to connect to"
    )
    n.add_argument(
        "--listen", action="append", metavar="ENDPOINT", help="zenoh endpoint to listen on"
    )
    n.add_argument("--mode", choices=("peer", "client", "router"), help="zenoh mode")
    n.add_argument("--bus-json", help=argparse.SUPPRESS)
    n.add_argument("--exit-with-parent", action="store_true", help=argparse.SUPPRESS)
    n.add_argument(
        "--supervised",
        action="store_true",
        help="a supervisor (anunnaki run) run-stops the platform when a node dies; without "
        "it, the surviving nodes do (one of them, once per death)",
    )
    n.add_argument(
        "--expect",
        default="",
        metavar="NODES",
        help="analyze: start cycling only once these nodes are up (e.g. plan,execute)",
    )
    n.add_argument("-v", "--verbose", action="store_true", help="log what the node does")
    n.set_defaults(run=run_node)


def _logging(verbose: bool) -> None:
    logging.basicConfig(
        level=logging.INFO if verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )


def run(args: argparse.Namespace) -> int:
    """Run a launch file; returns the exit code."""
    _logging(args.verbose)
    launch = load_launch(args.config)
    if getattr(args, "report", None) or getattr(args, "plot", None):
        if not isinstance(launch.managed, WritesReports):
            print(
                "error: --report and --plot need a simulated managed system, a kind that keeps "
                f"its run as data ('managed: {{kind: sim, …}}' in {args.config})",
                file=sys.stderr,
            )
            return 2
        launch.managed.with_reports(
            report=str(Path(args.report).resolve()) if args.report else None,
            plot=str(Path(args.plot).resolve()) if args.plot else None,
        )
    if not _scenario_options(launch, args):
        return 2
    if os.environ.get(OPERATOR_TOKEN_ENV) is None and launch.utu.operator_token_file is None:
        # Never open by accident: the user's own token, made now if missing (every node
        # process started below reads the same file).
        _, where, generated = user_operator_token()
        print(
            f"operator token: {where} ({'written now, ' if generated else ''}readable by you "
            f"alone); anunnaki reload and the dashboard read it there, other clients send it",
            flush=True,
        )
    live_case, case = _live_case(launch, args)
    dashboard = None
    if getattr(args, "dashboard", False):
        # Bound and serving before anything starts: a port in use fails here, at once.
        token = _dashboard.token_from(args.dashboard_token)
        dashboard = _dashboard.dashboard_for_launch(
            launch, host=args.dashboard_host, port=args.dashboard_port, token=token
        )
        if case is not None:
            from anunnaki.assurance import render_svg

            dashboard.state.set_case_drawing(render_svg(case))
        dashboard.start()
        _dashboard.announce(dashboard, token)
    sink = MailSink(args.mail_sink) if getattr(args, "mail_sink", None) is not None else None
    if sink is not None:
        print(f"mail sink: SMTP on 127.0.0.1:{sink.port} (the demo's stand-in for a mail server)")
    try:
        result = run_launch(
            launch,
            processes=args.processes,
            speed=args.speed,
            until=args.until,
            knowledge=args.knowledge,
            fresh=args.fresh,
            on_bus=None if dashboard is None else dashboard.attach,
            manager=getattr(args, "manager", None),
            manager_seed=getattr(args, "manager_seed", None),
            on_knowledge=live_case,
            on_running=_heap.settle,
        )
        if sink is not None:
            _print_mail(sink, result.decisions)
        if dashboard is not None and result.reason != "stopped by a signal":
            _dashboard.linger(dashboard.url, args.dashboard_linger, say=_say)
    finally:
        if dashboard is not None:
            dashboard.close()
        if sink is not None:
            sink.close()
    return result.exit_code


def _scenario_options(launch: Any, args: argparse.Namespace) -> bool:
    """Apply ``--seed`` and ``--until-landed`` to the managed system; False: an error said."""
    seed, landed = getattr(args, "seed", None), getattr(args, "until_landed", False)
    if seed is None and not landed:
        return True
    if not isinstance(launch.managed, DrawsScenarios):
        print(
            "error: --seed and --until-landed need a simulated managed system, a kind that "
            f"draws its scenario ('managed: {{kind: sim, …}}' in {args.config})",
            file=sys.stderr,
        )
        return False
    if seed is not None and seed < 0:
        print(f"error: --seed {seed}: a seed is 0 or more", file=sys.stderr)
        return False
    launch.managed.with_scenario(seed=seed, until_landed=landed)
    return True


def _live_case(launch: Any, args: argparse.Namespace) -> tuple[Any, Any]:
    """The hook that puts the launch's assurance case on the bus, and the case (or ``None``s).

    ``--case DIR`` (or the launch file's ``assurance: DIR``) reads a built case; otherwise
    one is built now when the launch has a criteria file beside it (a few tenths of a
    second). A case that cannot be built is said on stderr and the run goes on without it.
    """
    folder = _dashboard.case_folder(launch, getattr(args, "case", None))
    if getattr(args, "no_case", False) or folder is False:
        return None, None
    from anunnaki.assurance import load_live_case

    case = load_live_case(
        launch.path, folder if isinstance(folder, str) else None, warn=_warn, loaded=launch
    )
    if case is None:
        return None, None
    print(
        f"assurance: case {case.name} ({len(case.nodes)} nodes, top-level claim {case.root} "
        f"{case.nodes[case.root].status}) evaluated live",
        flush=True,
    )
    processes = bool(getattr(args, "processes", False))

    def attach(bus: Any, kb: Any) -> Any:
        from anunnaki.assurance import CaseMonitor, LiveCase, render_svg

        def record(*a: Any, **k: Any) -> None:
            kb.record_decision(*a, **k)
            if processes:  # this process's own connection: no loop commits it
                kb.flush()

        return CaseMonitor(LiveCase(case, record=record), bus, svg=render_svg(case))

    return attach, case


def _warn(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _print_mail(sink: MailSink, decisions: list[Any]) -> None:
    """The mail the sink received, after the run (an e-mail decided late: up to 5 s)."""
    emailed = any(
        d.kind == "notify_result" and d.data.get("channel") == "email" for d in decisions
    ) or any(d.kind == "action" and d.data.get("type") == "notify" for d in decisions)
    if emailed and not sink.mails:
        sink.wait(5.0)
    mails = sink.mails
    print(f"mail sink: {len(mails)} message(s) received")
    for i, mail in enumerate(mails, 1):
        print(f"--- message {i}")
        print(mail.render())


def _say(line: str) -> None:
    print(line, flush=True)


def run_node(args: argparse.Namespace) -> int:
    """Run one node until a signal; returns the exit code."""
    _logging(args.verbose)
    launch = load_launch(args.config, read_records=False)
    utu = launch.utu
    if args.knowledge:
        utu = utu.model_copy(update={"knowledge": str(Path(args.knowledge).resolve())})
    if args.name != "monitor" and utu.knowledge == ":memory:":
        at = ("knowledge",) if launch.config.knowledge is not None else ("utu", "knowledge")
        raise launch.error(
            f"the {args.name} node shares the knowledge base with the other nodes, but it is "
            "':memory:' (private to one process)",
            *at,
            hint="name a file: knowledge: run.db, or --knowledge run.db",
        )
    if args.bus_json:  # started by a launch: its session, as the launch says
        bus_config = BusConfig.model_validate_json(args.bus_json)
    elif args.connect or args.listen or args.mode:
        # Joining a running launch by hand: its session, never its place (a client does
        # not listen where the launch listens; a peer listens on a free loopback port).
        bus_config = _dashboard.joining_bus(launch, args, role=f"the {args.name} node")
    else:  # the launch file's bus as it is (this node is the session others join)
        bus_config = launch.bus
    if bus_config.kind == "inproc":
        raise launch.error(
            "a node on its own needs a bus other processes can reach, but the bus is inproc",
            "bus",
            hint="set bus: {kind: zenoh, ...} or give --connect ENDPOINT",
        )
    if args.name not in launch.nodes:
        print(f"note: {args.name} is not among the launch file's nodes", file=sys.stderr)
    rate = args.rate if args.rate is not None else launch.nodes.get(args.name, utu.rate)
    parts = launch.parts
    parts = type(parts)(utu, parts.sources, parts.model, parts.tactics, parts.warnings)
    stop = threading.Event()
    with signals_to(stop), open_bus(bus_config) as bus:
        extra: dict[str, Any] = {}
        expect = [n for n in args.expect.split(",") if n]
        if expect:
            if args.name != "analyze":
                raise NodeConfigError("--expect applies to the analyze node only")
            extra["expect"] = expect
        node = build_node(args.name, parts, bus=bus, rate=rate, **extra)
        peers = None if args.supervised else PeerWatch(args.name, bus, utu, say=_say)
        try:
            if args.exit_with_parent:

                def parent_gone() -> None:
                    stop.set()
                    node.wake()

                stop_with_parent(parent_gone)
            # "ready" means the others see this node: a client's declarations leave in the
            # background, and one killed just after declaring its token vanished unseen (no
            # survivor acted on its death). A liveliness query answers after them: wait for it.
            bus.alive_nodes(timeout=5.0)
            where = ", ".join(bus.endpoints) or ", ".join(bus_config.connect)
            print(
                f"node {args.name} ready: pid {os.getpid()}, rate {rate:g} Hz, "
                f"bus {bus.kind} {where}, knowledge {utu.knowledge}",
                flush=True,
            )
            node.spin(stop)
        finally:
            if peers is not None:
                peers.close()
            node.close()
    return 0
