"""Tests of the RELAX operators (through anunnaki.goals) and of the examples in docs/relax.md."""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import TypeAdapter, ValidationError

from anunnaki.goals import (
    AtemporalOperator,
    History,
    MayOrOperator,
    RelaxOperator,
    RelaxSpec,
    TemporalOperator,
    build_operator,
)

SPEC = TypeAdapter(RelaxSpec)
DOCS = Path(__file__).resolve().parents[2] / "docs" / "relax.md"
T, F, U = True, False, None

Samples = Sequence[tuple[float, bool | None]]


def parse(data: dict[str, Any]) -> RelaxOperator:
    return build_operator(SPEC.validate_python(data))


def relax(operator: str, **fields: Any) -> RelaxSpec:
    """The spec of ``operator`` with ``fields``, as a goal model's ``relax:`` mapping gives it."""
    return SPEC.validate_python({"operator": operator, **fields})


def atemporal(data: dict[str, Any]) -> AtemporalOperator:
    op = parse(data)
    assert isinstance(op, AtemporalOperator)
    return op


def temporal(spec: RelaxSpec) -> TemporalOperator:
    op = build_operator(spec)
    assert isinstance(op, TemporalOperator)
    return op


def at(op: TemporalOperator, p: Samples, now: float, e: Samples | None = None) -> float | None:
    return op.utility_at(History(p), None if e is None else History(e), now)


def close(u: float | None, expected: float | None) -> bool:
    if expected is None or u is None:
        return u is expected
    return math.isclose(u, expected, abs_tol=1e-12)


# ---------------------------------------------------------------------------------------
# The paper's G6
# ---------------------------------------------------------------------------------------

G6 = {
    "operator": "as_close_as_possible_to_frequency",
    "target": 5.0,
    "tolerance": 0.5,
    "side": "at_least",
    "unit": "Hz",
}


@pytest.mark.parametrize(
    ("f", "u"), [(4.0, 0.0), (4.5, 0.0), (4.75, 0.5), (4.8, 0.6), (5.0, 1.0), (6.0, 1.0)]
)
def test_g6_sample_rate(f: float, u: float) -> None:
    # 0 at f <= 4.5, 1 at f >= 5.0, (f - 4.5) / 0.5 between (the paper prints 4.5 - f).
    assert atemporal(G6).utility(f) == pytest.approx(u, abs=1e-12)


def test_g6_spec_fields() -> None:
    spec = SPEC.validate_python(G6)
    assert spec.operator == "as_close_as_possible_to_frequency"
    assert (spec.target, spec.tolerance, spec.side, spec.unit) == (5.0, 0.5, "at_least", "Hz")
    assert build_operator(spec).operator == "as_close_as_possible_to_frequency"


# ---------------------------------------------------------------------------------------
# Atemporal operators at hand-computed points
# ---------------------------------------------------------------------------------------

FREQ = "as_close_as_possible_to_frequency"
QTY = "as_close_as_possible_to_quantity"

ATEMPORAL_CASES: list[tuple[dict[str, Any], list[tuple[float, float]]]] = [
    ({"operator": "shall"}, [(0, 0.0), (1, 1.0), (0.3, 0.3), (2.0, 1.0), (-1.0, 0.0)]),
    (
        {"operator": FREQ, "target": 10.0, "tolerance": 2.0},
        [(10.0, 1.0), (9.0, 0.5), (11.5, 0.25), (12.0, 0.0), (7.0, 0.0)],
    ),
    (
        {"operator": FREQ, "target": 5.0, "tolerance": 1.0, "side": "at_most"},
        [(4.0, 1.0), (5.0, 1.0), (5.25, 0.75), (6.0, 0.0), (7.0, 0.0)],
    ),
    (
        {"operator": QTY, "target": 3, "tolerance": 2},
        [(3, 1.0), (2, 0.5), (4, 0.5), (0, 0.0), (6, 0.0)],
    ),
    (
        {"operator": QTY, "target": 3, "tolerance": 2, "side": "at_least"},
        [(3, 1.0), (8, 1.0), (2, 0.5), (1, 0.0), (4, 1.0)],
    ),
    (
        {"operator": QTY, "target": 3, "tolerance": 2, "side": "at_most"},
        [(3, 1.0), (0, 1.0), (4, 0.5), (5, 0.0), (2, 1.0)],
    ),
    (
        {"operator": "as_few_as_possible", "target": 2, "tolerance": 4},
        [(0, 1.0), (2, 1.0), (3, 0.75), (5, 0.25), (6, 0.0), (10, 0.0)],
    ),
    (
        {"operator": "as_many_as_possible", "target": 10, "tolerance": 5},
        [(12, 1.0), (10, 1.0), (9, 0.8), (7.5, 0.5), (5, 0.0), (0, 0.0)],
    ),
]


