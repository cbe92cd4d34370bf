"""Error messages: pydantic's wording never reaches the user ("Value error, …")."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from pydantic import BaseModel, ValidationError, field_validator

from anunnaki._safeyaml import load_yaml, validation_error
from anunnaki.errors import validation_message

SRC = Path(__file__).parents[1] / "src" / "anunnaki"


class Doc(BaseModel):
    name: str
    count: int = 1

    @field_validator("name")
    @classmethod
    def _known(cls, value: str) -> str:
        if value != "fog":
            raise ValueError(f"unknown phenomenon {value!r}")
        return value


def errors_of(data: object) -> list[dict[str, object]]:
    with pytest.raises(ValidationError) as err:
        Doc.model_validate(data)
    return list(err.value.errors(include_url=False))  # type: ignore[arg-type]


def test_a_validators_own_words_come_through_without_pydantics() -> None:
    (unknown,) = errors_of({"name": "smog"})
    assert str(unknown["msg"]).startswith("Value error, ")  # what pydantic says
    assert validation_message(unknown) == "unknown phenomenon 'smog'"
    assert validation_message({"msg": "Assertion failed, give a count above 0"}) == (
        "give a count above 0"
    )
    (plain,) = errors_of({"name": 5})
    assert validation_message(plain) == "Input should be a valid string"


def test_located_errors_of_user_files_have_no_value_error_prefix(tmp_path: Path) -> None:
    path = tmp_path / "doc.yaml"
    path.write_text("count: 2\nname: smog\n")
    data, lines = load_yaml(path)
    with pytest.raises(ValidationError) as err:
        Doc.model_validate(data)
    exc = validation_error(err.value, data, lines, path)
    assert exc.render() == f"{path}:2: name: unknown phenomenon 'smog'"


def test_every_message_built_from_a_pydantic_error_goes_through_validation_message() -> None:
    # one place words a pydantic error; reading its 'msg' anywhere else would leak
    # "Value error," again
    reads = re.compile(r"""\[\s*['"]msg['"]\s*\]""")
    offenders = [
        f"{p.relative_to(SRC)}:{i}"
        for p in sorted(SRC.rglob("*.py"))
        if p.name != "errors.py"
        for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
        if reads.search(line)
    ]
    assert offenders == []
