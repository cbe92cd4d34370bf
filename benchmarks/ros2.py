"""What the native ROS 2 bridge adds: round trips through it against plain rclpy, same run.

The script runs itself again inside a loopback-only network namespace (``unshare -rn``,
``ip link set lo up``), and every process it starts lives there, so no DDS packet leaves the
machine: the bridge (``python -m anunnaki.ros2`` with the ROS 2 environment's Python, ``.venv-ros2``
from scripts/setup-ros2.sh, or ``$ANUNNAKI_ROS2_PYTHON``) and the ROS 2 side
(``benchmarks/ros2_node.py``: an echo node for the plain rclpy baseline and the measuring
node). This process echoes on the bus (zenoh on the namespace's loopback). Two
paths, each a round trip back to the sender:

* plain rclpy: measure → /bench/direct/* → echo node → back;
* bridged: measure → ROS 2 → bridge → bus → echo (this process) → bus → bridge → ROS 2 → back.

Reaction: the robot (``ros2_node.py react``) publishes a violating ``/bench/level``; the
bridge carries it to the bus; Utu (an in-process manager here: one goal, ``level < 0.5``,
and one tactic requesting ``/bench/set_safe``, cooldown 0) reacts; the bridge calls the
robot's ``std_srvs/Trigger``. The robot times violation → call with its own clock; the
first trial warms up (the bridge's first call waits on the service's discovery) and is
reported apart (``first_call_ms``).

Bridge killed: the example rover (examples/rover/ros2/rover_robot.py) and its bridge
(examples/rover/ros2/bridge.yaml, the heartbeat's default 1-s lease); once the rover says it
sees the bridge alive, the bridge gets SIGKILL, and the time to the rover's ``safe state``
line is taken (this process's clock: the kill, then the line read; ``--kills`` times, a new
bridge each time).

Small message: one std_msgs/String in flight at a time. Image: a 320×240 rgb8
sensor_msgs/Image (PNG on the bus, a CompressedImage back), one in flight, then a stream
at 30 Hz (what arrives — frames dropped — and whether the round trip grows: a backlog).

    python benchmarks/ros2.py                  # → benchmarks/results/ros2.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from anunnaki.rosbridge import load_bridge
from ros1 import free_port, stats, wait_line  # the ROS 1 benchmark's, the same measures

ROOT = Path(__file__).resolve().parents[1]
#: The example rover's bridge, SIGKILLed in the kill trials (its heartbeat's lease is theirs).
KILLED_BRIDGE = ROOT / "examples" / "rover" / "ros2" / "bridge.yaml"
NODE = ROOT / "benchmarks" / "ros2_node.py"

_IN_NETNS = "ANUNNAKI_BENCH_IN_NETNS"

BRIDGE = """\
anunnaki: ros2-bridge/1
name: bench_bridge
topics:
  - {ros: /bench/bridge/ping, type: std_msgs/String, direction: to_bus, bus: /bench/ping,
     queue: 100}
  - {ros: /bench/bridge/pong, type: std_msgs/String, direction: to_ros, bus: /bench/pong,
     queue: 100}
  - {ros: /bench/bridge/image, type: sensor_msgs/Image, direction: to_bus, bus: /bench/image,
     queue: 64}
  - {ros: /bench/bridge/image_back, type: sensor_msgs/CompressedImage, direction: to_ros,
     bus: /bench/image_back, queue: 64}
  - {ros: /bench/level, type: std_msgs/Float64, direction: to_bus, fields: {level: data}}
services:
  - {bus: /bench/set_safe, type: std_srvs/Trigger}
"""

GOALS = """\
anunnaki: goal-model/1
name: bench
root: G1
agents:
  - {id: A1, topics: [{topic: /bench/level, attributes: [level]}]}
goals:
  - {id: G1, utility: A1.level < 0.5}
"""

TACTICS = """\
anunnaki: tactics/1
name: bench
tactics:
  - name: make-safe
    priority: 100
    preconditions:
      - {goal: G1, state: unsatisfied}
    actions:
      - {type: request, service: /bench/set_safe}
    cooldown: 0
