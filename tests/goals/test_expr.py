"""Utility expressions: grammar, semantics (Kleene unknown), bounds, errors."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from anunnaki.errors import ExpressionError
from anunnaki.goals import ABSENT, AttrRef, compile_expression, truth


def ev(text: str, rates: dict[str, float] | None = None, **attrs: object) -> object:
    env = {k.replace("__", "."): v for k, v in attrs.items()}
    return compile_expression(text).evaluate(env, rates)


@pytest.mark.parametrize(
    ("text", "attrs", "expected"),
    [
        ("A1.buzzer == true", {"A1__buzzer": True}, True),
        ("A1.buzzer == true", {"A1__buzzer": False}, False),
        ("A4.category >= 1", {"A4__category": 2}, True),
        ("A4.category >= 1", {"A4__category": 0}, False),
        ("A1.mode == 'manual'", {"A1__mode": "manual"}, True),
        ('A1.mode != "manual"', {"A1__mode": "manual"}, False),
        ("A1.x < 2 and A1.y > 2", {"A1__x": 1, "A1__y": 3}, True),
        ("A1.x < 2 or A1.y > 2", {"A1__x": 5, "A1__y": 0}, False),
        ("not A1.b", {"A1__b": False}, True),
        ("A1.x + 2 * 3", {"A1__x": 1}, 7),
        ("(A1.x + 2) * 3", {"A1__x": 1}, 9),
        ("A1.x - 4 / 2", {"A1__x": 1}, -1.0),
        ("A1.x % 4", {"A1__x": 10}, 2),
        ("-A1.x", {"A1__x": 3}, -3),
        ("min(A1.x, 3, 2)", {"A1__x": 5}, 2),
        ("max(A1.x, 3)", {"A1__x": 5}, 5),
        ("abs(A1.x)", {"A1__x": -2.5}, 2.5),
        ("A1.mode in ['manual', 'teleop']", {"A1__mode": "teleop"}, True),
        ("A1.mode not in ['manual', 'teleop']", {"A1__mode": "teleop"}, False),
        ("A1.n in [1, -2, 3.5]", {"A1__n": -2}, True),
        ("A1 has buzzer", {"A1__buzzer": False}, True),
        ("A1 has buzzer", {"A1__buzzer": ABSENT}, False),
        ("A1 has no buzzer", {"A1__buzzer": ABSENT}, True),
        ("A1.ok and A1.deg", {"A1__ok": True, "A1__deg": 0.4}, 0.4),
        ("A1.a or A1.b", {"A1__a": 0.2, "A1__b": 0.7}, 0.7),
        ("not A1.deg", {"A1__deg": 0.25}, 0.75),
        ("1e-3 < A1.x", {"A1__x": 0.01}, True),
    ],
)
def test_semantics(text: str, attrs: dict[str, object], expected: object) -> None:
    assert ev(text, **attrs) == expected


def test_rate_reads_the_rate_slot() -> None:
    e = compile_expression("rate(A3) >= 5.0")
    assert e.rated == {"A3"}
    assert e.evaluate({}, {"A3": 5.2}) is True
    assert e.evaluate({}, {"A3": 4.8}) is False
    assert e.evaluate({}, {}) is None


@pytest.mark.parametrize(
    ("text", "attrs", "expected"),
    [
        ("A1.x == 1", {}, None),  # missing = unknown
        ("A1.x == 1", {"A1__x": ABSENT}, None),  # absent field reads as unknown
        ("false and A1.x", {}, False),  # Kleene: false decides
        ("A1.x and false", {}, False),
        ("true or A1.x", {}, True),  # true decides
        ("A1.x or true", {}, True),
        ("true and A1.x", {}, None),
        ("false or A1.x", {}, None),
        ("not A1.x", {}, None),
        ("A1.x + 1", {}, None),
        ("A1 has x", {}, None),  # silent agent: presence unknown
        ("A1.x / A1.y", {"A1__x": 1, "A1__y": 0}, None),  # division by zero: unknown
        ("A1.s < 3", {"A1__s": "a"}, None),  # type clash at run time: unknown
        ("A1.s + 1", {"A1__s": "a"}, None),
        ("A1.z and 0.0", {}, 0.0),  # fuzzy: 0 decides
        ("A1.z or 1.0", {}, 1.0),
    ],
)
def test_unknown_propagates_by_kleene(
    text: str, attrs: dict[str, object], expected: object
) -> None:
    assert ev(text, **attrs) == expected


def test_references_are_collected() -> None:
    e = compile_expression("A1.mode == 'manual' and A4.category < 1 or A2 has seq or rate(A3) > 1")
    assert e.refs == {AttrRef("A1", "mode"), AttrRef("A4", "category"), AttrRef("A2", "seq")}
    assert e.rated == {"A3"}
    assert e.agents == {"A1", "A2", "A3", "A4"}


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("A1.", "syntax error at column"),
        ("A1.x ==", "unexpected end of expression"),
        ("A1.x && 1", "unexpected character '&'"),
        ("eval(A1.x)", "syntax error"),
        ("__import__('os')", "syntax error"),
        ("'a' < 3", "compares a string with a number"),
        ("abs(1, 2)", "abs() takes exactly one argument"),
        ("min('a', 1)", "min() takes numbers only"),
        ("'s' and true", "not strings"),
        ("true + 1", "arithmetic on a string or boolean"),
        ("", "empty expression"),
        ("(" * 40 + "1" + ")" * 40, "more than 32 brackets"),
        ("1" + " + 1" * 1200, "longer than 2000 characters"),
        (" + ".join(["A1.x"] * 200), "deeper than 32 levels or larger than 400 nodes"),
    ],
)
def test_errors_name_the_problem(text: str, needle: str) -> None:
    with pytest.raises(ExpressionError) as info:
        compile_expression(text, path="m.yaml", line=7, element="goals[G1].utility")
    msg = str(info.value)
    assert needle in msg
    assert msg.startswith("m.yaml:7: goals[G1].utility: ")


def test_attribute_names_may_contain_keywords_as_prefix() -> None:
    assert (
        ev(
            "A1.order >= 1 and A1.index > 0 and A1.notice",
            A1__order=2,
            A1__index=1,
            A1__notice=True,
        )
        is True
    )


@given(st.one_of(st.none(), st.booleans(), st.floats(allow_nan=True), st.integers(), st.text()))
def test_truth_is_bounded(value: object) -> None:
    t = truth(value)  # type: ignore[arg-type]
    assert t is None or 0.0 <= t <= 1.0


@given(
    a=st.one_of(st.none(), st.booleans(), st.floats(0, 1)),
    b=st.one_of(st.none(), st.booleans(), st.floats(0, 1)),
)
def test_and_or_match_kleene_min_max(a: object, b: object) -> None:
    ta, tb = truth(a), truth(b)  # type: ignore[arg-type]
    got_and = truth(ev("A1.a and A1.b", A1__a=a, A1__b=b))  # type: ignore[arg-type]
    got_or = truth(ev("A1.a or A1.b", A1__a=a, A1__b=b))  # type: ignore[arg-type]
    if ta is not None and tb is not None:
        assert got_and == min(ta, tb)
        assert got_or == max(ta, tb)
    else:
        known = [x for x in (ta, tb) if x is not None]
        assert got_and == (0.0 if 0.0 in known else None)
        assert got_or == (1.0 if 1.0 in known else None)
