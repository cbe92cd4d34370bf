"""Run a Utu manager from a config file on a zenoh bus until it is killed or terminated.

The child process of tests/utu/test_restart.py::

    python run_manager.py CONFIG --connect tcp/127.0.0.1:PORT --knowledge run.db [--dwell S]

It joins the test's zenoh session as a peer, prints ``ready`` once its services are
declared, and spins on the wall clock. SIGTERM stops it cleanly; the tests use SIGKILL.
"""

from __future__ import annotations

import argparse
import signal
import threading
from typing import Any

from anunnaki.bus import BusConfig, open_bus
from anunnaki.utu import AutonomicManager, load_config


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("config")
    parser.add_argument("--connect", required=True, help="zenoh endpoint of the test's bus")
    parser.add_argument("--knowledge", required=True, help="the SQLite knowledge file")
    parser.add_argument("--dwell", type=float, default=None)
    args = parser.parse_args()
    update: dict[str, Any] = {"knowledge": args.knowledge}
    if args.dwell is not None:
        update["dwell"] = args.dwell
    config = load_config(args.config).model_copy(update=update)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    bus_config = BusConfig(kind="zenoh", connect=[args.connect], name=f"utu:{config.name}")
    with (
        open_bus(bus_config) as bus,
        AutonomicManager.from_config(config, bus=bus) as manager,
    ):
        print("ready", flush=True)
        manager.spin(stop, rate=config.rate)


if __name__ == "__main__":
    main()