@pytest.mark.parametrize(("data", "points"), ATEMPORAL_CASES)
def test_atemporal_points(data: dict[str, Any], points: list[tuple[float, float]]) -> None:
    op = atemporal(data)
    assert op.kind == "atemporal"
    assert op.horizon == 0.0
    for x, u in points:
        assert op.utility(x) == pytest.approx(u, abs=1e-12), (data, x)


@pytest.mark.parametrize(("data", "points"), ATEMPORAL_CASES)
def test_atemporal_nan_and_infinities(
    data: dict[str, Any], points: list[tuple[float, float]]
) -> None:
    op = atemporal(data)
    assert op.utility(math.nan) == 0.0
    for x in (math.inf, -math.inf):
        assert 0.0 <= op.utility(x) <= 1.0


def test_shall_takes_booleans() -> None:
    op = atemporal({"operator": "shall"})
    assert op.utility(True) == 1.0
    assert op.utility(False) == 0.0


# ---------------------------------------------------------------------------------------
# MAY ... OR
# ---------------------------------------------------------------------------------------


def may_or(n: int = 2) -> MayOrOperator:
    op = parse({"operator": "may_or", "alternatives": [f"A{i}.ok" for i in range(n)]})
    assert isinstance(op, MayOrOperator)
    return op


@pytest.mark.parametrize(
    ("values", "u"),
    [
        ([0.2, 0.7], 0.7),
        ([0.0, 0.0], 0.0),
        ([True, False], 1.0),
        ([None, 1.0], 1.0),
        ([1.5, None], 1.0),
        ([None, 0.5], None),
        ([None, None], None),
        ([-0.5, math.nan], 0.0),
    ],
)
def test_may_or_is_kleene_or(values: list[float | None], u: float | None) -> None:
    op = may_or()
    assert op.kind == "alternatives"
    assert op.alternatives == ("A0.ok", "A1.ok")
    assert close(op.utility_of_alternatives(values), u)


def test_may_or_takes_any_number_of_values() -> None:
    assert may_or(2).utility_of_alternatives([0.25, 0.5, 0.75]) == 0.75
    assert may_or(2).utility_of_alternatives([]) == 0.0


values_or_none = st.one_of(st.none(), st.floats(allow_nan=False, allow_infinity=False))


@settings(max_examples=100, deadline=None)
@given(st.lists(values_or_none, min_size=2, max_size=5), st.data())
def test_may_or_properties(values: list[float | None], data: st.DataObject) -> None:
    op = may_or(len(values))
    u = op.utility_of_alternatives(values)
    known = [v for v in values if v is not None]
    if u is None:
        assert len(known) < len(values)
        assert all(v < 1.0 for v in known)
    else:
        assert 0.0 <= u <= 1.0
    # Raising one known value never lowers the result.
    i = data.draw(st.integers(0, len(values) - 1))
    if values[i] is not None and u is not None:
        higher = list(values)
        higher[i] = values[i] + data.draw(st.floats(0, 10))  # type: ignore[operator]
        v = op.utility_of_alternatives(higher)
        assert v is not None and v >= u


# ---------------------------------------------------------------------------------------
# Membership properties
# ---------------------------------------------------------------------------------------

finite = st.floats(allow_nan=False, allow_infinity=False)
moderate = st.floats(-1e6, 1e6, allow_nan=False)
tolerances = st.floats(1e-3, 1e6, allow_nan=False)
sides = st.sampled_from(["both", "at_least", "at_most"])


@st.composite
def atemporal_specs(draw: st.DrawFn) -> dict[str, Any]:
    name = draw(
        st.sampled_from(
            ["shall", FREQ, QTY, "as_few_as_possible", "as_many_as_possible"],
        )
    )
    if name == "shall":
        return {"operator": name}
    target = draw(st.floats(1e-3, 1e6) if name == FREQ else moderate)
    data: dict[str, Any] = {"operator": name, "target": target, "tolerance": draw(tolerances)}
    if name in (FREQ, QTY):
        data["side"] = draw(sides)
    return data


