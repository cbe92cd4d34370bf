"""``anunnaki assurance build | check``: a launch's assurance case (docs/assurance.md).

``build LAUNCH.yaml --out case/`` argues the launch's goal model in GSN and develops each
claim with the project's own measurements (the criteria file ``assurance.yaml`` beside the
launch says which), then writes case.json, case.gsn.yaml (gsn2x), case.svg and case.html.
When ``--out`` already holds a case, a figure whose measurement is unchanged while an
artefact it rests on changed is stale. ``check case/`` hashes every artefact again and
names what changed.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from anunnaki.cli._text import plain

__all__ = ["add_parser"]


def add_parser(sub: Any) -> None:
    """Register ``assurance`` and its sub-commands."""
    p: argparse.ArgumentParser = sub.add_parser(
        "assurance",
        help="an assurance case from the goal model and measured evidence: build, check",
        description=plain(__doc__),
    )
    asub = p.add_subparsers(dest="assurance_command", metavar="SUBCOMMAND")
    asub.required = True
    b: argparse.ArgumentParser = asub.add_parser(
        "build",
        help="build the case of a launch file (case.json, .gsn.yaml, .svg, .html)",
        description=(
            "Argue the launch's goal model in GSN and develop every claim with the "
            "measurements the criteria file names; write case.json, case.gsn.yaml (the "
            "layout gsn2x reads), case.svg and case.html into --out. Exit 0 when the "
            "top-level claim is supported, 1 when it is not (undeveloped, unverified, stale "
            "or failed: the case is written either way), 2 on a bad file."
        ),
    )
    b.add_argument("launch", help="launch file (anunnaki: launch/1)")
    b.add_argument("--out", required=True, help="folder to write the case into")
    b.add_argument(
        "--criteria",
        help="criteria file (anunnaki: assurance/1; default: assurance.yaml beside the launch)",
    )
    b.add_argument(
        "--root",
        help="project root the criteria's paths are relative to (default: the working folder)",
    )
    b.add_argument(
        "--run-tests",
        action="store_true",
        help="run the tests the criteria name (one pytest process) and record their outcome; "
        "otherwise they are 'not run' and support nothing",
    )
    b.add_argument(
        "--fresh",
        action="store_true",
        help="ignore a case already in --out (no comparison with it)",
    )
    b.set_defaults(run=_build)
    c: argparse.ArgumentParser = asub.add_parser(
        "check",
        help="hash a case's artefacts again; exit 1 when any changed (stale)",
        description=(
            "Hash every artefact the case's evidence rests on again. Each one that changed "
            "or is gone makes its evidence stale: printed with the claims that lose their "
            "support, and written back into the case with --update. Exit 0 when nothing "
            "changed, 1 when something did, 2 when the case cannot be read."
        ),
    )
    c.add_argument("case", help="a folder 'assurance build' wrote (or its case.json)")
    c.add_argument("--root", help="where the artefacts lie (default: the root it was built from)")
    c.add_argument(
        "--update", action="store_true", help="rewrite the case's files with the stale marks"
    )
    c.set_defaults(run=_check)


def _build(args: argparse.Namespace) -> int:
    from pathlib import Path

    from anunnaki.assurance import build_case, read_case, write_case

    prior = None
    if not args.fresh and (Path(args.out) / "case.json").is_file():
        prior = read_case(args.out)
    case = build_case(
        args.launch, criteria=args.criteria, root=args.root, tests=args.run_tests, prior=prior
    )
    files = write_case(case, args.out)
    cov = case.coverage()
    share = "—" if cov["share"] is None else f"{100 * cov['share']:.0f} %"
    print(
        f"{case.name}: top-level claim {case.root} {case.nodes[case.root].status}; "
        f"{cov['supported']} of {cov['leaf_goals']} leaf goals supported ({share}); "
        f"{cov['solutions']} evidence items {cov['solutions_by_status']}; "
        f"built in {case.build_seconds:.2f} s"
    )
    for note in case.notes:
        print(f"  note: {note}")
    for status, ids in cov["by_status"].items():
        if status != "supported":
            print(f"  {status}: {', '.join(ids)}")
    for n in case.solutions():
        if n.evidence is not None and n.evidence.stale:
            print(f"  stale {n.id}: {n.evidence.stale}")
    print(f"wrote {', '.join(str(f) for f in files.values())}")
    return 0 if case.nodes[case.root].status == "supported" else 1


def _check(args: argparse.Namespace) -> int:
    from anunnaki.assurance import check_case, read_case, write_case

    case = read_case(args.case)
    before = {n.id: n.status for n in case}
    changes = check_case(case, args.root)
    if not changes:
        print(
            f"{case.name}: every artefact is as recorded ({len(case.solutions())} evidence items)"
        )
        return 0
    for ch in changes:
        now = "gone" if ch.now is None else f"now {ch.now[:12]}…"
        what = "the argument" if ch.node == "(argument)" else f"stale {ch.node}"
        print(f"{what}: {ch.role} {ch.path} was {ch.recorded[:12]}…, {now}")
    if any(ch.node == "(argument)" for ch in changes):
        print(f"the argument was built from files that changed: build it again ({case.launch})")
    lost = [n.id for n in case if before.get(n.id) == "supported" and n.status != "supported"]
    if lost:
        print(f"claims no longer supported: {', '.join(lost)}")
    if args.update:
        from pathlib import Path

        folder = Path(args.case)
        write_case(case, folder if folder.is_dir() else folder.parent)
    sys.stdout.flush()
    return 1
