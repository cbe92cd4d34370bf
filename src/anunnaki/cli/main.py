"""The ``anunnaki`` command line.

Sub-commands are small modules in this package; each adds its parser and a ``run(args)``
that returns the exit code. Errors about user files print as ``file:line: element: message``
and exit with 2; a traceback is a bug.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from anunnaki import __version__
from anunnaki.cli import _heap
from anunnaki.errors import AnunnakiError

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser with every sub-command."""
    from anunnaki.cli import (
        _assess,
        _assurance,
        _check,
        _dashboard,
        _detector,
        _evaluate,
        _log,
        _oracle,
        _reload,
        _robustify,
        _run,
        _sim,
    )

    parser = argparse.ArgumentParser(
        prog="anunnaki",
        description="Keep learning-enabled systems trustworthy at run time.",
    )
    parser.add_argument("--version", action="version", version=f"anunnaki {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    _assess.add_parser(sub)
    _assurance.add_parser(sub)
    _check.add_parser(sub)
    _dashboard.add_parser(sub)
    _detector.add_parser(sub)
    _evaluate.add_parser(sub)
    _log.add_parser(sub)
    _oracle.add_parser(sub)
    _reload.add_parser(sub)
    _robustify.add_parser(sub)
    _run.add_parser(sub)
    _sim.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code.

    The garbage collector is paused while the command brings itself up (:mod:`._heap`): a
    command that sets ``settles_heap`` resumes it itself once it is up (``anunnaki run``),
    the others as soon as the command line is parsed.
    """
    _heap.pause()
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        if not getattr(args, "settles_heap", False):
            _heap.end(unfreeze=False)
        return _run_command(args)
    finally:
        # the process's own command line (argv from sys.argv) exits next: keep it frozen
        _heap.end(unfreeze=argv is not None)


def _run_command(args: argparse.Namespace) -> int:
    try:
        code: int = args.run(args)
    except AnunnakiError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # output piped into `head`
        return 0
    return code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