def scale(data: dict[str, Any]) -> float:
    return float(data.get("tolerance", 1.0))


@settings(max_examples=200, deadline=None)
@given(atemporal_specs(), finite)
def test_membership_in_unit_interval(data: dict[str, Any], x: float) -> None:
    u = atemporal(data).utility(x)
    assert isinstance(u, float)
    assert 0.0 <= u <= 1.0


@settings(max_examples=200, deadline=None)
@given(atemporal_specs(), moderate, st.floats(-10, 10, allow_nan=False))
def test_membership_is_continuous(data: dict[str, Any], x: float, dx: float) -> None:
    op = atemporal(data)
    y = x + dx
    assert abs(op.utility(y) - op.utility(x)) <= abs(y - x) / scale(data) + 1e-9


@settings(max_examples=200, deadline=None)
@given(atemporal_specs(), moderate, moderate)
def test_membership_is_monotone(data: dict[str, Any], a: float, b: float) -> None:
    op = atemporal(data)
    x, y = min(a, b), max(a, b)
    rising = data["operator"] in ("shall", "as_many_as_possible") or data.get("side") == "at_least"
    falling = data["operator"] == "as_few_as_possible" or data.get("side") == "at_most"
    if rising:
        assert op.utility(x) <= op.utility(y)
    elif falling:
        assert op.utility(x) >= op.utility(y)
    else:  # a triangle: rising up to the target, falling after it, symmetric
        target = data["target"]
        if y <= target:
            assert op.utility(x) <= op.utility(y)
        if x >= target:
            assert op.utility(x) >= op.utility(y)
        d = y - x
        slack = (abs(target) + d) * 1e-15 / data["tolerance"] + 1e-12  # rounding of target ± d
        assert op.utility(target - d) == pytest.approx(op.utility(target + d), abs=slack)


# ---------------------------------------------------------------------------------------
# RelaxSpec validation
# ---------------------------------------------------------------------------------------

VALID_SPECS: list[tuple[dict[str, Any], str]] = [
    ({"operator": "shall"}, "atemporal"),
    ({"operator": "may_or", "alternatives": ["A2.lidar_ok", "A3.sonar_ok"]}, "alternatives"),
    (G6, "atemporal"),
    ({"operator": QTY, "target": 4, "tolerance": 1}, "atemporal"),
    ({"operator": "as_few_as_possible", "target": 0, "tolerance": 3}, "atemporal"),
    ({"operator": "as_many_as_possible", "target": 8, "tolerance": 3}, "atemporal"),
    ({"operator": "eventually", "within": 10, "tolerance": 5, "unit": "s"}, "temporal"),
    ({"operator": "until", "event": "A1.arrived", "tolerance": 2}, "temporal"),
    ({"operator": "before", "event": "A1.takeoff", "tolerance": 4, "window": 60}, "temporal"),
    ({"operator": "after", "event": "A1.alarm", "within": 1, "tolerance": 2}, "temporal"),
    ({"operator": "as_early_as_possible", "tolerance": 4}, "temporal"),
    ({"operator": "as_late_as_possible", "target": 10}, "temporal"),
]


@pytest.mark.parametrize(("data", "kind"), VALID_SPECS)
def test_every_spec_builds(data: dict[str, Any], kind: str) -> None:
    spec = SPEC.validate_python(data)
    assert spec.operator == data["operator"]  # the union picked the operator's own spec
    assert type(spec)(**data) == spec  # which also validates when built directly
    op = build_operator(spec)
    assert op.kind == kind
    assert op.operator == data["operator"]
    assert op.spec is spec
    assert data["operator"] in repr(op)
    hash(spec)  # frozen specs are hashable (alternatives are a tuple)
    with pytest.raises(ValidationError):
        spec.unit = "m"  # type: ignore[misc]
    assert SPEC.validate_python(spec.model_dump()) == spec


