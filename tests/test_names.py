"""anunnaki._names: the one rule for names that become parts of paths, and writes kept inside."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from anunnaki._names import (
    DOMAIN_RULE,
    NAME_RULE,
    NameRuleError,
    check_domain,
    check_name,
    inside,
)
from anunnaki.errors import AnunnakiError

#: Names that would put a file elsewhere than their folder, or are no file name at all.
BAD_NAMES = [
    "",
    ".",
    "..",
    "../x",
    "fog/../x y",
    "a/b",
    "a\\b",
    "/etc/passwd",
    "C:\\x",
    "x\x00y",
    "x y",
    ".hidden",
    "-rf",
    "x\n",
    "a" * 129,
]


@pytest.mark.parametrize("bad", BAD_NAMES)
def test_a_name_that_could_leave_its_folder_is_refused(bad: str) -> None:
    with pytest.raises(NameRuleError) as info:
        check_name(bad, what="--id")
    text = str(info.value)
    assert text.startswith(f"--id {bad!r} is not allowed: ") and NAME_RULE in text
    assert isinstance(info.value, AnunnakiError) and isinstance(info.value, ValueError)


@pytest.mark.parametrize("good", ["rover-fog", "uav-rain_brightness", "m", "rover-fog-enki.v2",
                                  "0", "a" * 128])  # fmt: skip
def test_names_that_follow_the_rule_pass_unchanged(good: str) -> None:
    assert check_name(good, what="model id") == good


def test_the_message_suggests_a_name_that_follows_the_rule() -> None:
    with pytest.raises(NameRuleError, match=r"e\.g\. 'fog_.._x_y'"):
        check_name("fog/../x y", what="model id")
    with pytest.raises(NameRuleError, match=r"give --id NAME"):
        check_name("a/b", what="model id", fix="give --id NAME")
    with pytest.raises(NameRuleError, match=r"model id int 3 is not allowed"):
        check_name(3, what="model id")


@pytest.mark.parametrize("bad", [*BAD_NAMES, "heavy-fog", "fog.v2", "1fog", "a" * 65])
def test_a_domain_is_a_name_and_an_identifier(bad: str) -> None:
    with pytest.raises(NameRuleError) as info:
        check_domain(bad, what="--domain")
    assert str(info.value).startswith(f"--domain {bad!r} is not allowed: {DOMAIN_RULE}")


def test_domains_that_follow_the_rule_pass() -> None:
    for good in ("default", "fog", "low_light", "rain_brightness", "_x"):
        assert check_domain(good) == check_name(good, what="domain") == good
    with pytest.raises(NameRuleError, match=r"e\.g\. 'fog_x_y'"):
        check_domain("fog/../x y")


def test_inside_refuses_a_write_outside_its_folder(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    assert inside(out, out / "m.safetensors", what="model file") == out / "m.safetensors"
    assert inside(out, out / "sub" / "x.json", what="file") == out / "sub" / "x.json"
    for escape in (out / ".." / "x", Path("/tmp/elsewhere"), tmp_path / "outside"):
        with pytest.raises(NameRuleError, match="would be written outside its folder"):
            inside(out, escape, what="model file")
    (out / "link").symlink_to(tmp_path)  # a symlink out of the folder counts as outside
    with pytest.raises(NameRuleError, match="resolves to"):
        inside(out, out / "link" / "x", what="model file")
    cwd = os.getcwd()
    try:
        os.chdir(out)
        assert inside(".", "m.safetensors", what="model file") == Path("m.safetensors")
    finally:
        os.chdir(cwd)
