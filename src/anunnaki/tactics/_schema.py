"""What a tactic is: preconditions, postconditions, the tactic and the tactic set.

The actions are in :mod:`anunnaki.tactics._actions`, one class each.

Both file forms (XML as in the paper's Fig. 10, and YAML) are read into the same plain data
(dicts, lists, scalars) together with a :class:`~anunnaki._safeyaml.LineMap` from element paths
to lines; :func:`build_tactic_set` validates that data with the pydantic models below and turns
the first problem into a :class:`~anunnaki.errors.ModelFileError` naming file, line and element.

Where an element was written is not part of what it *is*: every model keeps a private
:class:`SourceRef` (read it through ``.source``) that takes no part in equality or dumps, so
a tactic loaded from XML equals the same tactic loaded from YAML. Loaders set it after
validation from the same element-path → line map that locates their errors.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Annotated, Any, Final, Literal

from pydantic import (
    Discriminator,
    Field,
    Tag,
    model_validator,
)

from anunnaki.tactics._actions import Action
from anunnaki.tactics._values import (
    EndpointReference,
    ExpressionReference,
    Filled,
    GoalId,
    GoalReference,
    Line,
    Seconds,
    Text,
    _error,
    _Model,
    tactic_element,
)

__all__ = [
    "ExpressionCondition",
    "GoalState",
    "Precondition",
    "Tactic",
    "TacticSet",
]

# --------------------------------------------------------------------------- conditions


class GoalState(_Model):
    """A goal in a state: ``{goal: G3, state: unsatisfied}``.

    As a precondition it holds when the goal is in that state; as a postcondition the goal is
    expected in that state by the tactic's deadline. ``unknown`` means the goal cannot be
    evaluated (a value is missing or stale).
    """

    goal: GoalId
    state: Literal["satisfied", "unsatisfied", "unknown"]


class ExpressionCondition(_Model):
    """A precondition given as a utility expression: ``{expression: "A4.category >= 1"}``.

    The string is kept as written; :mod:`anunnaki.goals` compiles it against the goal model's
    agents, and the precondition holds when the expression is true.
    """

    expression: Annotated[Text, Filled]


def _precondition_form(value: Any) -> str | None:
    if isinstance(value, GoalState):
        return "goal"
    if isinstance(value, ExpressionCondition):
        return "expression"
    if isinstance(value, Mapping):
        if "expression" in value and "goal" not in value and "state" not in value:
            return "expression"
        if "goal" in value or "state" in value:
            return None if "expression" in value else "goal"
    return None


PRECONDITION_HINT: Final = (
    "write either goal and state (e.g. goal: G3, state: unsatisfied) or expression"
)

Precondition = Annotated[
    Annotated[GoalState, Tag("goal")] | Annotated[ExpressionCondition, Tag("expression")],
    Discriminator(
        _precondition_form,
        custom_error_type="precondition_form",
        custom_error_message="a precondition is either a goal state or an expression",
        custom_error_context={"hint": PRECONDITION_HINT},
    ),
]
"""A precondition: a :class:`GoalState` or an :class:`ExpressionCondition`."""


# --------------------------------------------------------------------------- tactics


class Tactic(_Model):
    """An adaptation tactic: when all preconditions hold, run the actions in order.

    Attributes:
        name: Unique within its set.
        description: Free text for people (dashboard, decision log).
        priority: Higher runs first when several tactics apply at once.
        preconditions: All must hold for the tactic to apply (at least one).
        actions: Run in order (at least one).
        postconditions: Goal states expected after the actions, checked by ``deadline``.
        deadline: Seconds after the last action by which the postconditions must hold.
        cooldown: Seconds after a run during which the tactic is not started again.
        requires_approval: An operator must approve each run before it starts.
        conflicts: Names of tactics that must not be in flight at the same time.

    """

    name: Annotated[Line, Filled, Field(max_length=128)]
    description: Text = ""
    priority: Annotated[int, Field(ge=-1_000_000, le=1_000_000)] = 0
    preconditions: Annotated[list[Precondition], Field(min_length=1)]
    actions: Annotated[list[Action], Field(min_length=1)]
    postconditions: list[GoalState] = Field(default_factory=list)
    deadline: Annotated[Seconds, Field(gt=0)] = 5.0
    cooldown: Annotated[Seconds, Field(ge=0)] = 0.0
    requires_approval: bool = False
    conflicts: list[Annotated[Line, Filled]] = Field(default_factory=list)

    @model_validator(mode="after")
    def _consistent(self) -> Tactic:
        for field in ("preconditions", "postconditions"):
            seen: set[str] = set()
            for i, cond in enumerate(getattr(self, field)):
                if not isinstance(cond, GoalState):
                    continue  # an expression precondition
                if cond.goal in seen:
                    raise _error(
                        "repeated_goal",
                        f"goal {cond.goal} appears twice in the {field}",
                        hint="state each goal once",
                        where=(field, i),
                    )
                seen.add(cond.goal)
        names: set[str] = set()
        for i, other in enumerate(self.conflicts):
            if other == self.name:
                raise _error(
                    "conflict_self",
                    f"tactic {self.name!r} lists itself in 'conflicts'",
                    hint="a tactic never runs twice at once anyway; remove it",
                    where=("conflicts", i),
                )
            if other in names:
                raise _error(
                    "conflict_repeated",
                    f"{other!r} appears twice in 'conflicts'",
                    hint="name each tactic once",
                    where=("conflicts", i),
                )
            names.add(other)
        return self

    def _element(self, *parts: str | int) -> str:
        return tactic_element(self.name, parts)

    def _goal_refs(self) -> Iterator[tuple[str, GoalReference]]:
        for key, conditions in (
            ("preconditions", self.preconditions),
            ("postconditions", self.postconditions),
        ):
            for i, cond in enumerate(conditions):
                if isinstance(cond, GoalState):
                    yield cond.goal, GoalReference(self._element(key, i), cond.source.line)

    def referenced_goals(self) -> dict[str, list[GoalReference]]:
        """Map each goal id this tactic names to where it names it.

        Returns:
            ``{"G3": [GoalReference("tactics[fail-safe].preconditions[0]", 9), ...]}``, in
            file order (preconditions, then postconditions).

        """
        out: dict[str, list[GoalReference]] = {}
        for goal, ref in self._goal_refs():
            out.setdefault(goal, []).append(ref)
        return out

    def referenced_endpoints(self) -> list[EndpointReference]:
        """List every topic and service the actions use, with the payload each sends.

        ``change_mode`` sends ``{"mode": mode}``; ``swap_model`` sends ``{"lec": …, "model": …}``
        or ``{"lec": …, "domain": …}``; ``notify`` uses no endpoint and is not listed.
        """
        out: list[EndpointReference] = []
        for i, action in enumerate(self.actions):
            sent = action.endpoint()
            if sent is not None:
                kind, name, payload = sent
                out.append(
                    EndpointReference(
                        kind, name, payload, self._element("actions", i), action.source.line
                    )
                )
        return out

    def expressions(self) -> list[ExpressionReference]:
        """List the expression preconditions, as written, with element and line."""
        return [
            ExpressionReference(
                cond.expression, self._element("preconditions", i), cond.source.line
            )
            for i, cond in enumerate(self.preconditions)
            if isinstance(cond, ExpressionCondition)
        ]


class TacticSet(_Model):
    """The tactics of one file.

    Attributes:
        name: Optional name of the set (e.g. the managed system).
        tactics: The tactics, names unique; ``conflicts`` must name tactics of this set.

    """

    name: Annotated[Line, Filled] | None = None
    tactics: list[Tactic]

    @model_validator(mode="after")
    def _names(self) -> TacticSet:
        first: dict[str, int] = {}
        for i, tactic in enumerate(self.tactics):
            if tactic.name in first:
                raise _error(
                    "duplicate_tactic",
                    f"tactic name {tactic.name!r} is used twice",
                    hint="give each tactic its own name",
                    where=("tactics", i, "name"),
                    other=("tactics", first[tactic.name], "name"),
                )
            first[tactic.name] = i
        for i, tactic in enumerate(self.tactics):
            for k, other in enumerate(tactic.conflicts):
                if other not in first:
                    raise _error(
                        "unknown_conflict",
                        f"tactic {tactic.name!r} conflicts with {other!r}, which is not "
                        "a tactic of this file",
                        hint="known tactics: " + ", ".join(sorted(first)),
                        where=("tactics", i, "conflicts", k),
                    )
        return self

    def tactic(self, name: str) -> Tactic:
        """Return the tactic called ``name``.

        Raises:
            KeyError: no such tactic (the message lists the known names).

        """
        for tactic in self.tactics:
            if tactic.name == name:
                return tactic
        raise KeyError(f"no tactic {name!r}; known: {', '.join(t.name for t in self.tactics)}")

    def by_priority(self) -> list[Tactic]:
        """Return the tactics highest priority first; equal priorities keep file order."""
        return sorted(self.tactics, key=lambda t: -t.priority)

    def in_conflict(self, a: str, b: str) -> bool:
        """Tell whether tactics ``a`` and ``b`` must not be in flight together.

        Conflicts are symmetric: it is enough that either tactic lists the other.
        """
        return b in self.tactic(a).conflicts or a in self.tactic(b).conflicts

    def referenced_goals(self) -> dict[str, list[GoalReference]]:
        """Map each goal id named anywhere in the set to the places that name it."""
        out: dict[str, list[GoalReference]] = {}
        for tactic in self.tactics:
            for goal, ref in tactic._goal_refs():
                out.setdefault(goal, []).append(ref)
        return out

    def referenced_endpoints(self) -> list[EndpointReference]:
        """List every topic and service used by any action, in file order."""
        return [ref for t in self.tactics for ref in t.referenced_endpoints()]

    def expressions(self) -> list[ExpressionReference]:
        """List every expression precondition in the set, in file order."""
        return [ref for t in self.tactics for ref in t.expressions()]
