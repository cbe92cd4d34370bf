"""``anunnaki check MODEL [BINDING] [TACTICS]`` or ``anunnaki check LAUNCH``: static checks.

``anunnaki check LAUNCH`` checks everything ``anunnaki run LAUNCH`` would load, with the
loader ``run`` uses (:func:`anunnaki.launch.check_launch`), and starts nothing;
``--platform rover|uav`` checks the tactics' modes against a simulated platform's.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.text import Text

from anunnaki._findings import Finding
from anunnaki.check import CheckResult, PlatformModes, check_files

_EXIT_CODES = (
    "Exit codes: 0 nothing found; 1 findings (errors or warnings) in what was checked, a file "
    "that is not valid YAML or does not fit its format included; 2 nothing could be checked: "
    "a usage error, or a file named on the command line cannot be read at all (missing, a "
    "folder, not UTF-8 text, too large) or is of no kind check knows."
)


def add_parser(sub: Any) -> None:
    """Register the sub-command."""
    p: argparse.ArgumentParser = sub.add_parser(
        "check",
        help="check a goal model, binding and tactics, or everything a launch file loads; "
        "exit 0 clean, 1 findings, 2 cannot check",
        description=(
            "Static checks, each finding with file, line and element. Given a goal model, "
            "with an optional platform binding and tactics file (recognised by their "
            "'anunnaki:' tag or the .xml extension): the three files. Given a launch file "
            "(anunnaki: launch/1): everything 'anunnaki run' would load, with the code run "
            "loads it with: the Utu configuration, bus and notify settings, the goal model, "
            "binding and tactics, the fail-safe, the managed system's files (scenario and its "
            "phenomena, model registry with its models' and oracles' files, oracle names, "
            "trace or bridge) and the tactics' model swaps against the registry; nothing is "
            "started and no weights are loaded."
        ),
        epilog=_EXIT_CODES,
    )
    p.add_argument(
        "model",
        help="goal-model YAML file, or what 'anunnaki run' takes: a launch file "
        "(anunnaki: launch/1) or a Utu configuration (utu/1)",
    )
    p.add_argument("files", nargs="*", metavar="BINDING|TACTICS", help="binding and/or tactics")
    p.add_argument(
        "--binding",
        "-b",
        help="platform-binding file (instead of positional; with a launch file, instead of "
        "the one it names)",
    )
    p.add_argument(
        "--tactics",
        help="tactics file, XML or YAML (instead of positional; with a launch file, instead "
        "of the one it names)",
    )
    p.add_argument(
        "--platform",
        choices=["rover", "uav"],
        help="check the modes the tactics request against this simulated platform's "
        "(a launch file's managed system says its own)",
    )
    p.add_argument("--json", action="store_true", help="print findings as JSON")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run the checks and print the findings."""
    if len(args.files) > 2:
        print("error: give at most a binding and a tactics file", file=sys.stderr)
        return 2
    result = _check(args)
    if args.json:
        out = {
            "exit_code": result.exit_code,
            "findings": [
                {
                    "severity": f.severity,
                    "message": f.message,
                    "path": f.path,
                    "line": f.line,
                    "element": f.element,
                    "hint": f.hint,
                }
                for f in result.findings
            ],
        }
        sys.stdout.write(json.dumps(out, indent=2) + "\n")
        return result.exit_code
    console = Console(highlight=False, soft_wrap=True, stderr=False)
    for f in result.findings:
        style = "bold red" if f.severity == "error" else "yellow"
        console.print(Text(f.render(), style=style))
    n_err, n_warn = len(result.errors), len(result.warnings)
    if result.unreadable:
        console.print(Text("nothing checked: a file could not be read", style="bold red"))
    elif not result.findings:
        model = result.model
        parts = (
            [
                f"{len(model.goals)} goals, {len(model.obstacles)} obstacles, "
                f"{len(model.agents)} agents"
            ]
            if model
            else []
        )
        if result.tactics is not None:
            parts.append(f"{len(result.tactics.tactics)} tactics")
        parts.extend(result.checked)
        console.print(Text(f"ok: {'; '.join(parts)}", style="green"))
    else:
        console.print(f"{n_err} error(s), {n_warn} warning(s)")
    return result.exit_code


