"""A simulated run repeats itself: the same launch, three times, one beside a busy process.

Issue #30. ``anunnaki run LAUNCH --speed 0 --until S --report R`` three times (runs 1 and 3
quiet, run 2 beside a process that keeps one core busy), each with its own knowledge base;
then the report files and the decision logs compared byte for byte, and ``anunnaki replay``
of the first run's knowledge. The rover demo's first 30 s and the UAV's whole mission by
default. Each run's wall time gives the simulated seconds per wall second.

Writes ``benchmarks/results/determinism.json`` (one entry per launch, replaced when run
again) and prints one line per launch::

    .venv/bin/python benchmarks/determinism.py                  # rover 30 s and the UAV mission
    .venv/bin/python benchmarks/determinism.py --cases rover --runs 2
    .venv/bin/python benchmarks/determinism.py --cases uav --until 11 --output /tmp/d.json

``--case-studies`` checks the managers benchmark instead: ``benchmarks/case_studies.py --quick
--cases rover --seeds N`` twice (the second beside a busy process), and its tables (every run's
measures, every summary) compared, leaving out what measures the machine rather than the run
(:data:`MACHINE_FIELDS`: wall seconds, load averages, the date)::

    .venv/bin/python benchmarks/determinism.py --case-studies --seeds 2

``--until`` shortens every case to that many simulated seconds (the suite's checks,
tests/benchmarks/test_determinism_benchmark.py and test_determinism_uav.py, run the rover's
first 9 s and the UAV's first 11 s twice each); ``--output`` writes elsewhere than the
committed results.
"""

from __future__ import annotations

import argparse
import hashlib
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
RESULTS = Path(__file__).parent / "results" / "determinism.json"

#: name → (launch file, simulated seconds; None: the scenario's whole length)
CASES: dict[str, tuple[str, float | None]] = {
    "rover": ("examples/rover/demo.yaml", 30.0),
    "uav": ("examples/uav/sim.yaml", None),
}


#: Fields of benchmarks/case_studies.py's JSON that measure the machine, not the run.
MACHINE_FIELDS = frozenset({"wall_s", "load_average", "date", "machine"})


def run_facts(doc: Any) -> Any:
    """``doc`` without :data:`MACHINE_FIELDS`, at any depth: what a rerun must repeat."""
    if isinstance(doc, dict):
        return {k: run_facts(v) for k, v in doc.items() if k not in MACHINE_FIELDS}
    if isinstance(doc, list):
        return [run_facts(v) for v in doc]
    return doc


def case_studies(seeds: int) -> dict[str, Any]:
    """The managers benchmark's quick rover runs twice (the 2nd loaded); their tables compared."""
    tables: list[Any] = []
    walls: list[float] = []
    with tempfile.TemporaryDirectory(prefix="determinism-cs-") as tmp:
        for k in range(2):
            out = Path(tmp) / f"cs{k}.json"
            argv = [sys.executable, str(ROOT / "benchmarks" / "case_studies.py"), "--quick"]
            argv += ["--cases", "rover", "--seeds", str(seeds), "--output", str(out)]
            busy = subprocess.Popen([sys.executable, "-c", "while True: pass"]) if k else None
            t0 = time.perf_counter()
            try:
                proc = subprocess.run(argv, capture_output=True, text=True, check=False)
            finally:
                if busy is not None:
                    busy.kill()
                    busy.wait()
            walls.append(round(time.perf_counter() - t0, 1))
            if proc.returncode != 0:
                raise SystemExit(
                    f"case_studies.py exited {proc.returncode}:\n{proc.stderr[-2000:]}"
                )
            tables.append(run_facts(json.loads(out.read_text())["cases"]))
            print(f"  case studies run {k + 1}: {walls[-1]} s", flush=True)
    digests = [hashlib.sha256(json.dumps(t, sort_keys=True).encode()).hexdigest() for t in tables]
    return {
        "command": f"benchmarks/case_studies.py --quick --cases rover --seeds {seeds}",
        "runs": [
            {"wall_s": w, "tables_sha256": d, "beside_busy": bool(k)}
            for k, (w, d) in enumerate(zip(walls, digests, strict=True))
        ],
        "identical_tables": digests[0] == digests[1],
    }


