"""The assurance cases of the rover and the UAV: evidence coverage and build time.

For each case study (``examples/rover/demo.yaml``, ``examples/uav/sim.yaml``, with the
criteria files beside them):

* **evidence coverage**: the share of the goal model's leaf goals whose evidence supports
  them, with the leaf goals by status and the evidence items by status — once without the
  tests (they are then ``not run`` and support nothing) and once with ``--run-tests``;
* **build time** from the existing results: ``anunnaki assurance build`` end to end in a
  fresh process (interpreter start, imports, the launch's loader, reading and hashing every
  artefact, the four files written), the median of ``--repeats`` runs, and the in-process
  build alone (:func:`anunnaki.assurance.build_case`'s own ``build_seconds``). Aim ≤ 10 s.

Writes ``benchmarks/results/assurance.json``::

    .venv/bin/python benchmarks/assurance.py            # 5 runs per case (about 30 s)
    .venv/bin/python benchmarks/assurance.py --quick    # 1 run, no tests

``--ship DIR`` measures nothing: it writes both cases (case.json, case.gsn.yaml, case.svg,
case.html) into ``DIR/rover`` and ``DIR/uav`` without a build time or date, so the same
inputs give the same bytes — what ``make results`` commits as ``docs/assurance/`` (the tests
named in the criteria are not run: they show as unverified)::

    .venv/bin/python benchmarks/assurance.py --ship docs/assurance
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from anunnaki.assurance import build_case, write_case  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results" / "assurance.json"
CASES = {"rover": "examples/rover/demo.yaml", "uav": "examples/uav/sim.yaml"}
AIM_BUILD_S = 10.0


def _cli(launch: str, out: Path) -> float:
    started = time.perf_counter()
    subprocess.run(
        [
            sys.executable,
            "-m",
            "anunnaki",
            "assurance",
            "build",
            launch,
            "--out",
            str(out),
            "--fresh",
        ],
        cwd=ROOT,
        capture_output=True,
        check=False,
    )
    return time.perf_counter() - started


def measure(name: str, launch: str, repeats: int, tests: bool) -> dict[str, Any]:
    """One case study's coverage and build times."""
    case = build_case(ROOT / launch, root=ROOT)
    in_process = [case.build_seconds or 0.0]
    for _ in range(repeats - 1):
        in_process.append(build_case(ROOT / launch, root=ROOT).build_seconds or 0.0)
    with tempfile.TemporaryDirectory() as tmp:
        cli = [_cli(launch, Path(tmp) / name) for _ in range(repeats)]
    row: dict[str, Any] = {
        "launch": launch,
        "criteria": str(Path(launch).parent / "assurance.yaml"),
        "coverage": case.coverage(),
        "build_s": {
            "cli_median": round(statistics.median(cli), 3),
            "cli_max": round(max(cli), 3),
            "in_process_median": round(statistics.median(in_process), 3),
            "runs": repeats,
        },
    }
    if tests:
        started = time.perf_counter()
        with_tests = build_case(ROOT / launch, root=ROOT, tests=True)
        row["with_tests"] = {
            "coverage": with_tests.coverage(),
            "build_s": round(time.perf_counter() - started, 3),
        }
    return row


def ship(folder: Path) -> dict[str, Path]:
    """Write both cases, reproducibly, into ``folder/<name>``; returns the folders."""
    out = {}
    for name, launch in CASES.items():
        case = build_case(ROOT / launch, root=ROOT).reproducible()
        write_case(case, folder / name)
        cov = case.coverage()
        print(
            f"{name}: top-level claim {case.root} {case.nodes[case.root].status}; "
            f"{cov['supported']} of {cov['leaf_goals']} leaf goals supported -> {folder / name}"
        )
        out[name] = folder / name
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5, help="builds per case (5)")
    ap.add_argument("--no-tests", dest="tests", action="store_false", help="skip --run-tests")
    ap.add_argument("--quick", action="store_true", help="one build per case, no tests")
    ap.add_argument("--output", type=Path, default=RESULTS)
    ap.add_argument("--ship", type=Path, metavar="DIR", help="write both cases into DIR, only")
    args = ap.parse_args(argv)
    if args.ship is not None:
        ship(args.ship)
        return 0
    repeats = 1 if args.quick else max(1, args.repeats)
    tests = args.tests and not args.quick
    load = list(os.getloadavg())
    cases = {name: measure(name, launch, repeats, tests) for name, launch in CASES.items()}
    median = max(c["build_s"]["cli_median"] for c in cases.values())
    worst = max(c["build_s"]["cli_max"] for c in cases.values())
    doc = {
        "benchmark": "assurance",
        "date": dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M:%S"),
        "machine": {
            "python": platform.python_version(),
            "cpus": os.cpu_count(),
            "load_average_before": load,
            "load_average_after": list(os.getloadavg()),
        },
        "settings": {"repeats": repeats, "tests": tests, "quick": args.quick},
        "aims": {
            "build_s": {
                "aim": AIM_BUILD_S,
                "value": median,
                "of": "the slower case's median CLI build",
                "slowest_run": worst,
                "met": median <= AIM_BUILD_S,
            }
        },
        "cases": cases,
    }
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    for name, c in cases.items():
        cov = c["coverage"]
        line = (
            f"{name}: {cov['supported']} of {cov['leaf_goals']} leaf goals supported "
            f"({cov['share']}); top {cov['root']}; build {c['build_s']['cli_median']} s (CLI), "
            f"{c['build_s']['in_process_median']} s (in process)"
        )
        if "with_tests" in c:
            wt = c["with_tests"]["coverage"]
            line += f"; with tests {wt['supported']} of {wt['leaf_goals']} ({wt['share']})"
        print(line)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
