"""Every malformed or hostile tactics file is refused with a located ModelFileError.

Each ``tests/data/bad/tactics/<name>`` sits next to ``<name>.expected``, whose non-empty lines
must all appear in the error message (``file:line: element: message (hint: …)``).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from anunnaki.errors import ModelFileError
from anunnaki.tactics import load_tactics

BAD = Path(__file__).resolve().parents[1] / "data" / "bad" / "tactics"
CASES = sorted(p for p in BAD.iterdir() if p.suffix != ".expected")


def test_the_corpus_is_complete() -> None:
    assert len(CASES) >= 12
    for case in CASES:
        assert case.with_name(case.name + ".expected").is_file(), case.name
    for expected in BAD.glob("*.expected"):
        assert expected.with_suffix("").is_file(), expected.name


@pytest.mark.parametrize("case", CASES, ids=[p.name for p in CASES])
def test_bad_file_is_refused_with_a_located_error(case: Path) -> None:
    expected = [
        line
        for line in case.with_name(case.name + ".expected").read_text("utf-8").splitlines()
        if line.strip()
    ]
    with pytest.raises(ModelFileError) as info:
        load_tactics(case)
    message = str(info.value)
    assert message.startswith(str(case)), message
    assert info.value.line is not None, message
    for text in expected:
        assert text in message, f"{text!r} not in {message!r}"
