"""The evaluator: logic-tree semantics, obstacles, unknowns, rates, staleness, incrementality."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from anunnaki.goals import Evaluator, GoalModel, load_goal_model, parse_goal_model

ROVER = Path(__file__).parents[2] / "examples" / "rover"

TREE = """\
anunnaki: goal-model/1
name: t
root: G1
agents:
  - {id: A1, topics: [{topic: /a1, attributes: [a, b, c, mode]}]}
  - {id: A2, topics: [{topic: /a2, attributes: [x]}], staleness: 1.0}
goals:
  - {id: G1, refinement: and, children: [G2, G3]}
  - {id: G2, refinement: or, children: [G4, G5]}
  - {id: G3, utility: A1.c}
  - {id: G4, utility: A1.a}
  - {id: G5, utility: A1.b}
  - {id: G6, utility: A1.mode == 'manual'}
  - {id: G7, objective: avoid, utility: A2.x > 3}
obstacles:
  - {id: O1, obstructs: [G3], condition: A2.x >= 1, resolutions: [G6]}
"""


def tree_model(extra: str = "") -> GoalModel:
    text = TREE.replace("root: G1", "root: G1") + extra
    return parse_goal_model(text, strict=False)


def make(values: dict[str, object], now: float = 0.0) -> Evaluator:
    ev = Evaluator(tree_model())
    a1 = {k: v for k, v in values.items() if k in ("a", "b", "c", "mode")}
    if a1:
        ev.observe("/a1", a1, now)
    if "x" in values:
        ev.observe("/a2", {"x": values["x"]}, now)
    return ev


def test_and_is_min_or_is_max() -> None:
    ev = make({"a": 0.3, "b": 0.8, "c": 0.6, "mode": "auto", "x": 0})
    assert ev.state("G2").utility == pytest.approx(0.8)  # OR = max
    assert ev.state("G1").utility == pytest.approx(0.6)  # AND = min(0.8, 0.6)
    # satisfaction: fuzzy leaves below their threshold 1.0 are unsatisfied
    assert ev.state("G4").status is False
    assert ev.state("G1").status is False


def test_boolean_satisfaction() -> None:
    ev = make({"a": False, "b": True, "c": True, "mode": "auto", "x": 0})
    assert ev.state("G2").status is True  # OR of F, T
    assert ev.state("G1").status is True
    ev.observe("/a1", {"a": False, "b": False, "c": True, "mode": "auto"}, 0.1)
    assert ev.state("G2").status is False
    assert ev.state("G1").status is False


def test_obstacle_obstructs_unless_resolved() -> None:
    ev = make({"a": True, "b": True, "c": True, "mode": "auto", "x": 2})
    assert ev.state("O1").status is True  # the obstacle holds
    assert ev.state("G3").utility == 0.0  # min(1, 1 - 1)
    assert ev.state("G3").status is False
    assert ev.state("G1").status is False
    # a satisfied resolution goal lifts the obstruction
    ev.observe("/a1", {"a": True, "b": True, "c": True, "mode": "manual"}, 0.2)
    assert ev.state("G6").status is True
    assert ev.state("G3").status is True
    assert ev.state("G1").status is True


def test_avoid_negates_its_condition() -> None:
    ev = make({"x": 5})
    assert ev.state("G7").utility == 0.0
    assert ev.state("G7").status is False
    ev.observe("/a2", {"x": 1}, 0.5)
    assert ev.state("G7").status is True


def test_unknown_propagates_by_kleene() -> None:
    ev = make({"a": True, "c": True, "mode": "auto", "x": 0})  # b absent -> unknown
    assert ev.state("G5").status is None
    assert ev.state("G2").status is True  # true or unknown = true
    ev.observe("/a1", {"a": False, "c": True, "mode": "auto"}, 0.1)
    assert ev.state("G2").status is None  # false or unknown = unknown
    assert ev.state("G1").status is None
    assert ev.root.status_name == "unknown"
    ev.observe("/a1", {"a": False, "c": False, "mode": "auto"}, 0.2)
    assert ev.state("G1").status is False  # unknown and false = false
    assert ev.state("G1").utility == 0.0


def test_stale_values_become_unknown() -> None:
    ev = make({"a": True, "b": True, "c": True, "mode": "auto", "x": 0}, now=10.0)
    assert ev.state("O1").status is False
    ev.tick(10.9)
    assert ev.state("O1").status is False  # A2 staleness is 1.0 s
    ev.tick(11.1)
    assert ev.state("O1").status is None
    assert ev.state("G3").status is None
    assert ev.root.status is None
    # the policy decides how unknown counts for tactics (default: unsatisfied, fail-safe)
    assert ev.satisfied_for_tactics("G1") is False
    ev.observe("/a2", {"x": 0}, 11.5)
    assert ev.root.status is True


def test_unknown_policy_satisfied() -> None:
    model = parse_goal_model(TREE.replace("root: G1", "root: G1\nunknown_policy: satisfied"))
    ev = Evaluator(model)
    assert ev.root.status is None
    assert ev.satisfied_for_tactics("G1") is True


def test_explanation_names_the_deciding_leaves() -> None:
    ev = Evaluator(load_goal_model(ROVER / "goals.yaml", ROVER / "binding.yaml"))
    t = 0.0
    for k in range(12):
        t = k * 0.1
        ev.observe("/rover/ultrasonic", {"range": 3.0}, t)
    ev.observe("/rover/status", {"mode": "autonomous", "buzzer": False, "bumper": False}, t)
    ev.observe("/rover/camera/info", {"seq": 1}, t)
    ev.observe("/utu/oracle/output", {"category": 0, "confidence": 0.9}, t)
    assert ev.root.status is True
    ev.observe("/utu/oracle/output", {"category": 1, "confidence": 0.9}, t + 0.05)
    assert ev.root.status is False
    why = ev.explain("G1")
    assert why.leaves["A4.category"] == 1
    text = why.render()
    assert "obstructed by O1" in text
    assert "A4.category >= 1 with A4.category = 1" in text
    assert "G1 unsatisfied" in text
    assert why.to_dict()["status"] == "unsatisfied"


def _rover() -> Evaluator:
    return Evaluator(load_goal_model(ROVER / "goals.yaml", ROVER / "binding.yaml"))


def test_rate_from_inter_arrival_times() -> None:
    ev = _rover()
    t = 0.0
    for _ in range(30):
        ev.observe("/rover/ultrasonic", {"range": 3.0}, t)
        t += 1 / 4.8
    assert ev.value("rate(A3)") == pytest.approx(4.8, rel=1e-6)
    # RELAX-ed G6: (4.8 - 4.5) / 0.5 = 0.6 >= threshold 0.5
    assert ev.state("G6").utility == pytest.approx(0.6, rel=1e-6)
    assert ev.state("G6").status is True


def test_rate_decays_continuously_through_a_silence() -> None:
    ev = _rover()
    t = 0.0
    for _ in range(11):
        ev.observe("/rover/ultrasonic", {"range": 3.0}, t)
        t += 0.2  # 5 Hz
    last = t - 0.2
    rates = []
    for dt in (0.1, 0.2, 0.25, 0.3, 0.5, 1.0, 3.0):
        ev.tick(last + dt)
        rates.append(ev.value("rate(A3)"))
    assert rates[0] == pytest.approx(5.0)
    assert rates[1] == pytest.approx(5.0)  # gap = mean interval: no change yet
    assert rates[2] == pytest.approx(10 / (2.0 + 0.05))  # then the open gap counts
    assert all(a > b for a, b in itertools.pairwise(rates[2:]))
    assert ev.state("G6").status is False


def test_crisp_g6_is_violated_where_relaxed_is_not() -> None:
    text = (ROVER / "goals.yaml").read_text()
    crisp = text.replace(
        "    utility: rate(A3)\n    relax: {operator: as_close_as_possible_to_frequency, "
        "target: 5.0, tolerance: 0.5, side: at_least, unit: Hz}\n    threshold: 0.5\n",
        "    utility: rate(A3) >= 5.0\n",
    )
    assert crisp != text
    from anunnaki.goals import load_binding

    binding = load_binding(ROVER / "binding.yaml")
    relaxed_ev = Evaluator(parse_goal_model(text, binding=binding))
    crisp_ev = Evaluator(parse_goal_model(crisp, binding=binding))
    t = 0.0
    for _ in range(30):
        for ev in (relaxed_ev, crisp_ev):
            ev.observe("/rover/ultrasonic", {"range": 3.0}, t)
        t += 1 / 4.8
    assert relaxed_ev.state("G6").status is True
    assert crisp_ev.state("G6").status is False


def test_changes_are_reported_once() -> None:
    ev = make({"a": True, "b": True, "c": True, "mode": "auto", "x": 0})
    ev.drain_changes()
    ev.observe("/a1", {"a": True, "b": True, "c": True, "mode": "auto"}, 0.5)
    assert ev.drain_changes() == []  # nothing changed
    ev.observe("/a1", {"a": True, "b": True, "c": False, "mode": "auto"}, 0.6)
    assert set(ev.drain_changes()) == {"G3", "G1"}


def test_unbound_topics_and_fields_are_ignored() -> None:
    ev = make({"a": True, "b": True, "c": True, "mode": "auto", "x": 0})
    before = {n: ev.state(n) for n in ev.ids}
    ev.observe("/nobody/listens", {"a": False}, 1.0)
    ev.observe("/a1", {"a": True, "b": True, "c": True, "mode": "auto", "extra": [1]}, 1.0)
    assert {n: ev.state(n) for n in ev.ids} == before


def test_nested_field_paths_and_absent_fields() -> None:
    model = parse_goal_model(
        "anunnaki: goal-model/1\nname: n\n"
        "agents: [{id: A, topics: [{topic: /s, attributes: {seq: header.seq}}]}]\n"
        "goals:\n  - {id: G, refinement: and, children: [G1, G2]}\n"
        "  - {id: G1, utility: A has seq}\n  - {id: G2, utility: A.seq >= 0}\n"
    )
    ev = Evaluator(model)
    ev.observe("/s", {"header": {"seq": 4}}, 0.0)
    assert ev.state("G").status is True
    ev.observe("/s", {"header": {}}, 0.1)
    assert ev.state("G1").status is False  # A has no seq
    assert ev.state("G2").status is None  # its value is unknown
    assert ev.value("A.seq") is not None  # the ABSENT marker, not None


def test_a_failing_operator_is_contained() -> None:
    errors: list[str] = []
    ev = Evaluator(tree_model(), on_error=lambda node, exc: errors.append(node))

    def boom(slots: list[object]) -> object:
        raise RuntimeError("boom")

    ev._fn[ev.index["G4"]] = boom
    ev.observe("/a1", {"a": True, "b": True, "c": True, "mode": "auto"}, 0.0)
    assert errors and errors[0] == "G4"
    assert ev.state("G4").status is None
    assert ev.state("G2").status is True  # G5 still decides the OR


TEMPORAL = """\
anunnaki: goal-model/1
name: temporal
agents: [{id: A, topics: [{topic: /hb, attributes: [alive]}], staleness: 100}]
goals:
  - id: G
    utility: A.alive == true
    relax: {operator: eventually, within: 5, tolerance: 4}
    threshold: 0.5
