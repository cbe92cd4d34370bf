"""A RELAX-ed goal's tolerance stated as an acceptance criterion, with the bound it implies.

The bound is found with the goal's own operator (:func:`anunnaki.goals.build_operator`), so
the case says what the evaluator does: ``AS MANY AS POSSIBLE`` 40 % with tolerance 20 % and
threshold 0.5 holds while the value is at least 30 %; ``EVENTUALLY`` within 0.25 s,
tolerance 0.5 s, threshold 0.5 holds while the condition last held at most 0.5 s ago.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from anunnaki.goals import AtemporalOperator, GoalSpec, History, TemporalOperator, build_operator

__all__ = ["Acceptance", "acceptance", "check_value"]

_STEPS = 60  # bisection steps: far below any unit a goal model writes


@dataclass(frozen=True)
class Acceptance:
    """A criterion on one figure.

    Attributes:
        text: The criterion in words (``≥ 30 %``).
        at_least / at_most: Its bounds (both for a band; ``None`` where open).
        relax: The RELAX statement it comes from, when it does.

    """

    text: str
    at_least: float | None = None
    at_most: float | None = None
    relax: str | None = None


def check_value(value: float, acc: Acceptance) -> bool:
    """Whether ``value`` meets ``acc`` (a tiny slack for figures rounded when stored)."""
    eps = 1e-9
    if acc.at_least is not None and value < acc.at_least - eps:
        return False
    return not (acc.at_most is not None and value > acc.at_most + eps)


def _num(x: float) -> str:
    return f"{x:.4g}"


def _operator_words(operator: str) -> str:
    words = operator.removesuffix("_frequency").removesuffix("_quantity")
    return words.replace("_", " ").upper()


def relax_statement(goal: GoalSpec) -> str | None:
    """``RELAX AS MANY AS POSSIBLE 40 % (tolerance 20 %), threshold 0.5`` or ``None``."""
    spec = goal.relax
    if spec is None:
        return None
    unit = f" {spec.unit}" if spec.unit else ""
    fields: dict[str, Any] = spec.model_dump(exclude={"operator", "unit"}, exclude_none=True)
    parts = []
    for key in ("target", "within"):
        if key in fields:
            parts.append(f"{key} {_num(fields.pop(key))}{unit}")
    if "tolerance" in fields:
        parts.append(f"tolerance {_num(fields.pop('tolerance'))}{unit}")
    side = fields.pop("side", "both")
    if side != "both":
        parts.append(side.replace("_", " "))
    parts += [f"{k} {v}" for k, v in fields.items()]
    threshold = goal.threshold if goal.threshold is not None else 1.0
    return (
        f"RELAX {_operator_words(spec.operator)} ({', '.join(parts)}), threshold {_num(threshold)}"
    )


def acceptance(goal: GoalSpec) -> Acceptance | None:
    """The acceptance criterion a RELAX-ed goal states, or ``None`` for a crisp goal."""
    spec = goal.relax
    if spec is None:
        return None
    statement = relax_statement(goal)
    threshold = goal.threshold if goal.threshold is not None else 1.0
    op = build_operator(spec)
    unit = f" {spec.unit}" if spec.unit else ""
    subject = goal.utility or "the value"
    if isinstance(op, AtemporalOperator) and hasattr(spec, "target") and hasattr(spec, "tolerance"):
        target, tol = float(spec.target), float(spec.tolerance)
        lo, hi = target - tol, target + tol
        u = op.utility
        rises = u(lo) < u(target)
        falls = u(hi) < u(target)
        low = _cross(u, lo, target, threshold) if rises else None
        high = _cross(u, hi, target, threshold) if falls else None
        if low is not None and high is not None:
            text = f"{subject} between {_num(low)} and {_num(high)}{unit}"
        elif low is not None:
            text = f"{subject} ≥ {_num(low)}{unit}"
        elif high is not None:
            text = f"{subject} ≤ {_num(high)}{unit}"
        else:
            text = f"utility of {subject} ≥ {_num(threshold)}"
        return Acceptance(f"{text} ({statement})", low, high, statement)
    if isinstance(op, TemporalOperator) and spec.operator == "eventually":
        gap = _eventually_gap(op, float(spec.within) + float(spec.tolerance), threshold)
        text = f"{goal.utility} held within the last {_num(gap)} s"
        return Acceptance(f"{text} ({statement})", None, gap, statement)
    if spec.operator == "shall":
        return Acceptance(
            f"{subject} ≥ {_num(threshold)} ({statement})", threshold, None, statement
        )
    return Acceptance(f"utility ≥ {_num(threshold)} ({statement})", None, None, statement)


def _cross(u: Any, outer: float, inner: float, threshold: float) -> float | None:
    """Where, between ``inner`` (utility meets threshold) and ``outer``, it stops meeting it.

    ``None`` when it does not meet it at ``inner``; ``outer`` when it still does there.
    """
    if u(inner) < threshold:
        return None
    if u(outer) >= threshold:
        return outer
    a, b = outer, inner
    for _ in range(_STEPS):
        mid = (a + b) / 2
        if u(mid) >= threshold:
            b = mid
        else:
            a = mid
    return round(b, 6)


def _eventually_gap(op: TemporalOperator, horizon: float, threshold: float) -> float:
    """The longest gap since the condition held at which the utility still meets threshold."""

    def utility(gap: float) -> float:
        history = History([(0.0, True), (1.0, False)])
        value = op.utility_at(history, None, 1.0 + gap)
        return 0.0 if value is None else value

    gap = _cross(utility, horizon, 0.0, threshold)
    return 0.0 if gap is None else gap
