"""What the ROS 1 bridge adds: round trips through it against plain rospy, in the same run.

Starts ``rosmaster --core`` on a free loopback port, the bridge (``python -m anunnaki.ros1``)
with a bridge file for the benchmark's topics, an echo on the bus (this process), and the
ROS side (``benchmarks/ros1_node.py`` under Debian's python3: an echo node for the plain
rospy baseline and the measuring node). Two paths, each a round trip back to the sender:

* plain rospy: measure → /bench/direct/* → echo node → back;
* bridged: measure → ROS → bridge → bus → echo (this process) → bus → bridge → ROS → back.

Small message: one std_msgs/String in flight at a time. Image: a 320×240 rgb8
sensor_msgs/Image (PNG on the bus, a CompressedImage back), one in flight, then a stream
at 30 Hz (what arrives, and whether the round trip grows: a backlog).

    python benchmarks/ros1.py                  # → benchmarks/results/ros1.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import xmlrpc.client
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
NODE = ROOT / "benchmarks" / "ros1_node.py"

BRIDGE = """\
anunnaki: ros1-bridge/1
name: bench_bridge
topics:
  - {ros: /bench/bridge/ping, type: std_msgs/String, direction: to_bus, bus: /bench/ping}
  - {ros: /bench/bridge/pong, type: std_msgs/String, direction: to_ros, bus: /bench/pong}
  - {ros: /bench/bridge/image, type: sensor_msgs/Image, direction: to_bus, bus: /bench/image,
     queue: 64}
  - {ros: /bench/bridge/image_back, type: sensor_msgs/CompressedImage, direction: to_ros,
     bus: /bench/image_back, queue: 64}
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_line(proc: subprocess.Popen[str], text: str, timeout: float = 60) -> None:
    assert proc.stdout is not None
    end = time.monotonic() + timeout
    for line in proc.stdout:
        if text in line:
            return
        if time.monotonic() > end:
            break
    raise SystemExit(f"never saw {text!r}")


def stats(ms: list[float]) -> dict[str, float]:
    ordered = sorted(ms)
    if not ordered:
        return {"n": 0}
    q = statistics.quantiles(ordered, n=100) if len(ordered) > 1 else [ordered[0]] * 99
    return {
        "n": len(ordered),
        "median_ms": round(statistics.median(ordered), 3),
        "p90_ms": round(q[89], 3),
        "p99_ms": round(q[98], 3),
    }


def run(args: argparse.Namespace) -> dict[str, Any]:
    from anunnaki.bus import open_bus

    procs: list[subprocess.Popen[str]] = []
    home = tempfile.mkdtemp(prefix="anunnaki-ros1-bench-")
    port = free_port()
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update(ROS_MASTER_URI=f"http://127.0.0.1:{port}", ROS_IP="127.0.0.1", ROS_HOME=home)
    env["PYTHONUNBUFFERED"] = "1"

    def start(cmd: list[str]) -> subprocess.Popen[str]:
        p = subprocess.Popen(
            cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        procs.append(p)
        return p

    try:
        start(["rosmaster", "--core", "-p", str(port)])
        end = time.monotonic() + 30
        while True:
            try:
                with xmlrpc.client.ServerProxy(env["ROS_MASTER_URI"]) as m:
                    m.getPid("/bench")
                break
            except OSError:
                if time.monotonic() > end:
                    raise SystemExit("the master did not start") from None
                time.sleep(0.05)
        bridge_file = Path(home) / "bridge.yaml"
        bridge_file.write_text(BRIDGE)
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        bridge = start(
            [sys.executable, "-m", "anunnaki.ros1", str(bridge_file), "--listen", endpoint]
        )
        wait_line(bridge, "ros1 bridge ready")
        echo = start(["/usr/bin/python3", str(NODE), "echo"])
        wait_line(echo, "echo ready")
        with open_bus("zenoh", mode="peer", connect=[endpoint], listen=[]) as bus:
            bus.subscribe("/bench/ping", lambda s: bus.publish("/bench/pong", s.message), queue=256)
            bus.subscribe(
                "/bench/image", lambda s: bus.publish("/bench/image_back", s.message), queue=256
            )
            counts = ["--small", str(args.small), "--images", str(args.images)]
            counts += ["--stream", str(args.stream), "--rate", str(args.rate)]
            measure = start(["/usr/bin/python3", str(NODE), "measure", *counts])
            out, _ = measure.communicate(timeout=600)
        raw = json.loads(out.strip().splitlines()[-1])
        bridge.send_signal(2)
        tail, _ = bridge.communicate(timeout=30)
        print("\n".join(tail.strip().splitlines()[-3:]), file=sys.stderr)
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.terminate()
                try:
                    p.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    p.kill()
            if p.stdout is not None:
                p.stdout.close()
    return summarise(raw, args)


def summarise(raw: dict[str, Any], args: argparse.Namespace) -> dict[str, Any]:
    small = {k: stats(raw[f"{k}_small"]) for k in ("direct", "bridged")}
    image = {k: stats(raw[f"{k}_image"]) for k in ("direct", "bridged")}
    streams = {}
    for k in ("direct", "bridged"):
        s = raw[f"{k}_image_stream"]
        rtt = s["rtt"]
        half = len(rtt) // 2
        streams[k] = {
            **stats(rtt),
            "sent": s["sent"],
            "received": len(rtt),
            "rate_hz": round(len(rtt) / s["took_s"], 1) if s["took_s"] > 0 else 0.0,
            "first_half_median_ms": round(statistics.median(rtt[:half]), 3) if half else None,
            "second_half_median_ms": round(statistics.median(rtt[half:]), 3) if half else None,
        }
    added = {
        "small_median_ms": round(small["bridged"]["median_ms"] - small["direct"]["median_ms"], 3),
        "image_median_ms": round(image["bridged"]["median_ms"] - image["direct"]["median_ms"], 3),
    }
    return {
        "benchmark": "ros1",
        "machine": {
            "python": platform.python_version(),
            "cpus": os.cpu_count(),
            "load_average_1min": round(os.getloadavg()[0], 2),
        },
        "parameters": vars(args) | {"output": None},
        "small_message_round_trip": small,
        "image_320x240_round_trip": image,
        "image_320x240_stream": streams,
        "added_by_bridge": added,
        "aims": {"small_added_median_ms": 1.0, "stream_rate_hz": args.rate},
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--small", type=int, default=500, help="small-message round trips per path")
    p.add_argument("--images", type=int, default=100, help="image round trips per path")
    p.add_argument("--stream", type=int, default=300, help="frames in the 30 Hz stream")
    p.add_argument("--rate", type=float, default=30.0, help="stream rate, Hz")
    p.add_argument("--output", default=str(ROOT / "benchmarks" / "results" / "ros1.json"))
    args = p.parse_args()
    result = run(args)
    Path(args.output).write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    print(json.dumps({k: result[k] for k in ("added_by_bridge", "image_320x240_stream")}, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