"""


def test_temporal_relax_through_the_evaluator() -> None:
    ev = Evaluator(parse_goal_model(TEMPORAL))
    ev.observe("/hb", {"alive": True}, 0.0)
    ev.observe("/hb", {"alive": False}, 1.0)
    ev.tick(6.0)  # 5 s since it last held: still fully met
    assert ev.state("G").utility == pytest.approx(1.0)
    ev.tick(8.0)  # 7 s: 1 - (7 - 5) / 4 = 0.5
    assert ev.state("G").utility == pytest.approx(0.5)
    assert ev.state("G").status is True
    ev.tick(9.0)  # 1 - (8 - 5) / 4 = 0.25, below the threshold
    assert ev.state("G").utility == pytest.approx(0.25)
    assert ev.state("G").status is False
    ev.tick(12.0)
    assert ev.state("G").utility == pytest.approx(0.0)
    ev.observe("/hb", {"alive": True}, 12.5)
    assert ev.state("G").utility == pytest.approx(1.0)


# -- incremental == full, for any sequence of updates -------------------------------------

UPDATES = st.lists(
    st.tuples(
        st.sampled_from(["/a1", "/a2"]),
        st.fixed_dictionaries(
            {},
            optional={
                "a": st.one_of(st.booleans(), st.floats(-1, 2)),
                "b": st.one_of(st.booleans(), st.floats(0, 1)),
                "c": st.booleans(),
                "mode": st.sampled_from(["auto", "manual"]),
                "x": st.integers(-1, 5),
            },
        ),
        st.floats(0, 2),
    ),
    max_size=40,
)


def _snapshot(ev: Evaluator) -> dict[str, tuple[float | None, bool | None]]:
    return {n: (ev.state(n).utility, ev.state(n).status) for n in ev.ids}


@settings(max_examples=150, deadline=None)
@given(UPDATES)
def test_incremental_equals_full(updates: list[tuple[str, dict[str, object], float]]) -> None:
    ev = Evaluator(tree_model())
    now = 0.0
    for topic, msg, dt in updates:
        now += dt
        ev.observe(topic, msg, now)
        if dt > 1.5:
            ev.tick(now)
        incremental = _snapshot(ev)
        ev.evaluate_all(now)
        assert _snapshot(ev) == incremental
        for u, _ in incremental.values():
            assert u is None or 0.0 <= u <= 1.0


@settings(max_examples=100, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.sampled_from(["/rover/status", "/utu/oracle/output", "/rover/ultrasonic"]),
            st.integers(0, 2),
            st.floats(0.01, 0.6),
        ),
        max_size=60,
    )
)
def test_incremental_equals_full_on_the_rover(updates: list[tuple[str, int, float]]) -> None:
    ev = _rover()
    now = 0.0
    for topic, k, dt in updates:
        now += dt
        msg: dict[str, object] = {
            "/rover/status": {
                "mode": ["autonomous", "manual", "x"][k],
                "buzzer": k == 1,
                "bumper": k == 2,
            },
            "/utu/oracle/output": {"category": k, "confidence": 0.5},
            "/rover/ultrasonic": {"range": float(k)},
        }[topic]
        ev.tick(now)
        ev.observe(topic, msg, now)
        incremental = _snapshot(ev)
        ev.evaluate_all(now)
        assert _snapshot(ev) == incremental


@given(st.lists(st.floats(0, 1), min_size=4, max_size=4), st.integers(0, 3), st.floats(0, 1))
def test_and_or_are_monotone(values: list[float], which: int, bump: float) -> None:
    ev = Evaluator(tree_model())
    msg = dict(zip(["a", "b", "c"], values[:3], strict=False), mode="auto")
    ev.observe("/a1", msg, 0.0)
    ev.observe("/a2", {"x": 0}, 0.0)
    before = _snapshot(ev)
    key = ["a", "b", "c", "a"][which]
    msg[key] = min(1.0, float(msg[key]) + bump)  # type: ignore[arg-type]
    ev.observe("/a1", msg, 0.1)
    after = _snapshot(ev)
    for node in ("G1", "G2"):
        ub, ua = before[node][0], after[node][0]
        assert ub is not None and ua is not None
        assert ua >= ub - 1e-12
        assert not math.isnan(ua)


# -- status and utility agree: a known status has a known utility ---------------------------

RELAXED = """\
anunnaki: goal-model/1
name: relaxed
root: G1
agents:
  - {id: A1, topics: [{topic: /a1, attributes: [a, b, c, d]}]}
