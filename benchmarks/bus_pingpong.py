"""Round-trip latency of the bus: pub/sub ping-pong and request/reply, on every bus.

Setups:

* ``inproc``: two in-process buses on one hub (one process);
* ``zenoh``: two zenoh sessions in one process, over TCP loopback;
* ``zenoh-2proc``: the echo side in a child process, over TCP loopback.

Each round trip carries a small ``Generic`` message (``{"i": n}``). Ping-pong: ``a``
publishes on ``/bench/ping``; ``b``'s callback subscriber republishes on ``/bench/pong``;
``a`` waits for it with a pull subscriber. Request/reply: ``a.request("/bench/echo", ...)``
against a service on ``b``. Each setup runs ``--repeats`` times (the machine is shared and
noisy); ``benchmarks/results/bus.json`` keeps the median of each statistic (p50, p90, p99,
in microseconds) and the range of p50 and p99 over the repeats.

Run: ``.venv/bin/python benchmarks/bus_pingpong.py [--rounds 2000]``
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

from anunnaki.bus import Bus, BusTimeout, InprocHub, Sample, open_bus
from anunnaki.messages import Generic, Message

RESULTS = Path(__file__).parent / "results" / "bus.json"

ECHO_CHILD = """
import sys, threading
from anunnaki.bus import open_bus
bus = open_bus("zenoh", connect=[sys.argv[1]], name="echo")
pong = bus.publisher("/bench/pong")
bus.subscribe("/bench/ping", lambda s: pong.put(s.message), queue=64)
bus.service("/bench/echo", lambda request: request)
print("ready", flush=True)
sys.stdin.read()  # until the parent closes our stdin
bus.close()
"""


def percentiles(samples_s: list[float]) -> dict[str, float]:
    us = sorted(x * 1e6 for x in samples_s)
    q = statistics.quantiles(us, n=100, method="inclusive")
    return {
        "p50": round(q[49], 1),
        "p90": round(q[89], 1),
        "p99": round(q[98], 1),
        "mean": round(statistics.fmean(us), 1),
        "n": len(us),
    }


def summarize(runs: list[dict[str, float]]) -> dict[str, object]:
    out: dict[str, object] = {
        key: round(statistics.median(r[key] for r in runs), 1) for key in ("p50", "p90", "p99")
    }
    out["p50_range"] = [min(r["p50"] for r in runs), max(r["p50"] for r in runs)]
    out["p99_range"] = [min(r["p99"] for r in runs), max(r["p99"] for r in runs)]
    out["n"] = sum(int(r["n"]) for r in runs)
    return out


def serve_echo(b: Bus) -> None:
    pong = b.publisher("/bench/pong")
    b.subscribe("/bench/ping", lambda s: pong.put(s.message), queue=64)
    b.service("/bench/echo", lambda request: request)


def measure(a: Bus, rounds: int, warmup: int) -> dict[str, dict[str, float]]:
    pongs = a.subscribe("/bench/pong", queue=64)
    ping = a.publisher("/bench/ping")
    if not ping.wait_for_subscribers(10):
        raise RuntimeError("the echo side never subscribed")
    # Handshake: the echo side's route back to us may come up a little later.
    deadline = time.monotonic() + 10
    while True:
        ping.put({"i": -1})
        try:
            pongs.recv(timeout=0.1)
            break
        except BusTimeout:
            if time.monotonic() > deadline:
                raise RuntimeError("no pong from the echo side") from None
    while pongs.try_recv() is not None:
        pass

    def pingpong(i: int) -> None:
        ping.put({"i": i})
        while True:
            sample: Sample = pongs.recv(timeout=5)
            assert isinstance(sample.message, Generic)  # a dict is sent as a Generic
            got = sample.message["i"]
            assert isinstance(got, int), got
            # a handshake ping's pong still in flight when the queue was drained (loaded
            # machine) arrives before this one: skip it, never a later pong
            assert got <= i, (got, i)
            if got == i:
                return

    def request(i: int) -> None:
        reply: Message = a.request("/bench/echo", {"i": i}, timeout=5)
        assert isinstance(reply, Generic) and reply["i"] == i

    out = {}
    for name, op in (("pubsub_rtt_us", pingpong), ("request_reply_us", request)):
        out[name] = percentiles(timed(op, rounds, warmup))
    return out


def timed(op: Callable[[int], None], rounds: int, warmup: int) -> list[float]:
    for i in range(warmup):
        op(i)
    samples = []
    for i in range(rounds):
        t0 = time.perf_counter()
        op(i)
        samples.append(time.perf_counter() - t0)
    return samples


def run_inproc(rounds: int, warmup: int) -> dict[str, dict[str, float]]:
    hub = InprocHub()
    with open_bus("inproc", hub=hub) as a, open_bus("inproc", hub=hub) as b:
        serve_echo(b)
        return measure(a, rounds, warmup)


def run_zenoh(rounds: int, warmup: int) -> dict[str, dict[str, float]]:
    with open_bus("zenoh") as a, open_bus("zenoh", connect=list(a.endpoints)) as b:
        serve_echo(b)
        return measure(a, rounds, warmup)


def run_zenoh_2proc(rounds: int, warmup: int) -> dict[str, dict[str, float]]:
    with (
        open_bus("zenoh") as a,
        subprocess.Popen(
            [sys.executable, "-c", ECHO_CHILD, a.endpoints[0]],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        ) as child,
    ):
        assert child.stdout is not None and child.stdin is not None
        if child.stdout.readline().strip() != "ready":
            raise RuntimeError("echo child did not start")
        try:
            return measure(a, rounds, warmup)
        finally:
            child.stdin.close()
            child.wait(10)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2000)
    parser.add_argument("--warmup", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    import zenoh  # noqa: F401  (fail early without the bus extra)

    results: dict[str, dict[str, dict[str, object]]] = {}
    for name, run in (
        ("inproc", run_inproc),
        ("zenoh", run_zenoh),
        ("zenoh-2proc", run_zenoh_2proc),
    ):
        runs = [run(args.rounds, args.warmup) for _ in range(args.repeats)]
        results[name] = {kind: summarize([r[kind] for r in runs]) for kind in runs[0]}
        print(name, json.dumps(results[name]))
    doc = {
        "benchmark": "bus_pingpong",
        "rounds": args.rounds,
        "warmup": args.warmup,
        "repeats": args.repeats,
        "summary": "median over repeats of each statistic; *_range: min and max over repeats",
        "message": 'Generic {"i": n}',
        "machine": {
            "python": platform.python_version(),
            "platform": platform.platform(),
            "cpus": os.cpu_count(),
            "zenoh": _zenoh_version(),
        },
        "results": results,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=2) + "\n")
    print("wrote", args.out)


def _zenoh_version() -> str:
    from importlib.metadata import version

    return version("eclipse-zenoh")


if __name__ == "__main__":
    main()
