"""``anunnaki check MODEL [BINDING] [TACTICS]``: static checks with file:line messages."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from rich.console import Console
from rich.text import Text

from anunnaki.check import check_files


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
    p.add_argument("model", help="goal-model YAML file")
    p.add_argument("files", nargs="*", metavar="BINDING|TACTICS", help="binding and/or tactics")
    p.add_argument("--binding", "-b", help="platform-binding file (instead of positional)")
    p.add_argument("--tactics", help="tactics file, XML or YAML (instead of positional)")
    p.add_argument("--json", action="store_true", help="print findings as JSON")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run the checks and print the findings."""
    if len(args.files) > 2:
        print("error: give at most a binding and a tactics file", file=sys.stderr)
        return 2
    result = check_files(args.model, *args.files, binding=args.binding, tactics=args.tactics)
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