@pytest.mark.parametrize(
    ("data", "field", "words"),
    [
        ({"operator": FREQ, "target": 5.0, "tolerance": 0}, "tolerance", "greater than 0"),
        ({"operator": QTY, "target": 5.0, "tolerance": -1}, "tolerance", "greater than 0"),
        ({"operator": "eventually", "within": 1, "tolerance": math.inf}, "tolerance", "finite"),
        ({"operator": QTY, "target": math.nan, "tolerance": 1}, "target", "finite"),
        ({"operator": FREQ, "target": 0.0, "tolerance": 1}, "target", "frequency in Hz"),
        ({"operator": "as_late_as_possible", "target": -3}, "target", "minimum delay"),
        ({"operator": "eventually", "within": -1, "tolerance": 1}, "within", "0 or more"),
        ({"operator": "until", "event": "x", "tolerance": 1, "window": -5}, "window", "than 0"),
        ({"operator": "until", "event": "x", "tolerance": 1, "window": 0}, "window", "than 0"),
        ({"operator": "before", "event": "x", "tolerance": 5, "window": 2}, "window", "at least"),
        (
            {"operator": "after", "event": "x", "within": 3, "tolerance": 2, "window": 4},
            "window",
            "within + tolerance",
        ),
        ({"operator": "until", "event": "  ", "tolerance": 1}, "event", "non-empty"),
        ({"operator": "may_or", "alternatives": ["a"]}, "alternatives", "at least 2"),
        ({"operator": "may_or", "alternatives": ["a", ""]}, "alternatives", "must be a non-empty"),
        ({"operator": "may_or", "alternatives": ["a", "a"]}, "alternatives", "twice"),
        ({"operator": "sometimes"}, "operator", "as_close_as_possible_to_frequency"),
        ({"target": 5, "tolerance": 1}, "operator", "discriminator"),
        ({"operator": "shall", "treshold": 0.5}, "treshold", "Extra inputs"),
        ({"operator": QTY, "target": 5, "tolerance": True}, "tolerance", "valid number"),
        ({"operator": QTY, "target": "5", "tolerance": 1}, "target", "valid number"),
        ({"operator": QTY, "target": 5, "tolerance": 1, "side": "above"}, "side", "at_least"),
        ({"operator": "eventually", "within": 5}, "tolerance", "Field required"),
    ],
)
def test_invalid_specs_name_the_field(data: dict[str, Any], field: str, words: str) -> None:
    with pytest.raises(ValidationError) as info:
        SPEC.validate_python(data)
    message = str(info.value)
    assert field in message
    assert words in message


@settings(max_examples=100, deadline=None)
@given(st.floats(max_value=0.0, allow_nan=False), st.sampled_from([FREQ, QTY]))
def test_nonpositive_tolerance_is_refused(tolerance: float, name: str) -> None:
    with pytest.raises(ValidationError, match="tolerance"):
        SPEC.validate_python({"operator": name, "target": 5.0, "tolerance": tolerance})


def test_build_operator_refuses_other_objects() -> None:
    with pytest.raises(TypeError, match="not a RELAX spec"):
        build_operator("eventually")  # type: ignore[arg-type]


# ---------------------------------------------------------------------------------------
# History
# ---------------------------------------------------------------------------------------


def test_history_merges_equal_states_and_replaces_same_instant() -> None:
    h = History([(0, F), (1, F), (2, T), (3, T), (4, U), (5, U)])
    assert list(h) == [(0.0, F), (2.0, T), (4.0, U)]
    h.append(6, F)
    h.append(6, T)  # same instant: the later sample wins
    assert list(h)[-1] == (6.0, T)
    h.append(6, U)  # back to the previous state: merged away
    assert list(h) == [(0.0, F), (2.0, T), (4.0, U)]
    assert h.latest == 6.0
    assert len(h) == 3


def test_history_refuses_time_going_back_and_non_finite_times() -> None:
    h = History([(5, T)])
    h.append(5, T)
    with pytest.raises(ValueError, match="earlier than"):
        h.append(4.9, F)
    with pytest.raises(ValueError, match="finite"):
        h.append(math.nan, F)
    with pytest.raises(ValueError, match="finite"):
        h.append(math.inf, F)
    with pytest.raises(ValueError, match="maxlen"):
        History(maxlen=1)
    with pytest.raises(ValueError, match="NaN"):
        h.prune(math.nan)


def test_history_is_capped() -> None:
    h = History(maxlen=4)
    for i in range(10):
        h.append(i, i % 2 == 0)
    assert h.maxlen == 4
    assert [t for t, _ in h] == [6.0, 7.0, 8.0, 9.0]


def test_history_prune_keeps_the_state_at_the_cutoff() -> None:
    h = History([(0, T), (2, F), (5, T), (8, F)])
    h.prune(-math.inf)
    assert len(h) == 4
    h.prune(6.0)
    assert list(h) == [(5.0, T), (8.0, F)]
    assert h.state_at(6.0) is True
    h.prune(8.0)
    assert list(h) == [(8.0, F)]
    h.prune(100.0)
    assert list(h) == [(8.0, F)]