goals:
  - {id: G1, refinement: and, children: [G2, G5]}
  - {id: G2, refinement: or, children: [G3, G4]}
  - {id: G3, utility: A1.a, relax: {operator: shall}, threshold: 0.5}
  - {id: G4, utility: A1.b, relax: {operator: shall}, threshold: 0.5}
  - {id: G5, utility: A1.c, relax: {operator: shall}, threshold: 0.5}
obstacles:
  - {id: O1, obstructs: [G5], condition: A1.d, threshold: 0.5}
"""
ATTRS = ("a", "b", "c", "d")


def relaxed(values: dict[str, float | None]) -> Evaluator:
    ev = Evaluator(parse_goal_model(RELAXED))
    ev.observe("/a1", {k: v for k, v in values.items() if v is not None}, 0.0)
    return ev


def test_a_satisfied_or_with_an_unknown_child_has_the_known_maximum() -> None:
    ev = relaxed({"a": 0.6, "b": None, "c": 1.0, "d": 0.0})
    assert ev.state("G4").status is None
    assert (ev.state("G2").utility, ev.state("G2").status) == (pytest.approx(0.6), True)
    assert (ev.state("G1").utility, ev.state("G1").status) == (pytest.approx(0.6), True)
    # a crisp satisfied child (1.0) dominates, as before
    ev.observe("/a1", {"a": 1.0, "c": 1.0, "d": 0.0}, 0.1)
    assert (ev.state("G2").utility, ev.state("G2").status) == (1.0, True)
    # not decided by the known child: unknown, as before
    ev.observe("/a1", {"a": 0.3, "c": 1.0, "d": 0.0}, 0.2)
    assert (ev.state("G2").utility, ev.state("G2").status) == (None, None)


def test_an_unsatisfied_and_with_an_unknown_child_has_the_known_minimum() -> None:
    ev = relaxed({"a": None, "b": None, "c": 0.3, "d": 0.0})
    assert ev.state("G2").status is None
    assert (ev.state("G5").utility, ev.state("G5").status) == (pytest.approx(0.3), False)
    assert (ev.state("G1").utility, ev.state("G1").status) == (pytest.approx(0.3), False)
    # an unknown obstacle on an unsatisfied goal, a holding one on an unknown goal
    ev.observe("/a1", {"a": 1.0, "c": 0.3}, 0.1)
    assert (ev.state("G5").utility, ev.state("G5").status) == (pytest.approx(0.3), False)
    ev.observe("/a1", {"a": 1.0, "d": 0.8}, 0.2)
    assert (ev.state("G5").utility, ev.state("G5").status) == (pytest.approx(0.2), False)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from([None, 0.0, 0.2, 0.5, 0.7, 1.0]), min_size=4, max_size=4))
def test_a_known_status_has_a_known_utility_that_bounds_every_completion(
    values: list[float | None],
) -> None:
    given_values = dict(zip(ATTRS, values, strict=True))
    ev = relaxed(given_values)
    got = _snapshot(ev)
    unknown = [k for k, v in given_values.items() if v is None]
    completions = [
        _snapshot(relaxed({**given_values, **dict(zip(unknown, fill, strict=True))}))
        for fill in itertools.product((0.0, 1.0), repeat=len(unknown))
    ]
    for node, (u, s) in got.items():
        if s is None:
            continue
        assert u is not None, f"{node} is {s} with an unknown utility"
        for done in completions:
            cu, cs = done[node]
            assert cs is s  # Kleene: what the known values decide, every completion agrees with
            assert cu is not None
            if node == "G2" and s is True:
                assert cu >= u - 1e-12  # a satisfied OR: the known maximum is a lower bound
            elif node != "O1" and s is False:
                assert cu <= u + 1e-12  # an unsatisfied goal: an upper bound
