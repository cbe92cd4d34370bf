"""``anunnaki sim rover|uav --scenario FILE``: run a simulated platform on a bus.

The platform publishes its camera, sensors, status, ``/clock`` and ground truth and obeys
mode, stop, buzzer and teleoperation commands, on an in-process bus (``--bus inproc``: on
its own, e.g. to check a scenario) or a zenoh peer (``--bus zenoh``, loopback by default)
that Utu, the detector and the dashboard join; ``--bus`` offers every kind of
:data:`anunnaki.bus.BUS_KINDS`, a transport installed by entry point too. One line per
simulated second: time, mode, speed, collisions (rover) or altitude and battery (UAV),
frames. Ctrl-C ends it cleanly.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from collections.abc import Iterator
from typing import Any

__all__ = ["add_parser", "run"]


class _BusKinds:
    """``--bus``'s choices: the bus kinds registry, read when a name is checked or listed.

    Building the parser loads no plugin: a built-in name is checked without the entry
    points, which are loaded for another name, for ``--help`` and for the error that lists
    the valid names.
    """

    def __contains__(self, name: object) -> bool:
        from anunnaki.bus import BUS_KINDS

        return name in BUS_KINDS

    def __iter__(self) -> Iterator[str]:
        from anunnaki.bus import BUS_KINDS

        return iter(BUS_KINDS.names())


def add_parser(sub: Any) -> None:
    """Register the ``sim`` sub-command."""
    p: argparse.ArgumentParser = sub.add_parser(
        "sim",
        help="run a simulated rover or UAV (pybullet) on the bus",
        description=(
            "Run a simulated platform from a scenario file on an in-process or zenoh bus, "
            "printing a line per simulated second. Exit 0, or 2 when the scenario is invalid."
        ),
    )
    p.add_argument("platform", choices=["rover", "uav"], help="which platform")
    p.add_argument("--scenario", metavar="FILE", help="scenario file (default: built-in)")
    p.add_argument("--until", type=float, metavar="S", help="stop at simulated time S")
    p.add_argument(
        "--speed",
        type=float,
        default=1.0,
        metavar="X",
        help="simulated seconds per wall second; 0 = as fast as possible (default 1)",
    )
    p.add_argument("--width", type=int, metavar="W", help="camera width (overrides scenario)")
    p.add_argument("--height", type=int, metavar="H", help="camera height (overrides scenario)")
    p.add_argument(
        "--bus",
        choices=_BusKinds(),
        default="inproc",
        metavar="KIND",
        help="bus kind: %(choices)s (default %(default)s)",
    )
    p.add_argument(
        "--listen",
        action="append",
        metavar="ENDPOINT",
        help="endpoint to listen on (zenoh: default tcp/127.0.0.1:<free port>)",
    )
    p.add_argument(
        "--connect", action="append", metavar="ENDPOINT", help="endpoint to connect to (zenoh)"
    )
    p.add_argument(
        "--models",
        metavar="REGISTRY",
        help="run the detector in the loop: the LEC node on this model registry "
        "(e.g. examples/models/rover.yaml), scored per phase against the ground truth",
    )
    p.add_argument(
        "--oracle",
        default="ground_truth",
        metavar="NAME",
        help="the oracle node that assesses the detector (with --models; 'none' for none; "
        "default ground_truth)",
    )
    p.add_argument(
        "--report",
        metavar="FILE.json",
        help="with --models: write the run as data (every scored frame, assessment and tactic)",
    )
    p.add_argument(
        "--plot",
        metavar="FILE.png",
        help="with --models: draw the run (windowed F1 per model, oracle category, tactics)",
    )
    p.add_argument("--quiet", action="store_true", help="no per-second lines")
    p.set_defaults(run=run)


def _scenario(args: argparse.Namespace) -> Any:
    from anunnaki.sim import Scenario, load_scenario

    sc = load_scenario(args.scenario) if args.scenario else Scenario(platform=args.platform)
    if sc.platform != args.platform:
        from anunnaki.errors import ModelFileError

        raise ModelFileError(
            f"the scenario is for the {sc.platform}, not the {args.platform}",
            path=args.scenario,
            element="platform",
            hint=f"run 'anunnaki sim {sc.platform} --scenario {args.scenario}'",
        )
    if args.width or args.height:
        camera = sc.camera.model_copy(
            update={
                k: v for k, v in (("width", args.width), ("height", args.height)) if v is not None
            }
        )
        sc = sc.model_copy(update={"camera": type(sc.camera).model_validate(camera.model_dump())})
    return sc


def _line(sim: Any) -> str:
    st = sim.status()
    if sim.platform == "rover":
        extra = (
            f"x {st['x']:6.2f} m  speed {st['speed']:5.2f} m/s  collisions {st['collisions']}  "
            f"buzzer {'on ' if st['buzzer'] else 'off'}"
            + (f"  stop: {st['obstacle']}" if st["obstacle"] else "")
        )
    else:
        extra = (
            f"alt {st['altitude']:5.1f} m  battery {st['battery']:5.1f} %  "
            f"{st['phase']}{'  delivered' if st['delivered'] else ''}"
        )
    applied = ", ".join(n for n, _ in sim.last_phenomena)
    return f"t={sim.t:7.2f}s  {st['mode']:<11} {extra}  frames {sim.frames}" + (
        f"  [{applied}]" if applied else ""
    )


def _done(sim: Any) -> str:
    return f"done at t={sim.t:.2f}s: {sim.frames} frames, " + (
        f"{sim.collisions} collisions"
        if sim.platform == "rover"
        else f"delivered={sim.delivered}, battery {sim.battery:.1f} %"
    )


def _run_loop(
    args: argparse.Namespace,
    bus: Any,
    scenario: Any,
    *,
    stop: threading.Event,
    until: float,
    callback: Any,
) -> int:
    """The platform with its detector and oracle (``--models``); a per-phase report."""
    import time

    from anunnaki.managed import SimulatedSystem, format_phases
    from anunnaki.sim import save_run

    oracle = None if args.oracle == "none" else {"name": args.oracle}
    with SimulatedSystem(bus, scenario, models=args.models, oracle=oracle) as system:
        print(
            f"detector {system.lec.active.id} ({system.lec.active.domain}) on "
            f"{system.lec.camera}; oracle {args.oracle}",
            flush=True,
        )
        t0 = time.monotonic()
        system.run(stop, speed=args.speed, until=until, callback=callback)
        wall = time.monotonic() - t0
        sim = system.platform
        print(_done(sim), flush=True)
        print(
            f"simulated {sim.t:.1f} s in {wall:.1f} s wall "
            f"({sim.frames / max(wall, 1e-9):.1f} frames/s); per phase:",
            flush=True,
        )
        print(format_phases(system.phases()), flush=True)
        save_run(
            system.report(), report=args.report, plot=args.plot, say=lambda m: print(m, flush=True)
        )
    return 0


def run(args: argparse.Namespace) -> int:
    """Run the simulation until ``--until``, the scenario's duration, or Ctrl-C."""
    from anunnaki.bus import Executor, open_bus

    if args.speed < 0:
        print("error: --speed must be >= 0", file=sys.stderr)
        return 2
    if (args.report or args.plot) and not args.models:
        print("error: --report and --plot score the detector: give --models too", file=sys.stderr)
        return 2
    if args.plot:
        from anunnaki.sim import require_plot_extra

        require_plot_extra()  # before the run, not after it
    scenario = _scenario(args)
    options: dict[str, Any] = {"name": f"sim-{args.platform}"}
    if args.listen:  # the bus's configuration says whether its kind listens
        options["listen"] = args.listen
    if args.connect:
        options["connect"] = args.connect
    until = args.until if args.until is not None else scenario.duration
    stop = threading.Event()
    previous = signal.getsignal(signal.SIGINT)
    in_main = threading.current_thread() is threading.main_thread()
    if in_main:
        signal.signal(signal.SIGINT, lambda *_: stop.set())
    try:
        # In one process the run is one deterministic program: its nodes are delivered on
        # the simulation's thread (anunnaki.bus.Executor); a networked bus has its threads.
        if args.bus == "inproc" and args.models:
            options["executor"] = Executor()
        with open_bus(args.bus, **options) as bus:
            if bus.endpoints:  # a networked kind: where the others join it
                print(f"{args.bus} peer listening on {', '.join(bus.endpoints)}", flush=True)
            callback = None if args.quiet else (lambda s: print(_line(s), flush=True))
            if args.models:
                return _run_loop(args, bus, scenario, stop=stop, until=until, callback=callback)
            if args.platform == "rover":
                from anunnaki.sim import RoverSim

                sim: Any = RoverSim(bus, scenario)
            else:
                from anunnaki.sim import UavSim

                sim = UavSim(bus, scenario)
            with sim:
                sim.run(stop, speed=args.speed, until=until, callback=callback)
                print(_done(sim), flush=True)
    finally:
        if in_main:
            signal.signal(signal.SIGINT, previous)
    return 0