def test_history_queries() -> None:
    h = History([(0, F), (2, T), (4, U), (6, F), (8, T), (9, F)])
    assert h.state_at(-1) is None
    assert h.state_at(3) is True
    assert h.state_at(5) is None
    assert h.last_held(8.5) == 8.5
    assert h.last_held(20) == 9.0
    assert h.last_held(7) == 4.0  # the unknown stretch does not count as holding
    assert h.last_held(1) is None
    assert h.last_onset(20) == 8.0
    assert h.last_onset(7) == 2.0
    assert h.last_onset(1) is None
    assert h.first_held(0, 20) == 2.0
    assert h.first_held(3, 20) == 3.0
    assert h.first_held(4.5, 20) == 8.0
    assert h.first_held(9.5, 20) is None
    # Known-false time only: [0,2) and [6,8) and [9,10] -> 2 + 2 + 1; the unknown [4,6) not.
    assert h.not_holding_time(-5, 10) == pytest.approx(5.0)
    assert h.not_holding_time(1, 7) == pytest.approx(2.0)
    assert h.not_holding_time(7, 7) == 0.0
    assert History().not_holding_time(0, 10) == 0.0
    assert History().last_onset(10) is None
    assert "maxlen=10000" in repr(History([(0, T)]))


# ---------------------------------------------------------------------------------------
# Temporal operators at hand-computed points, and with events in swapped order
# ---------------------------------------------------------------------------------------


def test_eventually() -> None:
    op = temporal(relax("eventually", within=10, tolerance=5))
    assert op.horizon == 15.0
    p = [(0, T), (2, F)]  # last held at 2
    for now, u in [(1, 1.0), (2, 1.0), (12, 1.0), (14.5, 0.5), (16, 0.2), (17, 0.0), (30, 0.0)]:
        assert close(at(op, p, now), u), now
    # Never held: the gap is measured from the first sample.
    for now, u in [(10, 1.0), (12.5, 0.5), (15, 0.0)]:
        assert close(at(op, [(0, F)], now), u), now


def test_eventually_order_matters() -> None:
    op = temporal(relax("eventually", within=10, tolerance=5))
    assert close(at(op, [(0, F), (6, T)], 18), 1.0)  # holds now
    assert close(at(op, [(0, T), (6, F)], 18), 0.6)  # last held 12 s ago


def test_until() -> None:
    op = temporal(relax("until", event="E", tolerance=4))
    assert op.horizon == math.inf
    assert op.needs_event
    assert op.event == "E"
    p = [(0, T), (2, F), (4, T), (7, F)]
    e = [(0, F), (5, T), (6, F)]
    # E holds at 5.5: the episode [0, 5] had P false for 2 s.
    assert close(at(op, p, 5.5, e), 0.5)
    # After E ended at 6 a new episode starts: P false since 7.
    for now, u in [(6.5, 1.0), (8, 0.75), (10, 0.25), (11, 0.0), (20, 0.0)]:
        assert close(at(op, p, now, e), u), now
    # No event yet: one open episode since the first sample.
    for now, u in [(1, 1.0), (3, 0.75), (4, 0.5), (5, 0.5)]:
        assert close(at(op, p, now, [(0, F)]), u), now


def test_until_with_window() -> None:
    op = temporal(relax("until", event="E", tolerance=4, window=3))
    assert op.horizon == 3.0
    p = [(0, T), (2, F), (4, T), (7, F)]
    e = [(0, F), (5, T), (6, F)]
    # Episode [0, 5] clipped to the window [2.5, 5.5]: P false during [2.5, 4).
    assert close(at(op, p, 5.5, e), 0.625)
    # At 9 the window is [6, 9]: P false during [7, 9].
    assert close(at(op, p, 9, e), 0.5)


def test_until_order_matters() -> None:
    op = temporal(relax("until", event="E", tolerance=2))
    # P lapses during [1, 2], then E at 3: the lapse came before E.
    assert close(at(op, [(0, T), (1, F), (2, T)], 4, [(0, F), (3, T)]), 0.5)
    # E at 1, then P lapses during [2, 3]: the obligation was already discharged.
    assert close(at(op, [(0, T), (2, F), (3, T)], 4, [(0, F), (1, T)]), 1.0)


