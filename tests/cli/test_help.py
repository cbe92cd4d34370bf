"""Every command's ``--help`` is plain text: no reStructuredText from the docstrings."""

from __future__ import annotations

import argparse
import re
from collections.abc import Iterator

import pytest

from anunnaki.cli.main import build_parser

#: Markup that means nothing in a terminal: literals, roles, links, bold, any backtick.
MARKUP = re.compile(r"``|:[A-Za-z]+:`|`_|\*\*|`")


def _parsers(
    parser: argparse.ArgumentParser, path: tuple[str, ...]
) -> Iterator[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _parsers(sub, (*path, name))


def test_every_help_is_plain_text(monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 34 item 11: robustify, oracle and reload --help showed ``…`` and roles."""
    monkeypatch.setenv("COLUMNS", "100")
    seen, offenders = [], []
    for path, parser in _parsers(build_parser(), ("anunnaki",)):
        seen.append(" ".join(path))
        for n, line in enumerate(parser.format_help().splitlines(), 1):
            if MARKUP.search(line):
                offenders.append(f"{' '.join(path)} --help, line {n}: {line.strip()}")
    assert offenders == []
    # the walk reaches the sub-commands' own sub-commands
    assert {"anunnaki robustify", "anunnaki oracle train", "anunnaki oracle evaluate",
            "anunnaki reload", "anunnaki log"} <= set(seen)  # fmt: skip
    assert len(seen) > 15


@pytest.mark.parametrize(
    ("rst", "text"),
    [
        ("``anunnaki reload``: swap", "anunnaki reload: swap"),
        ("see :func:`~anunnaki.lec.load_detector`", "see load_detector"),
        ("see :class:`anunnaki.lec.ModelRegistry`", "see anunnaki.lec.ModelRegistry"),
        ("a :py:meth:`the load <anunnaki.lec.ModelRegistry.load>`", "a the load"),
        ("read `the docs <https://x.org>`_ now", "read the docs now"),
        ("``--models\n[REGISTRY.yaml]`` asks", "--models\n[REGISTRY.yaml] asks"),
        ("plain text stays", "plain text stays"),
    ],
)
def test_plain_drops_the_markup_and_keeps_the_text(rst: str, text: str) -> None:
    from anunnaki.cli._text import plain

    assert plain(rst) == text
    assert plain(None) == ""