def _run(launch: str, until: float | None, folder: Path, k: int) -> dict[str, Any]:
    report, kb = folder / f"run{k}.json", folder / f"run{k}.db"
    argv = [sys.executable, "-m", "anunnaki.cli.main", "run", str(ROOT / launch), "--speed", "0"]
    argv += ["--report", str(report), "--knowledge", str(kb)]
    if until is not None:
        argv += ["--until", str(until)]
    t0 = time.perf_counter()
    proc = subprocess.run(argv, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{launch}: run {k} exited {proc.returncode}:\n{proc.stderr[-2000:]}")
    log = subprocess.run(
        [sys.executable, "-m", "anunnaki.cli.main", "log", str(kb), "--json"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    simulated = json.loads(report.read_text())["duration"]
    return {
        "wall_s": round(wall, 2),
        "simulated_s": simulated,
        "sim_per_wall": round(simulated / wall, 3),
        "report_sha256": hashlib.sha256(report.read_bytes()).hexdigest(),
        "log_sha256": hashlib.sha256(log.encode()).hexdigest(),
        "decisions": len(log.splitlines()),
        "load": [round(x, 2) for x in os.getloadavg()],
    }


def measure(name: str, runs: int, until: float | None = None) -> dict[str, Any]:
    """``runs`` runs of case ``name`` (``until``: its own length); the 2nd beside a busy process."""
    launch, length = CASES[name]
    until = length if until is None else until
    out: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="determinism-") as tmp:
        folder = Path(tmp)
        for k in range(runs):
            loaded = k == 1
            busy = subprocess.Popen([sys.executable, "-c", "while True: pass"]) if loaded else None
            try:
                row = _run(launch, until, folder, k)
            finally:
                if busy is not None:
                    busy.kill()
                    busy.wait()
            row["beside_busy"] = loaded
            out.append(row)
            print(f"  {name} run {k + 1}: {row}", flush=True)
        replay = subprocess.run(
            [sys.executable, "-m", "anunnaki.cli.main", "replay", str(folder / "run0.db")],
            capture_output=True,
            text=True,
            check=False,
        )
    return {
        "launch": launch,
        "until": until,
        "runs": out,
        "identical_reports": len({r["report_sha256"] for r in out}) == 1,
        "identical_logs": len({r["log_sha256"] for r in out}) == 1,
        "replay_exit_code": replay.returncode,
        "replay": replay.stdout.strip().splitlines()[-1:] or replay.stderr.strip()[-300:],
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="rover,uav", help="comma-separated: rover, uav")
    ap.add_argument("--runs", type=int, default=3, help="runs per case (the 2nd is loaded)")
    ap.add_argument("--until", type=float, help="simulated seconds of every case (default: each's)")
    ap.add_argument("--output", type=Path, default=RESULTS, help="the JSON written")
    ap.add_argument(
        "--case-studies", action="store_true", help="the managers benchmark's tables instead"
    )
    ap.add_argument("--seeds", type=int, default=2, help="--case-studies: seeds per manager")
    args = ap.parse_args(argv)
    if args.runs < 2:
        ap.error("--runs must be at least 2: one run cannot repeat itself")
    if args.until is not None and args.until <= 0:
        ap.error(f"--until must be positive, got {args.until:g}")
    names = [c for c in args.cases.split(",") if c]
    unknown = [c for c in names if c not in CASES]
    if unknown:
        ap.error(f"unknown case(s) {unknown}: choose from {sorted(CASES)}")
    out: Path = args.output
    doc = json.loads(out.read_text()) if out.is_file() else {"cases": {}}
    if args.case_studies:
        doc["case_studies"] = cs = case_studies(args.seeds)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(doc, indent=1) + "\n")
        print(f"case studies: tables identical {cs['identical_tables']}", flush=True)
        return 0 if cs["identical_tables"] else 1
    doc.update(
        benchmark="determinism",
        date=time.strftime("%Y-%m-%d %H:%M:%S"),
        machine={"python": platform.python_version(), "cpus": os.cpu_count()},
    )
    for name in names:
        print(f"{name}: {args.runs} runs", flush=True)
        doc["cases"][name] = measure(name, args.runs, args.until)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(doc, indent=1) + "\n")
        c = doc["cases"][name]
        print(
            f"{name}: reports identical {c['identical_reports']}, decision logs identical "
            f"{c['identical_logs']}, replay exit {c['replay_exit_code']}",
            flush=True,
        )
    ok = all(
        c["identical_reports"] and c["identical_logs"] and c["replay_exit_code"] == 0
        for n, c in doc["cases"].items()
        if n in names
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