def test_before() -> None:
    op = temporal(relax("before", event="E", tolerance=4))
    e = [(0, F), (5, T)]
    assert close(at(op, [(0, F), (3, T), (4, F)], 6, e), 1.0)  # P held at 3, before E at 5
    late = [(0, F), (7, T)]
    for now, u in [(4, 1.0), (6, 0.75), (7, 0.5), (20, 0.5)]:
        assert close(at(op, late, now, e), u), now
    assert close(at(op, [(0, F)], 9, e), 0.0)  # never held, 4 s after E
    assert close(at(op, [(0, F)], 9, [(0, F)]), 1.0)  # no event: nothing to check yet
    # A new occurrence of E starts a new episode, in which P must hold again.
    e2 = [(0, F), (5, T), (6, F), (10, T)]
    assert close(at(op, [(0, F), (3, T), (4, F)], 11, e2), 0.75)


def test_before_with_window_forgets_old_events() -> None:
    op = temporal(relax("before", event="E", tolerance=4, window=10))
    e = [(0, F), (5, T), (6, F)]
    assert close(at(op, [(0, F)], 8, e), 0.25)
    assert close(at(op, [(0, F)], 16, e), 1.0)  # E at 5 left the window [6, 16]


def test_before_order_matters() -> None:
    op = temporal(relax("before", event="E", tolerance=4))
    assert close(at(op, [(0, F), (3, T), (4, F)], 8, [(0, F), (5, T)]), 1.0)
    assert close(at(op, [(0, F), (5, T), (6, F)], 8, [(0, F), (3, T)]), 0.5)


def test_after() -> None:
    op = temporal(relax("after", event="E", within=1, tolerance=2))
    e = [(0, F), (3, T)]
    p = [(0, F), (5, T)]  # responds 2 s after E
    for now, u in [(2, 1.0), (3.5, 1.0), (4, 1.0), (4.5, 0.75), (5, 0.5), (9, 0.5)]:
        assert close(at(op, p, now, e), u), now
    assert close(at(op, [(0, T)], 9, e), 1.0)  # already holding when E occurs
    assert close(at(op, [(0, F)], 9, [(0, F)]), 1.0)  # no event: nothing required yet


def test_after_order_matters() -> None:
    op = temporal(relax("after", event="E", within=1, tolerance=2))
    # E at 3, P at 5: P came 2 s after E.
    assert close(at(op, [(0, F), (5, T), (6, F)], 8, [(0, F), (3, T)]), 0.5)
    # P at 3, E at 5: P has not held since E, 3 s ago.
    assert close(at(op, [(0, F), (3, T), (4, F)], 8, [(0, F), (5, T)]), 0.0)
    assert close(at(op, [(0, F), (3, T), (4, F)], 7, [(0, F), (5, T)]), 0.5)


def test_after_with_window_forgets_old_events() -> None:
    op = temporal(relax("after", event="E", within=1, tolerance=2, window=5))
    assert op.horizon == 5.0
    e = [(0, F), (3, T), (3.5, F)]
    assert close(at(op, [(0, F)], 7, e), 0.0)
    assert close(at(op, [(0, F)], 8.5, e), 1.0)  # E's onset at 3 left the window


def test_as_early_as_possible() -> None:
    op = temporal(relax("as_early_as_possible", tolerance=4))
    assert op.horizon == 4.0
    p = [(0, T), (2, F), (7, T)]
    for now, u in [(1, 1.0), (2, 1.0), (3, 0.75), (4, 0.5), (6, 0.0), (7, 1.0)]:
        assert close(at(op, p, now), u), now
    assert close(at(op, [(0, F)], 1), 0.75)  # never held: measured from the first sample


def test_as_early_as_possible_order_matters() -> None:
    op = temporal(relax("as_early_as_possible", tolerance=4))
    assert close(at(op, [(0, F), (2, T)], 3), 1.0)
    assert close(at(op, [(0, T), (2, F)], 3), 0.75)


def test_as_late_as_possible() -> None:
    op = temporal(relax("as_late_as_possible", target=10))
    assert op.horizon == math.inf
    assert close(at(op, [(0, T), (2, F), (7, T)], 8), 0.5)  # 5 s between two holdings
    assert close(at(op, [(0, T), (2, F), (20, T)], 21), 1.0)
    assert close(at(op, [(0, T), (2, F)], 5), 1.0)  # not holding: nothing early yet
    assert close(at(op, [(0, F), (4, T)], 5), 0.4)  # measured from the first sample
    assert close(at(op, [(0, T)], 5), None)  # holding since the first sample: delay unseen


