"""``anunnaki check MODEL [BINDING] [TACTICS]``: static checks with file:line messages.

``anunnaki check LAUNCH`` checks the goal model, binding and tactics a launch file names,
with the modes its managed system declares; ``--platform rover|uav`` checks the tactics'
modes against a simulated platform's.
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
from anunnaki.errors import ModelFileError


def add_parser(sub: Any) -> None:
    """Register the sub-command."""
    p: argparse.ArgumentParser = sub.add_parser(
        "check",
        help="check a goal model, its binding and tactics; exit 0 clean, 1 findings, 2 unreadable",
        description=(
            "Static checks of a goal model with an optional platform binding and tactics file "
            "(recognised by their 'anunnaki:' tag or the .xml extension). Each finding names "
            "file, line and element. Exit 0 clean, 1 findings, 2 a file is unreadable."
        ),
    )
    p.add_argument("model", help="goal-model YAML file, or a launch file (anunnaki: launch/1)")
    p.add_argument("files", nargs="*", metavar="BINDING|TACTICS", help="binding and/or tactics")
    p.add_argument("--binding", "-b", help="platform-binding file (instead of positional)")
    p.add_argument("--tactics", help="tactics file, XML or YAML (instead of positional)")
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
        console.print(Text("a file could not be read", style="bold red"))
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
        console.print(Text(f"ok: {'; '.join(parts)}", style="green"))
    else:
        console.print(f"{n_err} error(s), {n_warn} warning(s)")
    return result.exit_code


def _check(args: argparse.Namespace) -> CheckResult:
    """Check the files given, or those a launch file names (with its platform's modes)."""
    modes = _simulated(args.platform) if args.platform else None
    if not _is_launch(args.model):
        return check_files(
            args.model, *args.files, binding=args.binding, tactics=args.tactics, modes=modes
        )
    from anunnaki.launch import load_launch

    try:
        launch = load_launch(args.model, read_records=False)
    except ModelFileError as exc:
        return CheckResult(findings=[Finding.from_error(exc)], unreadable=True)
    utu = launch.utu
    if modes is None and launch.managed is not None:
        modes = _managed_modes(launch.managed, args.model)
    return check_files(
        utu.goal_model,
        binding=args.binding or utu.binding,
        tactics=args.tactics or utu.tactics,
        modes=modes,
    )


_LAUNCH_TAG = re.compile(r"""^anunnaki:[ \t]*['"]?launch/1\b""", re.MULTILINE)


def _is_launch(path: str) -> bool:
    """Whether *path* is a launch file (its format tag); unreadable files are not."""
    try:
        with Path(path).open("rb") as fh:
            head = fh.read(4096).decode("utf-8", errors="replace")
    except OSError:
        return False  # check_files says why
    return _LAUNCH_TAG.search(head) is not None


def _simulated(platform: str) -> PlatformModes:
    from anunnaki.sim import PLATFORM_MODES

    cls = {"rover": "RoverSim", "uav": "UavSim"}[platform]
    return PlatformModes(platform, PLATFORM_MODES[platform], f"anunnaki.sim.{cls}.modes")


def _managed_modes(managed: Any, launch: str) -> PlatformModes | None:
    """The modes a launch's managed system declares: a simulated platform's, or its option."""
    options = getattr(managed, "options", None)
    scenario = getattr(options, "scenario", None)
    if getattr(managed, "name", None) == "sim" and scenario is not None:
        from anunnaki.sim import load_scenario

        try:
            return _simulated(load_scenario(scenario).platform)
        except (ModelFileError, KeyError):
            return None  # the run reports the scenario; the files are still checked
    declared = getattr(options, "modes", None)
    if declared:
        name = getattr(managed, "name", "managed")
        return PlatformModes(name, tuple(declared), f"{launch}: managed.{name}.modes")
    return None
