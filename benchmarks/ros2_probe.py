"""Why plain rclpy round trips were slow on a quiet machine: executors and transports side by side.

benchmarks/results/ros2-quiet.json showed *direct* rclpy round trips (no Anunnaki: the echo
and measuring nodes of benchmarks/ros2_node.py) at a median of 140 ms on an idle machine,
against 4 ms under load. This script runs only that direct path, once per configuration, in
rounds (each round every configuration once, so a change in the machine's load hits them
all alike), inside a loopback-only network namespace (as benchmarks/ros2.py):

* the executor both nodes spin: ``multi`` (MultiThreadedExecutor, 2 threads, in a thread:
  what ros2_node.py used before this probe), ``single`` (SingleThreadedExecutor: what
  ros2_node.py and the bridge use since), ``events`` (rclpy.experimental.EventsExecutor);
* Fast DDS's transports (``FASTDDS_BUILTIN_TRANSPORTS``): ``DEFAULT`` (shared memory and
  UDPv4), ``UDPv4`` (no shared memory), ``SHM`` (shared memory only).

    python benchmarks/ros2_probe.py           # → benchmarks/results/ros2-probe.json
"""

from __future__ import annotations

import argparse
import json
import os
import random
import subprocess
import tempfile
from pathlib import Path
from typing import Any

from ros1 import stats, wait_line
from ros2 import NODE, ROOT, in_netns, rerun_in_netns, ros2_python


def once(python: str, executor: str, transport: str, args: argparse.Namespace) -> dict[str, Any]:
    """One configuration: the echo node and the measuring node, direct paths only."""
    home = Path(tempfile.mkdtemp(prefix="anunnaki-ros2-probe-"))
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update(ROS_HOME=str(home), ROS_LOG_DIR=str(home / "log"), PYTHONUNBUFFERED="1")
    env["ROS_DOMAIN_ID"] = str(random.randint(1, 100))
    env["FASTDDS_BUILTIN_TRANSPORTS"] = transport
    kind = ["--executor", executor]
    echo = subprocess.Popen(
        [python, str(NODE), "echo", *kind],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        wait_line(echo, "echo ready")
        counts = ["--small", str(args.small), "--images", str(args.images), "--stream", "0"]
        done = subprocess.run(
            [python, str(NODE), "measure", "--direct-only", *kind, *counts],
            env=env,
            capture_output=True,
            text=True,
            timeout=600,
            check=False,
        )
    finally:
        echo.kill()  # a probe: the echo node holds nothing worth a clean stop
        echo.communicate(timeout=30)
    lines = [ln for ln in done.stdout.splitlines() if ln.startswith("{")]
    if not lines:
        raise SystemExit(f"{executor}/{transport}: no figures\n{done.stdout[-1000:]}{done.stderr}")
    raw = json.loads(lines[-1])
    return {"small": raw["direct_small"], "image": raw["direct_image"]}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--small", type=int, default=200, help="small round trips per configuration")
    p.add_argument("--images", type=int, default=20, help="image round trips per configuration")
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--executors", default="multi,single,events")
    p.add_argument("--transports", default="DEFAULT,UDPv4,SHM")
    p.add_argument("--output", default=str(ROOT / "benchmarks" / "results" / "ros2-probe.json"))
    args = p.parse_args()
    if not in_netns():
        return rerun_in_netns(__file__)
    python = ros2_python()
    configs = [(e, t) for e in args.executors.split(",") for t in args.transports.split(",")]
    rtt: dict[str, dict[str, list[float]]] = {}
    load = [os.getloadavg()[0]]
    for _ in range(args.rounds):
        for executor, transport in configs:
            got = once(python, executor, transport, args)
            both = rtt.setdefault(f"{executor}/{transport}", {"small": [], "image": []})
            for k in both:
                both[k].extend(got[k])
            print(executor, transport, stats(got["small"]), flush=True)
        load.append(os.getloadavg()[0])
    result = {
        "benchmark": "ros2-probe",
        "machine": {
            "cpus": os.cpu_count(),
            "load_average_1min": [round(x, 2) for x in load],
            "ros": "ROS 2 Jazzy from PyPI (rclpy, Fast DDS 2.14), loopback-only network namespace",
        },
        "parameters": vars(args) | {"output": None},
        "direct_round_trip": {
            name: {"small": stats(r["small"]), "image_320x240": stats(r["image"])}
            for name, r in rtt.items()
        },
    }
    Path(args.output).write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    print(json.dumps(result["direct_round_trip"], indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
