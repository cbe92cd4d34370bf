"""Baseline managers for comparison (``anunnaki run --manager none|random``).

The self-adaptive exemplars (SUAVE, ReBeT) measure their manager against two baselines on
the same platform and scenario: *none* (no adaptation) and *random*. Both replace only the
planner's choice; monitoring, analysis, execution (actions, postconditions, escalation to
the fail-safe) and the knowledge base stay Utu's, so a comparison isolates the choice.

* ``none``: nothing ever starts; the tactics the planner would start stay queued.
* ``random``: whenever the planner would start tactics (so at the rate Utu decides, and
  at the same instants), one tactic is drawn uniformly, with a seeded generator, among
  all the tactics the planner could start at that instant: not in flight, not in its
  cooldown, not in conflict with one in flight, not waiting for an approval. The draw
  ignores the tactics' goal-model preconditions, which is what makes it a baseline: among
  the tactics whose preconditions hold, the rover's tactic set nearly always offers one,
  and the draw would be the planner's own choice. The planner's choices the draw displaced
  are consumed as if started: their episode has fired, so a tactic without a cooldown is
  not queued again before its preconditions clear (one with a cooldown may be queued again
  at the next instant, and the draw is repeated then). Each draw is recorded as a
  ``random_draw`` decision naming the displaced tactics.

Under either, the decision log (and ``anunnaki run``'s output) holds what the baseline did,
not what Utu would have done: the planner records none of its own choices (``selected``,
``deferred``) and asks no operator to approve a tactic the baseline would not start.
"""

from __future__ import annotations

import random
from collections.abc import Callable

from anunnaki.utu.cycle._mape import Planner, TacticRuntime

__all__ = ["MANAGERS", "baseline"]

#: The managers ``anunnaki run --manager`` knows: Utu's planner and the two baselines.
MANAGERS = ("utu", "none", "random")

Select = Callable[[Planner, list[TacticRuntime], float], list[TacticRuntime]]


def _none(planner: Planner, start: list[TacticRuntime], now: float) -> list[TacticRuntime]:
    return []


class _Random:
    """Draw one startable tactic uniformly whenever the planner would start any."""

    def __init__(self, seed: int) -> None:
        self.rng = random.Random(seed)

    def __call__(
        self, planner: Planner, start: list[TacticRuntime], now: float
    ) -> list[TacticRuntime]:
        if not start:
            return []
        candidates = [
            rt
            for rt in planner.runtimes.values()
            if rt.state in ("idle", "queued")
            and not rt.tactic.requires_approval
            and planner.blocked(rt, now) is None
        ]
        pick = self.rng.choice(candidates) if candidates else start[0]
        displaced = [rt for rt in start if rt is not pick]
        for rt in displaced:  # selection state only: nothing started, nothing to wait out
            rt.state = "idle"
            rt.fired = True
        planner.knowledge.record_decision(
            now,
            "random_draw",
            pick.name,
            displaced=[rt.name for rt in displaced],
            candidates=len(candidates),
        )
        return [pick]


def baseline(manager: str, seed: int = 0) -> Select | None:
    """The selection that replaces the planner's for ``manager`` (``None``: Utu's own)."""
    if manager == "utu":
        return None
    if manager == "none":
        return _none
    if manager == "random":
        return _Random(seed)
    raise ValueError(f"unknown manager {manager!r}; managers: {', '.join(MANAGERS)}")
