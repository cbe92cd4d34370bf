"""Run the ROS 1 bridge as a process: ``python -m anunnaki.ros1 BRIDGE.yaml --connect EP``.

The process joins the zenoh bus (``--connect`` the launch's or Utu's endpoint), imports
Debian's rospy (appending its folder to ``sys.path`` here, in this process only), becomes
the ROS node named in the bridge file on ``$ROS_MASTER_URI`` (or ``--master-uri``), prints
``ros1 bridge ready`` once everything is declared, holds the bus liveliness token
``/ros1_bridge_<name>``, and runs until SIGINT/SIGTERM (or, with ``--exit-with-parent``,
until its standard input closes: a launch starts it so, and it never outlives the launch).
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import threading
import time
from collections.abc import Sequence

__all__ = ["main"]


def _parser() -> argparse.ArgumentParser:
    from anunnaki.rosbridge import add_bus_arguments

    p = argparse.ArgumentParser(
        prog="python -m anunnaki.ros1", description="Bridge ROS 1 topics and services to the bus."
    )
    p.add_argument("bridge", help="the bridge file (anunnaki: ros1-bridge/1)")
    add_bus_arguments(p)
    p.add_argument("--master-uri", help="the ROS master (default $ROS_MASTER_URI)")
    p.add_argument("--ros-ip", help="this host's address for ROS (default $ROS_IP)")
    p.add_argument(
        "--watch-every",
        type=float,
        default=0.5,
        help="seconds between looks at the master (a new master: register everything again)",
    )
    p.add_argument(
        "--wait-master",
        type=float,
        default=30.0,
        metavar="SECONDS",
        help="how long to wait for the master to answer at start (default 30)",
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run the bridge until SIGINT or SIGTERM; 0 on a clean stop, 2 on a bad start."""
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    if args.master_uri:
        os.environ["ROS_MASTER_URI"] = args.master_uri
    if args.ros_ip:
        os.environ["ROS_IP"] = args.ros_ip
    from anunnaki.bus import open_bus
    from anunnaki.errors import AnunnakiError
    from anunnaki.ros1._bridge import Bridge
    from anunnaki.ros1._rospy import import_rospy
    from anunnaki.rosbridge import bus_options, load_bridge, stop_event

    try:
        spec = load_bridge(args.bridge)
        rospy = import_rospy()
    except AnunnakiError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    stop = stop_event(args)
    options = bus_options(args, spec.name)
    uri = os.environ.get("ROS_MASTER_URI", "http://localhost:11311")
    if not _wait_for_master(spec.name, uri, args.wait_master, stop):
        print(
            f"error: no ROS master answers at {uri} after {args.wait_master:g} s: start "
            "roscore (or rosmaster --core), or set ROS_MASTER_URI / --master-uri to the robot's",
            file=sys.stderr,
        )
        return 2
    rospy.init_node(spec.name, anonymous=False, disable_signals=True)
    try:
        with (
            open_bus("zenoh", **options) as bus,  # type: ignore[arg-type]
            Bridge(spec, bus, rospy, watch_every=args.watch_every) as bridge,
        ):
            token = bus.liveliness_token(f"/ros1_bridge_{spec.name}")
            print(
                f"ros1 bridge ready: {len(spec.topics)} topics, {len(spec.services)} "
                f"services, master {uri}",
                flush=True,
            )
            stop.wait()
            token.close()
            print(f"ros1 bridge stopped: {dict(bridge.stats)}", flush=True)
    finally:
        rospy.signal_shutdown("stopped")
    return 0


def _wait_for_master(name: str, uri: str, timeout: float, stop: threading.Event) -> bool:
    """Wait until the master answers (a robot's roscore may come up after the bridge)."""
    from anunnaki.ros1._rospy import master_pid

    end = time.monotonic() + timeout
    said = False
    while master_pid(f"/{name}") is None:
        if time.monotonic() >= end or stop.is_set():
            return False
        if not said:
            print(f"waiting for the ROS master at {uri}", flush=True)
            said = True
        stop.wait(0.2)
    return True


if __name__ == "__main__":
    raise SystemExit(main())