def _check(args: argparse.Namespace) -> CheckResult:
    """Check the files given, or everything a launch file names (with its platform's modes)."""
    modes = _simulated(args.platform) if args.platform else None
    if _tag_of(args.model) == "assurance/1":
        if args.files or args.binding or args.tactics:
            return CheckResult(
                findings=[
                    Finding(
                        "error",
                        "an assurance criteria file is checked alone",
                        args.model,
                        hint="drop the other files: the criteria name their goal model "
                        "(goal_model:)",
                    )
                ],
                unreadable=True,
            )
        return _check_criteria(Path(args.model))
    if not _is_launch(args.model):
        return check_files(
            args.model, *args.files, binding=args.binding, tactics=args.tactics, modes=modes
        )
    from anunnaki.launch import check_launch

    if args.files:  # the launch names its binding and tactics; --binding/--tactics replace them
        return CheckResult(
            findings=[
                Finding(
                    "error",
                    "a launch file names its own binding and tactics",
                    args.files[0],
                    hint="check the launch file alone, or replace one with --binding/--tactics",
                )
            ],
            unreadable=True,
        )
    return check_launch(args.model, binding=args.binding, tactics=args.tactics, modes=modes)


_TAG = re.compile(r"""^anunnaki:[ \t]*['"]?([a-z-]+/\d+)\b""", re.MULTILINE)


def _tag_of(path: str) -> str | None:
    """The format tag (``anunnaki: KIND/N``) in the first 4 KiB of *path*, if any."""
    try:
        with Path(path).open("rb") as fh:
            head = fh.read(4096).decode("utf-8", errors="replace")
    except OSError:
        return None  # check_files says why
    found = _TAG.search(head)
    return found.group(1) if found else None


def _is_launch(path: str) -> bool:
    """Whether *path* is what ``run`` takes: a launch file or a Utu configuration (its tag)."""
    return _tag_of(path) in ("launch/1", "utu/1")


def _check_criteria(path: Path) -> CheckResult:
    """Check an assurance criteria file (``assurance/1``).

    Its format, and that every claim it develops is a goal or obstacle of the goal model it
    names (``goal_model:``, relative to the file).
    """
    from anunnaki._safeyaml import load_yaml
    from anunnaki.assurance import parse_criteria
    from anunnaki.errors import ModelFileError
    from anunnaki.goals import did_you_mean, load_goal_model

    result = CheckResult()
    try:
        data, lines = load_yaml(path)
        crit = parse_criteria(data, source=str(path), lines=lines)
    except ModelFileError as exc:
        result.findings.append(Finding.from_error(exc))
        return result
    items = sum(len(v) for v in crit.evidence.values())
    result.checked.append(f"{items} evidence items for {len(crit.evidence)} claims")
    if crit.goal_model is None:
        result.findings.append(
            Finding(
                "warning",
                "no goal_model: the claims it develops are not checked",
                str(path),
                element="goal_model",
                hint="name the goal model this file develops, relative to it",
            )
        )
        return result
    model_path = path.parent / crit.goal_model
    try:
        model = load_goal_model(model_path, None, strict=False)
    except ModelFileError as exc:
        result.findings.append(Finding.from_error(exc))
        return result
    result.model = model
    known = {**dict.fromkeys(model.goals), **dict.fromkeys(model.obstacles)}
    for key in crit.evidence:
        if key not in known:
            result.findings.append(
                Finding(
                    "error",
                    f"evidence for {key!r}: no goal or obstacle of {crit.goal_model} has that id",
                    str(path),
                    line=lines.line(("evidence", key)),
                    element=f"evidence.{key}",
                    hint=did_you_mean(key, known),
                )
            )
    return result


def _simulated(platform: str) -> PlatformModes:
    from anunnaki.sim import PLATFORM_MODES

    cls = {"rover": "RoverSim", "uav": "UavSim"}[platform]
    return PlatformModes(platform, PLATFORM_MODES[platform], f"anunnaki.sim.{cls}.modes")
