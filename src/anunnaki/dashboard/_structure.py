"""The goal model and tactics as the page draws them: a plain description, fixed for a run.

The page draws the goal tree, the obstacles, the agents and the tactics once, from this
description; it never changes during a run, so it is built from the loaded model and
tactic set alone, apart from the store of what the run publishes.
"""

from __future__ import annotations

from typing import Any

from anunnaki.goals import GoalModel
from anunnaki.tactics import TacticSet

__all__ = ["describe"]


def describe(name: str, model: GoalModel, tactics: TacticSet) -> dict[str, Any]:
    """The run's name, goal model and tactics as JSON-ready lists (see the page's script)."""
    goals = [
        {
            "id": g.id,
            "description": g.description,
            "refinement": g.refinement,
            "children": list(g.children),
            "utility": g.utility,
            "relax": None if g.relax is None else g.relax.operator,
            "agents": list(g.agents),
            "objective": g.objective,
        }
        for g in model.goals.values()
    ]
    obstacles = [
        {
            "id": o.id,
            "description": o.description,
            "obstructs": list(o.obstructs),
            "condition": o.condition,
            "resolutions": list(o.resolutions),
            "agents": list(o.agents),
        }
        for o in model.obstacles.values()
    ]
    agents = [
        {
            "id": a.id,
            "description": a.description,
            "topics": [{"topic": tb.topic, "attributes": list(tb.attributes)} for tb in a.topics],
            "goals": [g.id for g in model.goals.values() if a.id in g.agents],
            "obstacles": [o.id for o in model.obstacles.values() if a.id in o.agents],
        }
        for a in model.agents.values()
    ]
    rows = [
        {
            "name": t.name,
            "description": t.description,
            "priority": t.priority,
            "requires_approval": t.requires_approval,
            "deadline": t.deadline,
            "preconditions": [_describe_condition(c) for c in t.preconditions],
            "postconditions": [_describe_condition(c) for c in t.postconditions],
        }
        for t in tactics.tactics
    ]
    return {
        "name": name,
        "root": model.root,
        "goals": goals,
        "obstacles": obstacles,
        "agents": agents,
        "tactics": rows,
    }


def _describe_condition(cond: Any) -> str:
    goal = getattr(cond, "goal", None)
    if goal is not None:
        return f"{goal} {getattr(cond, 'state', '')}".strip()
    expression = getattr(cond, "expression", None)
    return str(expression) if expression is not None else str(cond)