def test_as_late_as_possible_order_matters() -> None:
    op = temporal(relax("as_late_as_possible", target=10))
    # The same stretches (F 1 s, T 1 s, F 8 s, then T) in two orders.
    assert close(at(op, [(0, F), (1, T), (2, F), (10, T)], 11), 0.8)
    assert close(at(op, [(0, F), (8, T), (9, F), (10, T)], 11), 0.1)


# ---------------------------------------------------------------------------------------
# Unknown values
# ---------------------------------------------------------------------------------------

TEMPORAL_SPECS = [
    relax("eventually", within=10, tolerance=5),
    relax("until", event="E", tolerance=2),
    relax("before", event="E", tolerance=4),
    relax("after", event="E", within=1, tolerance=2),
    relax("as_early_as_possible", tolerance=4),
    relax("as_late_as_possible", target=10),
]


@pytest.mark.parametrize("spec", TEMPORAL_SPECS, ids=lambda s: s.operator)
def test_nothing_known_is_unknown(spec: RelaxSpec) -> None:
    op = temporal(spec)
    e = [(0, F)]
    assert at(op, [], 5, e) is None
    assert at(op, [(0, U)], 5, e) is None
    assert at(op, [(6, T)], 5, e) is None  # now is before the first sample
    if op.needs_event:
        assert at(op, [(0, T)], 5, [(0, U)]) is None
        assert at(op, [(0, T)], 5, []) is None
        with pytest.raises(ValueError, match="needs the history of its event"):
            op.utility_at(History([(0, T)]), None, 5)
    with pytest.raises(ValueError, match="finite"):
        op.utility_at(History([(0, T)]), History(e), math.nan)


def test_unknown_current_state_is_unknown_only_when_it_matters() -> None:
    op = temporal(relax("eventually", within=10, tolerance=5))
    p = [(0, T), (2, U)]
    assert close(at(op, p, 12), 1.0)  # held or not, P held within the last 10 s
    assert close(at(op, p, 14.5), None)  # 1.0 if P holds, 0.5 if not
    op = temporal(relax("after", event="E", within=1, tolerance=2))
    assert close(at(op, [(0, T)], 5, [(0, F), (3, U)]), 1.0)  # P holds either way
    assert close(at(op, [(0, F)], 5, [(0, F), (3, U)]), None)


def test_unknown_past_stretch_is_neither_holding_nor_not() -> None:
    op = temporal(relax("until", event="E", tolerance=2))
    e = [(0, F)]
    assert close(at(op, [(0, T), (1, U), (3, T)], 4, e), 1.0)  # unknown: no violation
    assert close(at(op, [(0, T), (1, F), (3, T)], 4, e), 0.0)
    op = temporal(relax("eventually", within=1, tolerance=4))
    assert close(at(op, [(0, T), (1, U), (3, F)], 5, e), 0.25)  # last known holding at 1


def test_future_samples_are_ignored() -> None:
    op = temporal(relax("eventually", within=10, tolerance=5))
    assert close(at(op, [(0, T), (2, F), (20, T)], 14.5), 0.5)


# ---------------------------------------------------------------------------------------
# Temporal properties
# ---------------------------------------------------------------------------------------

states = st.sampled_from([T, F, U])
eighths = st.integers(0, 80).map(lambda n: n / 8)


@st.composite
def histories(draw: st.DrawFn) -> list[tuple[float, bool | None]]:
    t = draw(st.integers(-80, 80)) / 8
    samples = []
    for _ in range(draw(st.integers(1, 12))):
        samples.append((t, draw(states)))
        t += draw(eighths)
    return samples


positive = st.integers(1, 160).map(lambda n: n / 8)


@st.composite
def temporal_specs(draw: st.DrawFn, windows: bool = True) -> RelaxSpec:
    kind = draw(st.sampled_from(["eventually", "until", "before", "after", "early", "late"]))
    tol = draw(positive)
    within = draw(eighths)
    window = draw(st.none() | positive) if windows else None
    if kind == "eventually":
        return relax("eventually", within=within, tolerance=tol)
    if kind == "until":
        return relax("until", event="E", tolerance=tol, window=window)
    if kind == "before":
        return relax(
            "before", event="E", tolerance=tol, window=None if window is None else tol + window
        )
    if kind == "after":
        w = None if window is None else within + tol + window
        return relax("after", event="E", within=within, tolerance=tol, window=w)
    if kind == "early":
        return relax("as_early_as_possible", tolerance=tol)
    return relax("as_late_as_possible", target=tol)


