"""The safe YAML loader every user file goes through: what it refuses, and where it says so."""

from __future__ import annotations

from pathlib import Path

import pytest

from anunnaki._safeyaml import (
    MAX_DEPTH,
    LineMap,
    describe_path,
    element_path,
    load_yaml,
    read_text_limited,
)
from anunnaki.errors import ModelFileError


def refused(text: str, **kw: int) -> ModelFileError:
    with pytest.raises(ModelFileError) as info:
        load_yaml("m.yaml", text=text, **kw)
    return info.value


# -- what is refused --------------------------------------------------------------------


def test_anchors_and_aliases_are_refused() -> None:
    err = refused("a: &x 1\nb: 2\n")
    assert (err.line, err.message) == (1, "YAML anchor '&x' is not allowed")
    err = refused("a: [1, 2]\nb: *x\n")
    assert (err.line, err.message) == (2, "YAML alias '*x' is not allowed")
    assert "anchors and aliases are refused" in str(err)


def test_a_billion_laughs_is_refused_before_any_expansion() -> None:
    lines = ["a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    lines += [f"a{i}: &a{i} [*a{i - 1}, *a{i - 1}, *a{i - 1}]" for i in range(1, 10)]
    err = refused("\n".join(lines) + "\n")
    assert err.message == "YAML anchor '&a0' is not allowed"


@pytest.mark.parametrize(
    ("text", "tag"),
    [
        ("a: !!python/object:os.system {}\n", "tag:yaml.org,2002:python/object:os.system"),
        ("a: !!python/object/apply:os.system [ls]\n", "python/object/apply:os.system"),
        ("a: !!binary aGVsbG8=\n", "tag:yaml.org,2002:binary"),
        ("a: !custom bar\n", "'!custom'"),
        ("a: !custom {b: 1}\n", "'!custom'"),
        ("a: !!set {b}\n", "tag:yaml.org,2002:set"),
        ("a: !!omap [b: 1]\n", "tag:yaml.org,2002:omap"),
        ("a: {<<: {b: 1}}\n", "tag:yaml.org,2002:merge"),
    ],
)
def test_language_binary_and_custom_tags_are_refused(text: str, tag: str) -> None:
    err = refused(text)
    assert "is not allowed" in err.message
    assert tag in err.message
    assert err.line == 1
    assert err.element == "a"


def test_plain_core_tags_are_allowed() -> None:
    data, _ = load_yaml("m.yaml", text="a: !!str 5\nb: !!int '7'\nc: !!float 1\n")
    assert data == {"a": "5", "b": 7, "c": 1.0}


def test_duplicate_keys_are_refused_at_the_line_of_the_second() -> None:
    err = refused("goals:\n  - id: G1\n    utility: a\n    utility: b\n")
    assert err.line == 4
    assert err.element == "goals[0]"
    assert err.message == "duplicate key 'utility'"
    err = refused("a: 1\nb: 2\na: 3\n")
    assert (err.line, err.element) == (3, "<document>")


def test_deep_nesting_is_refused() -> None:
    err = refused("a: " + "[" * (MAX_DEPTH + 5) + "]" * (MAX_DEPTH + 5) + "\n")
    assert err.message == f"nesting deeper than {MAX_DEPTH} levels"
    assert err.line == 1
    # the bound is a parameter; nesting within it loads
    assert refused("a: [[[[1]]]]\n", max_depth=3).message == "nesting deeper than 3 levels"
    assert load_yaml("m.yaml", text="a: [[[[1]]]]\n", max_depth=6)[0] == {"a": [[[[1]]]]}


def test_oversized_input_is_refused_text_and_file(tmp_path: Path) -> None:
    err = refused("a: 1\n" * 100, max_bytes=100)
    assert "over the limit of 100 bytes" in err.message
    big = tmp_path / "big.yaml"
    big.write_text("a: 1\n" * 100)
    with pytest.raises(ModelFileError, match=r"big\.yaml: file is 500 bytes, over the limit of 99"):
        load_yaml(big, max_bytes=99)


def test_invalid_utf8_is_refused_naming_line_and_byte(tmp_path: Path) -> None:
    path = tmp_path / "latin1.yaml"
    path.write_bytes("anunnaki: goal-model/1\nname: café\n".encode("latin-1"))
    with pytest.raises(ModelFileError) as info:
        load_yaml(path)
    assert str(info.value).startswith(f"{path}:2: not UTF-8 text (byte 0xe9 at column 10)")
    assert "save the file as UTF-8" in str(info.value)
    with pytest.raises(ModelFileError, match="not UTF-8"):
        read_text_limited(path)


def test_control_characters_are_refused_with_a_line_not_a_traceback() -> None:
    err = refused("a: 1\nb: x\x07y\n")
    assert err.line == 2
    assert err.message == "character U+0007 is not allowed in YAML"


@pytest.mark.parametrize(
    ("text", "line", "message"),
    [
        ("a: [1, 2\n", 2, "invalid YAML"),
        ("a:\n\tb: 1\n", 2, "invalid YAML: found character '\\t' that cannot start any token"),
        ("a: 1\n---\nb: 2\n", 2, "invalid YAML"),
        ("", None, "the file is empty"),
        ("# only a comment\n", None, "the file is empty"),
        ("[1]: a\n", 1, "a mapping key must be a plain value"),
        ("a: " + "9" * 5000 + "\n", 1, "cannot read value"),
    ],
)
def test_malformed_yaml_is_located(text: str, line: int | None, message: str) -> None:
    err = refused(text)
    assert err.line == line
    assert err.message.startswith(message)


def test_unreadable_paths(tmp_path: Path) -> None:
    with pytest.raises(ModelFileError, match=r"missing\.yaml: cannot read file"):
        load_yaml(tmp_path / "missing.yaml")
    with pytest.raises(ModelFileError, match="not a regular file"):
        load_yaml(tmp_path)


# -- what is read, and how --------------------------------------------------------------


def test_yaml_11_booleans_stay_strings_and_true_false_are_booleans() -> None:
    data, _ = load_yaml(
        "m.yaml",
        text="a: [on, yes, off, no, y, n, ON, Yes]\nb: [true, false, True, FALSE]\non: 1\n",
    )
    assert data["a"] == ["on", "yes", "off", "no", "y", "n", "ON", "Yes"]
    assert data["b"] == [True, False, True, False]
    assert data["on"] == 1  # a payload field named 'on' stays a key named 'on'
    assert all(type(x) is bool for x in data["b"])


def test_plain_values() -> None:
    data, _ = load_yaml("m.yaml", text="a: [~, null, '', 1, 1.5, -2.0e+3, 'x', \"y\"]\n")
    assert data["a"] == [None, None, "", 1, 1.5, -2000.0, "x", "y"]


def test_an_exponent_needs_a_dot_as_in_yaml_11() -> None:
    # PyYAML resolves floats by YAML 1.1: a number with an exponent needs a dot and a signed
    # exponent ('1.0e-3', '1.0e+3'); '1e-3' and '1.0e3' are text. docs/goal-models.md says
    # so; changing it needs the tactics YAML dumper to quote such strings too.
    data, _ = load_yaml("m.yaml", text="a: [1e-3, 1.0e-3, 1.0e+3, 1.0e3, 0.001]\n")
    assert data["a"] == ["1e-3", 0.001, 1000.0, "1.0e3", 0.001]


def test_a_byte_order_mark_is_skipped() -> None:
    assert load_yaml("m.yaml", text="\ufeffa: 1\n")[0] == {"a": 1}


def test_a_file_is_read_when_no_text_is_given(tmp_path: Path) -> None:
    path = tmp_path / "m.yaml"
    path.write_text("a:\n  b: [1, 2]\n", encoding="utf-8")
    data, lines = load_yaml(path)
    assert data == {"a": {"b": [1, 2]}}
    assert lines.line(("a", "b", 1)) == 2


MODEL = """\
anunnaki: goal-model/1
name: lines
goals:
  - id: G1
    refinement: and
    children: [G6]
  - id: G6
    utility: rate(A3)
    relax:
      operator: as_close_as_possible_to_frequency
      target: 5.0
      tolerance: 0
    threshold: 0.5
"""


def test_linemap_lines_for_nested_paths() -> None:
    _, lines = load_yaml("m.yaml", text=MODEL)
    assert isinstance(lines, LineMap)
    assert lines.line(()) == 1
    assert lines.line(("anunnaki",)) == 1
    assert lines.line(("goals",)) == 3
    assert lines.line(("goals", 0)) == 4
    assert lines.line(("goals", 0, "children")) == 6
    assert lines.line(("goals", 0, "children", 0)) == 6
    assert lines.line(("goals", 1)) == 7
    assert lines.line(("goals", 1, "relax")) == 9
    assert lines.line(("goals", 1, "relax", "tolerance")) == 12
    assert lines.line(("goals", 1, "threshold")) == 13
    # a path that is not in the file falls back to its longest recorded prefix
    assert lines.line(("goals", 1, "relax", "window")) == 9
    assert lines.line(("goals", 7, "utility")) == 3
    assert lines.line(("nowhere",)) == 1
    assert LineMap().line(("a",)) is None


def test_describe_path_names_list_items_by_id() -> None:
    data, _ = load_yaml("m.yaml", text=MODEL)
    real, text = describe_path(data, ("goals", 1, "relax", "tolerance"))
    assert real == ("goals", 1, "relax", "tolerance")
    assert text == "goals[G6].relax.tolerance"
    # pydantic's union tags and validator markers are not in the file: they are skipped
    real, text = describe_path(
        data, ("goals", 1, "relax", "as_close_as_possible_to_frequency", "tolerance")
    )
    assert (real, text) == (("goals", 1, "relax", "tolerance"), "goals[G6].relax.tolerance")
    real, text = describe_path(data, ("goals", 0, "function-after", "threshold"))
    assert (real, text) == (("goals", 0), "goals[G1].threshold")  # a missing field is named
    assert describe_path(data, ()) == ((), "<document>")


def test_describe_path_uses_name_then_index() -> None:
    data = {"endpoints": [{"name": "/rover/stop", "kind": "x"}], "xs": [{"v": 1}, 5]}
    assert describe_path(data, ("endpoints", 0, "kind"))[1] == "endpoints[/rover/stop].kind"
    assert describe_path(data, ("xs", 0, "v"))[1] == "xs[0].v"
    assert describe_path(data, ("xs", 1))[1] == "xs[1]"
    assert element_path(("goals", 3, "utility")) == "goals[3].utility"
    assert element_path(()) == "<document>"


def test_a_validation_error_of_a_number_where_text_is_expected_says_to_quote_it() -> None:
    from anunnaki.goals import parse_goal_model

    with pytest.raises(ModelFileError) as info:
        parse_goal_model("anunnaki: goal-model/1\nname: x\ngoals: [{id: G1, utility: true}]\n")
    assert info.value.line == 3
    assert info.value.element == "goals[G1].utility"
    assert info.value.hint == "put the value in quotes to make it text: 'true'"
