"""Live replays of the rover example on simulation time: when does Utu decide? (issue #30)

A live run is Utu's nodes on threads of their own in one process, or one process per node
over zenoh (``--processes``): the scripted replay plays on its clock and waits for no one.
The deterministic run (one process, on the bus executor) fails safe at t=25.0 when the
light dims, and takes nine decisions. A live run takes the same decisions unless an input
is stamped at the wrong simulated time: from t=10 the ultrasonic's 4.8 Hz leaves G6 20 ms
of slack, so an input stamped one instant late reads as a rate violation and the fail-safe
comes early.

Each case runs ``--runs`` times; a row has the decisions' times and, against the
deterministic run, whether the nine decisions are the same in kind and order (``story``)
and at the same times (``exact``). ``--label`` names the code measured (``before``/``after``
a change: run the script with ``PYTHONPATH`` set to another checkout's ``src`` to measure
that one); entries of other labels in the output are kept::

    .venv/bin/python benchmarks/live_stamps.py --label after
    PYTHONPATH=/tmp/base/src .venv/bin/python benchmarks/live_stamps.py --label before
    .venv/bin/python benchmarks/live_stamps.py --label after --busy   # beside a busy process

Writes ``benchmarks/results/live-stamps-issue30.json`` (``--output`` elsewhere).
"""

from __future__ import annotations

import argparse
import io
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).parents[1]
ROVER = ROOT / "examples" / "rover"
RESULTS = Path(__file__).parent / "results" / "live-stamps-issue30.json"

#: case name → (node classes on threads, or one process per node; replay speed)
CASES: dict[str, tuple[str, float]] = {
    "threads-10x": ("threads", 10.0),
    "threads-50x": ("threads", 50.0),
    "processes-10x": ("processes", 10.0),
    "processes-50x": ("processes", 50.0),
}


def threads_launch(d: Path) -> Path:
    """The rover example without its knowledge node's rate: four node classes on threads."""
    text = (ROVER / "utu.yaml").read_text().replace("  knowledge: {rate: 10}\n", "")
    for name in ("goals.yaml", "binding.yaml", "tactics.yaml", "trace.jsonl"):
        text = text.replace(name, str(ROVER / name))
    p = d / "threads.yaml"
    p.write_text(text)
    return p


def decisions(mode: str, speed: float, d: Path) -> list[tuple[float, str, str]]:
    """One run's decisions: (simulated t, kind, tactic)."""
    from anunnaki.launch import load_launch, run_launch

    path = threads_launch(d) if mode == "threads" else ROVER / "utu.yaml"
    live = mode != "deterministic"
    result = run_launch(
        load_launch(path),
        processes=mode == "processes",
        speed=speed,
        knowledge=str(d / "kb.db") if live else None,
        out=io.StringIO(),
        handle_signals=False,
    )
    if result.exit_code != 0:
        raise RuntimeError(f"{mode} at {speed}x: exit {result.exit_code} ({result.reason})")
    return [(round(float(x.t), 3), x.kind, x.tactic or "") for x in result.decisions]


def measure(runs: int, cases: list[str]) -> dict[str, Any]:
    """Every case ``runs`` times, against one deterministic run."""
    with tempfile.TemporaryDirectory() as tmp:
        reference = decisions("deterministic", 50.0, Path(tmp))
    story = [x[1:] for x in reference]
    out: dict[str, Any] = {"deterministic": reference, "cases": {}}
    for name in cases:
        mode, speed = CASES[name]
        rows: list[dict[str, Any]] = []
        for _ in range(runs):
            with tempfile.TemporaryDirectory() as tmp:
                started = time.perf_counter()
                got = decisions(mode, speed, Path(tmp))
                wall = time.perf_counter() - started
            rows.append(
                {
                    "failsafe_t": got[0][0] if got else None,
                    "story": [x[1:] for x in got] == story,
                    "exact": got == reference,
                    "decisions": got,
                    "wall_s": round(wall, 2),
                    "load": [round(x, 2) for x in os.getloadavg()],
                }
            )
            print(name, rows[-1]["failsafe_t"], rows[-1]["story"], rows[-1]["exact"], flush=True)
        failsafe = [r["failsafe_t"] for r in rows if r["failsafe_t"] is not None]
        out["cases"][name] = {
            "mode": mode,
            "speed": speed,
            "runs": runs,
            "exact": sum(r["exact"] for r in rows),
            "story": sum(r["story"] for r in rows),
            "failsafe_t_min": min(failsafe, default=None),
            "failsafe_t_max": max(failsafe, default=None),
            "rows": rows,
        }
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--label", required=True, help="the code measured: before, after, ...")
    ap.add_argument("--runs", type=int, default=5, help="runs per case")
    ap.add_argument("--cases", nargs="+", choices=sorted(CASES), default=list(CASES))
    ap.add_argument("--busy", action="store_true", help="beside a process that keeps a core busy")
    ap.add_argument("--output", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"]) if args.busy else None
    try:
        entry = measure(args.runs, args.cases)
    finally:
        if busy is not None:
            busy.kill()
            busy.wait()
    import anunnaki

    entry.update(
        beside_busy=args.busy,
        code=str(Path(anunnaki.__file__).parents[1]),
        date=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        machine={"python": platform.python_version(), "cpus": os.cpu_count()},
    )
    doc = json.loads(args.output.read_text()) if args.output.is_file() else {"entries": {}}
    key = args.label + ("-busy" if args.busy else "")
    doc["entries"][key] = entry
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(doc, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