def temporal_scale(spec: RelaxSpec) -> float:
    return float(getattr(spec, "tolerance", getattr(spec, "target", 1.0)))


def last_time(p: Samples, e: Samples) -> float:
    return max(t for t, _ in [*p, *e])


@settings(max_examples=150, deadline=None)
@given(temporal_specs(), histories(), histories(), st.integers(-40, 200).map(lambda n: n / 8))
def test_temporal_results_are_unit_or_none_and_pruning_keeps_them(
    spec: RelaxSpec, p: Samples, e: Samples, dt: float
) -> None:
    op = temporal(spec)
    now = last_time(p, e) + dt
    u = at(op, p, now, e)
    assert u is None or (isinstance(u, float) and 0.0 <= u <= 1.0)
    hp, he = History(p), History(e)
    hp.prune(now - op.horizon)
    he.prune(now - op.horizon)
    assert op.utility_at(hp, he, now) == u


@settings(max_examples=100, deadline=None)
@given(temporal_specs(), histories(), histories(), eighths, st.integers(-10, 10))
def test_temporal_results_do_not_depend_on_the_clock_origin(
    spec: RelaxSpec, p: Samples, e: Samples, dt: float, shift: int
) -> None:
    op = temporal(spec)
    now = last_time(p, e) + dt
    moved_p = [(t + 16 * shift, v) for t, v in p]
    moved_e = [(t + 16 * shift, v) for t, v in e]
    assert close(at(op, moved_p, now + 16 * shift, moved_e), at(op, p, now, e))


@settings(max_examples=150, deadline=None)
@given(temporal_specs(windows=False), histories(), histories(), eighths, eighths)
def test_temporal_results_are_continuous_and_monotone_in_time(
    spec: RelaxSpec, p: Samples, e: Samples, dt: float, step: float
) -> None:
    # Between samples, time passing changes a utility by at most step / tolerance, and
    # (no window) never raises it: a violation only grows until the next sample.
    op = temporal(spec)
    now = last_time(p, e) + dt
    u1, u2 = at(op, p, now, e), at(op, p, now + step, e)
    if u1 is not None and u2 is not None:
        assert abs(u2 - u1) <= step / temporal_scale(spec) + 1e-9
        assert u2 <= u1 + 1e-12


@settings(max_examples=100, deadline=None)
@given(temporal_specs(), histories(), histories(), eighths)
def test_known_histories_give_known_utilities(
    spec: RelaxSpec, p: Samples, e: Samples, dt: float
) -> None:
    # Unknown only comes from unknown samples, except an unobserved onset (as_late).
    p = [(t, bool(v)) for t, v in p]
    e = [(t, bool(v)) for t, v in e]
    op = temporal(spec)
    now = last_time(p, e) + dt
    u = at(op, p, now, e)
    if u is None:
        assert op.operator == "as_late_as_possible"
        assert History(p).last_onset(now) == p[0][0]


@settings(max_examples=100, deadline=None)
@given(temporal_specs(), histories(), histories(), eighths, histories())
def test_later_samples_do_not_change_the_past(
    spec: RelaxSpec, p: Samples, e: Samples, dt: float, extra: Samples
) -> None:
    op = temporal(spec)
    now = last_time(p, e) + dt
    later = [(now + 1 + t - extra[0][0], v) for t, v in extra]
    assert close(at(op, [*p, *later], now, [*e, *later]), at(op, p, now, e))


# ---------------------------------------------------------------------------------------
# docs/relax.md: every YAML example is a valid spec
# ---------------------------------------------------------------------------------------


def test_docs_yaml_examples_are_valid_specs() -> None:
    text = DOCS.read_text(encoding="utf-8")
    blocks = re.findall(r"```yaml\n(.*?)```", text, flags=re.DOTALL)
    specs = []
    for block in blocks:
        data = yaml.safe_load(block)
        items = data if isinstance(data, list) else [data]
        for item in items:
            if isinstance(item, dict) and "relax" in item:
                specs.append(SPEC.validate_python(item["relax"]))
    names = {s.operator for s in specs}
    assert names == {data["operator"] for data, _ in VALID_SPECS}
    assert specs[0] == SPEC.validate_python(G6)  # G6 is the first example
