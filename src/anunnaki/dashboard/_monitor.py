"""The monitor pane's store: each agent topic's last message and freshness.

One row per topic the binding names, with the agents that publish on it. Freshness (last
arrival, count, rate, staleness) is :class:`anunnaki.goals.TopicFreshness`, the definition
the goal model's ``rate(A)`` and Utu's TopicWatch use, so the pane shows the rate the goal
model judges. The store calls it with its lock held.
"""

from __future__ import annotations

from typing import Any

from anunnaki.goals import GoalModel, TopicFreshness

__all__ = ["monitor_rows", "topics_of"]


class _Topic(TopicFreshness):
    """A monitored topic as the monitor pane shows it: last message and freshness."""

    def __init__(self, agents: list[str], staleness: float, window: int) -> None:
        super().__init__(staleness, window=window)
        self.agents = agents
        self.last_msg: Any = None
        self.version = 0


def topics_of(model: GoalModel) -> dict[str, _Topic]:
    """The binding's topics, each with its agents and the strictest staleness among them."""
    staleness = model.spec.staleness
    topics: dict[str, _Topic] = {}
    for agent in model.agents.values():
        for tb in agent.topics:
            entry = topics.get(tb.topic)
            if entry is None:
                entry = topics[tb.topic] = _Topic(
                    [], agent.staleness or staleness, model.spec.rate_window
                )
            entry.agents.append(agent.id)
            entry.staleness = min(entry.staleness, agent.staleness or staleness)
    return topics


def monitor_rows(topics: dict[str, _Topic], now: float, since: int) -> list[dict[str, Any]]:
    """The rows changed after version ``since`` (all of them for ``since`` 0)."""
    rows = []
    for topic, e in topics.items():
        if e.version <= since and since > 0:
            continue
        rows.append(
            {
                "topic": topic,
                "agents": e.agents,
                "last": e.last_msg,
                "last_t": e.last,
                "count": e.count,
                "rate": e.rate(now),
                "staleness": e.staleness,
                "stale": e.stale(now),
            }
        )
    return rows
