"""A stand-in behavior oracle: holds the liveliness token ``/oracle`` and publishes assessments.

The child process of tests/utu/test_failures.py::

    python oracle_node.py --connect tcp/127.0.0.1:PORT [--connect ...] [--category 0]

It publishes ``{"category", "confidence"}`` on ``/utu/oracle/output`` at 10 Hz and prints
``ready`` once its token is declared, until it is killed (the test uses SIGKILL).
"""

from __future__ import annotations

import argparse
import signal
import threading

from anunnaki.bus import BusConfig, open_bus


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--connect", action="append", required=True)
    parser.add_argument("--category", type=int, default=0)
    parser.add_argument("--rate", type=float, default=10.0)
    args = parser.parse_args()
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    with open_bus(BusConfig(kind="zenoh", connect=args.connect, name="oracle")) as bus:
        bus.liveliness_token("/oracle")
        pub = bus.publisher("/utu/oracle/output")
        print("ready", flush=True)
        period = 1.0 / args.rate
        while not stop.wait(period):  # the publishing period, not a synchronisation
            pub.put({"category": args.category, "confidence": 0.9})


if __name__ == "__main__":
    main()
