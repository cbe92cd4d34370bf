"""Run the native ROS 2 bridge as a process: ``python -m anunnaki.ros2 BRIDGE.yaml --connect EP``.

Run it with a Python that imports rclpy: the ROS 2 environment scripts/setup-ros2.sh builds
(``.venv-ros2/bin/python -m anunnaki.ros2 ...``), or any Python after sourcing a ROS 2
install's ``setup.bash``. The process joins the zenoh bus (``--connect`` the launch's or
Utu's endpoint), becomes the ROS 2 node named in the bridge file (domain
``$ROS_DOMAIN_ID``), checks that the bridge file's ``distro`` (if it names one) is the
installed ROS 2's, prints ``ros2 bridge ready`` once everything is declared, holds the bus
liveliness token ``/ros2_bridge_<name>``, publishes its ROS 2 heartbeat ``/<name>/heartbeat``
(a liveliness lease robots watch), and runs until SIGINT/SIGTERM (or, with
``--exit-with-parent``, until its standard input closes). rclpy's own signal handlers are
off: a signal stops the bridge cleanly (executor, node, bus, in that order), and an
``ExternalShutdownException`` (the ROS context shut down under it) ends it cleanly too.
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading
from collections.abc import Sequence
from typing import Any

__all__ = ["main"]


def _parser() -> argparse.ArgumentParser:
    from anunnaki.rosbridge import add_bus_arguments

    p = argparse.ArgumentParser(
        prog="python -m anunnaki.ros2",
        description="Bridge ROS 2 topics and services to the bus (rclpy).",
    )
    p.add_argument("bridge", help="the bridge file (anunnaki: ros2-bridge/1)")
    add_bus_arguments(p)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run the bridge until SIGINT or SIGTERM; 0 on a clean stop, 2 on a bad start."""
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    from anunnaki.errors import AnunnakiError
    from anunnaki.ros2._distro import installed_distro, resolve_distro
    from anunnaki.ros2._native import import_rclpy
    from anunnaki.rosbridge import bus_options, load_bridge, stop_event

    try:
        spec = load_bridge(args.bridge)
        rclpy = import_rclpy()
        distro = resolve_distro(spec.distro, where=args.bridge)
    except AnunnakiError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    installed = installed_distro()
    if installed is not None and installed != distro:
        print(
            f"error: {args.bridge} names ROS 2 {distro.capitalize()}, but this environment's "
            f"rclpy is {installed.capitalize()}: run the bridge with the robot's distribution, "
            "or correct 'distro'",
            file=sys.stderr,
        )
        return 2
    stop = stop_event(args)
    options = bus_options(args, spec.name)
    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    try:
        return _run(rclpy, spec, options, stop, distro)
    finally:
        rclpy.try_shutdown()


def _run(
    rclpy: Any, spec: Any, options: dict[str, object], stop: threading.Event, distro: str
) -> int:
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

    from anunnaki.bus import open_bus
    from anunnaki.ros2._native import Ros2Bridge

    node = rclpy.create_node(spec.name)
    # one thread: no callback of the bridge waits. benchmarks/ros2_probe.py, plain rclpy
    # round trips at load 7 on 2 cores: SingleThreadedExecutor median 0.47 ms, p99 9.7 ms;
    # MultiThreadedExecutor 4.2 ms, 92 ms (docs/results.md)
    executor = SingleThreadedExecutor()
    executor.add_node(node)

    def spin() -> None:
        try:
            executor.spin()
        except ExternalShutdownException:
            pass  # the ROS context shut down (another SIGINT handler, rclpy.shutdown)
        finally:
            stop.set()

    spinner = threading.Thread(target=spin, name="anunnaki-ros2-executor", daemon=True)
    try:
        with (
            open_bus("zenoh", **options) as bus,  # type: ignore[arg-type]
            Ros2Bridge(spec, bus, node, rclpy) as bridge,
        ):
            spinner.start()
            token = bus.liveliness_token(f"/ros2_bridge_{spec.name}")
            print(
                f"ros2 bridge ready: {len(spec.topics)} topics, {len(spec.services)} "
                f"services, ROS 2 {distro.capitalize()}",
                flush=True,
            )
            stop.wait()
            token.close()
            executor.shutdown(timeout_sec=5.0)
            print(f"ros2 bridge stopped: {dict(bridge.stats)}", flush=True)
    finally:
        executor.shutdown(timeout_sec=5.0)
        node.destroy_node()
    spinner.join(timeout=5.0)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