"""


def rerun_in_netns(script: str) -> int:
    """Run ``script`` (with this process's arguments) again in a loopback-only network namespace."""
    inner = [sys.executable, str(Path(script).resolve()), *sys.argv[1:]]
    shell = 'ip link set lo up && exec "$@"'
    env = os.environ | {_IN_NETNS: "1"}
    return subprocess.run(
        ["unshare", "-rn", "sh", "-c", shell, "sh", *inner], check=False, env=env
    ).returncode


def in_netns() -> bool:
    """Whether this process is the one :func:`rerun_in_netns` started."""
    return os.environ.get(_IN_NETNS) == "1"


def ros2_python() -> str:
    named = os.environ.get("ANUNNAKI_ROS2_PYTHON")
    python = Path(named) if named else ROOT / ".venv-ros2" / "bin" / "python"
    if not python.exists():
        raise SystemExit(f"no ROS 2 environment at {python}: run scripts/setup-ros2.sh")
    return str(python)


def run(args: argparse.Namespace) -> dict[str, Any]:
    from anunnaki.bus import open_bus

    procs: list[subprocess.Popen[str]] = []
    home = Path(tempfile.mkdtemp(prefix="anunnaki-ros2-bench-"))
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update(PYTHONUNBUFFERED="1", ROS_HOME=str(home), ROS_LOG_DIR=str(home / "log"))
    # a domain of its own: Fast DDS's shared-memory ports (/dev/shm) are not in the namespace
    env["ROS_DOMAIN_ID"] = str(random.randint(1, 100))
    python = ros2_python()

    def start(cmd: list[str]) -> subprocess.Popen[str]:
        p = subprocess.Popen(
            cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        procs.append(p)
        return p

    try:
        bridge_file = home / "bridge.yaml"
        bridge_file.write_text(BRIDGE)
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        with open_bus("zenoh", mode="peer", listen=[endpoint], connect=[]) as bus:
            bus.subscribe("/bench/ping", lambda s: bus.publish("/bench/pong", s.message), queue=256)
            bus.subscribe(
                "/bench/image", lambda s: bus.publish("/bench/image_back", s.message), queue=256
            )
            bridge = start([python, "-m", "anunnaki.ros2", str(bridge_file), "--connect", endpoint])
            wait_line(bridge, "ros2 bridge ready")
            echo = start([python, str(NODE), "echo"])
            wait_line(echo, "echo ready")
            counts = ["--small", str(args.small), "--images", str(args.images)]
            counts += ["--stream", str(args.stream), "--rate", str(args.rate)]
            measure = start([python, str(NODE), "measure", *counts])
            out, _ = measure.communicate(timeout=600)
            reaction = react(bus, start, python, args.trials)
            bridge.send_signal(2)
            tail, _ = bridge.communicate(timeout=30)
            killed = kill_to_safe_state(start, python, endpoint, args.kills)
        lines = [ln for ln in out.strip().splitlines() if ln.startswith("{")]
        if not lines:
            raise SystemExit(f"the measuring node printed no figures:\n{out[-2000:]}")
        raw = json.loads(lines[-1]) | reaction | killed
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


def react(bus: Any, start: Any, python: str, trials: int) -> dict[str, Any]:
    """The reaction trials: Utu here, the robot in ROS 2; the robot's figures."""
    import threading

    from anunnaki.goals import parse_goal_model
    from anunnaki.tactics import parse_tactics_yaml
    from anunnaki.utu import AutonomicManager

    model = parse_goal_model(GOALS)
    tactics = parse_tactics_yaml(TACTICS)
    stop = threading.Event()
    # a lost call is a lost trial, not the end of the run (no escalation to a run stop)
    with AutonomicManager(
        model, tactics, bus=bus, rate=50.0, escalate_to_run_stop=False
    ) as manager:
        spinner = threading.Thread(target=manager.spin, args=(stop,), daemon=True)
        spinner.start()
        try:
            robot = start([python, str(NODE), "react", "--trials", str(trials)])
            out, _ = robot.communicate(timeout=600)
        finally:
            stop.set()
            spinner.join(timeout=30)
        failed = [d.data for d in manager.knowledge.decisions() if d.kind == "action_failed"]
        if failed:
            print(f"{len(failed)} actions failed, e.g. {failed[0]}", file=sys.stderr)
    lines = [ln for ln in out.strip().splitlines() if ln.startswith("{")]
    if not lines:
        raise SystemExit(f"the robot printed no figures:\n{out[-2000:]}")
    return dict(json.loads(lines[-1]))


def kill_to_safe_state(start: Any, python: str, endpoint: str, kills: int) -> dict[str, Any]:
    """SIGKILL the example rover's bridge ``kills`` times; the seconds to its safe state each."""
    rover_py = ROOT / "examples" / "rover" / "ros2" / "rover_robot.py"
    if kills <= 0:
        return {"kill_to_safe_state": [], "kill_lost": 0}
    rover = start([python, str(rover_py)])
    wait_line(rover, "rover ready")
    took: list[float] = []
    lost = 0
    for _ in range(kills):
        bridge = start([python, "-m", "anunnaki.ros2", str(KILLED_BRIDGE), "--connect", endpoint])
        wait_line(bridge, "ros2 bridge ready")
        wait_line(rover, "manager anunnaki_bridge alive")
        t0 = time.monotonic()
        bridge.kill()
        try:
            wait_line(rover, "manager anunnaki_bridge gone", timeout=60)
            took.append((time.monotonic() - t0) * 1000.0)
        except SystemExit:
            lost += 1
        bridge.wait(timeout=30)
    rover.terminate()
    rover.wait(timeout=30)
    return {"kill_to_safe_state": took, "kill_lost": lost}


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
            "dropped": s["sent"] - len(rtt),
            "rate_hz": round(len(rtt) / s["took_s"], 1) if s["took_s"] > 0 else 0.0,
            "first_half_median_ms": round(statistics.median(rtt[:half]), 3) if half else None,
            "second_half_median_ms": round(statistics.median(rtt[half:]), 3) if half else None,
        }
    b, d = small["bridged"], small["direct"]
    added = {
        "small_median_ms": round(b["median_ms"] - d["median_ms"], 3),
        "small_p99_ratio": round(b["p99_ms"] / d["p99_ms"], 2) if d.get("p99_ms") else None,
        "image_median_ms": round(image["bridged"]["median_ms"] - image["direct"]["median_ms"], 3),
    }
    return {
        "benchmark": "ros2",
        "machine": {
            "python": platform.python_version(),
            "cpus": os.cpu_count(),
            "load_average_1min": round(os.getloadavg()[0], 2),
            "ros": "ROS 2 Jazzy from PyPI (rclpy, Fast DDS), loopback-only network namespace",
        },
        "parameters": vars(args) | {"output": None},
        "small_message_round_trip": small,
        "image_320x240_round_trip": image,
        "image_320x240_stream": streams,
        "added_by_bridge": added,
        "violation_to_robot_service_call": {
            **stats(raw["violation_to_call"]),
            "lost": raw["lost"],
            # the warm-up trial, not in the figures above: the bridge's first call of the
            # robot's service (discovery of its endpoints included); None: never arrived
            "first_call_ms": _round(raw.get("first_call")),
        },
        "bridge_kill_to_rover_safe_state": {
            **stats(raw["kill_to_safe_state"]),
            "ms": [round(x, 1) for x in raw["kill_to_safe_state"]],
            "lost": raw["kill_lost"],
            "heartbeat_lease_s": load_bridge(KILLED_BRIDGE).heartbeat_lease,
        },
        "aims": {"small_added_median_ms": 1.0, "small_p99_ratio": 2.0, "stream_rate_hz": args.rate},
    }


def _round(ms: float | None) -> float | None:
    return None if ms is None else round(ms, 1)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--small", type=int, default=500, help="small-message round trips per path")
    p.add_argument("--images", type=int, default=100, help="image round trips per path")
    p.add_argument("--stream", type=int, default=300, help="frames in the 30 Hz stream")
    p.add_argument("--rate", type=float, default=30.0, help="stream rate, Hz")
    p.add_argument("--trials", type=int, default=100, help="violation → service call trials")
    p.add_argument("--kills", type=int, default=5, help="bridge SIGKILL → rover safe state trials")
    p.add_argument("--output", default=str(ROOT / "benchmarks" / "results" / "ros2.json"))
    args = p.parse_args()
    if not in_netns():
        return rerun_in_netns(__file__)
    result = run(args)
    Path(args.output).write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    print(json.dumps({k: result[k] for k in ("added_by_bridge", "image_320x240_stream")}, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
