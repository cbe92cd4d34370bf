"""Goal-model evaluation speed: full evaluation vs incremental updates.

A generated goal model of about 1,000 goals (branching about 5, depth 5, about 200
attributes on 40 topics, AND/OR mixed, 20 obstacles) is evaluated

* fully (``Evaluator.evaluate_all``), and
* incrementally: one attribute changes (``Evaluator.set_value``) or one message arrives
  (``Evaluator.observe``, five attributes), re-evaluating only the paths to the root —
  with unknown values in the stream (one update in ten makes a value unknown).

As a baseline in the same process, a bare incremental min/max over the same tree (floats
only: no unknowns, no statuses, no obstacles, no expressions) runs the same updates. The
machine is shared and noisy, so the ratio to that baseline is the figure to compare.

Writes ``benchmarks/results/goals.json``.
"""

from __future__ import annotations

import argparse
import json
import platform
import random
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

from anunnaki.goals import AttrRef, Evaluator, GoalModel, parse_goal_model

N_TOPICS = 40
ATTRS_PER_TOPIC = 5


def generate(seed: int = 1, depth: int = 5, branching: tuple[int, int] = (5, 6)) -> dict[str, Any]:
    rng = random.Random(seed)
    agents = [
        {
            "id": f"A{a}",
            "topics": [
                {"topic": f"/sys/agent{a}", "attributes": [f"v{k}" for k in range(ATTRS_PER_TOPIC)]}
            ],
            "staleness": 1e9,
        }
        for a in range(N_TOPICS)
    ]
    goals: list[dict[str, Any]] = []
    counter = [0]

    def new_id() -> str:
        counter[0] += 1
        return f"G{counter[0]}"

    def build(level: int) -> str:
        gid = new_id()
        if level == depth - 1:
            a, k = rng.randrange(N_TOPICS), rng.randrange(ATTRS_PER_TOPIC)
            kind = rng.random()
            if kind < 0.5:
                util = f"A{a}.v{k} >= 0.5"
            elif kind < 0.8:
                b, m = rng.randrange(N_TOPICS), rng.randrange(ATTRS_PER_TOPIC)
                util = f"A{a}.v{k} > 0.2 and A{b}.v{m} < 0.9"
            else:
                util = f"A{a}.v{k}"
            goals.append({"id": gid, "utility": util})
            return gid
        goal: dict[str, Any] = {"id": gid, "refinement": rng.choice(["and", "or"])}
        goals.append(goal)
        goal["children"] = [build(level + 1) for _ in range(rng.randint(*branching))]
        return gid

    root = build(0)
    obstacles = [
        {
            "id": f"O{i}",
            "obstructs": [rng.choice(goals)["id"]],
            "condition": f"A{rng.randrange(N_TOPICS)}.v{rng.randrange(ATTRS_PER_TOPIC)} > 0.95",
        }
        for i in range(20)
    ]
    return {
        "anunnaki": "goal-model/1",
        "name": "generated",
        "root": root,
        "agents": agents,
        "goals": goals,
        "obstacles": obstacles,
    }


class BareMinMax:
    """The baseline: incremental min/max propagation over floats, nothing else.

    Built from the goal model's public structure: each goal's children and refinement, and
    which attributes each leaf goal's utility reads (attribute ``k`` of ``refs``).
    """

    def __init__(self, model: GoalModel, refs: list[AttrRef]) -> None:
        ids = list(model.goals)
        index = {gid: i for i, gid in enumerate(ids)}
        n = len(ids)
        goals = [model.goals[gid] for gid in ids]
        self.kind = [0 if not g.children else 1 if g.refinement == "and" else 2 for g in goals]
        self.children = [[index[c] for c in g.children if c in index] for g in goals]
        self.parents: list[list[int]] = [[] for _ in range(n)]
        for i, ch in enumerate(self.children):
            for c in ch:
                self.parents[c].append(i)
        self.util = [0.0] * n
        slot = {ref: k for k, ref in enumerate(refs)}
        self.leaf_of_slot: dict[int, list[int]] = {}
        for i, gid in enumerate(ids):
            expr = model.expressions.get((gid, "utility"))
            if self.kind[i] == 0 and expr is not None:
                for ref in sorted(expr.refs):
                    self.leaf_of_slot.setdefault(slot[ref], []).append(i)

    def set(self, slot: int, value: float) -> None:
        util, kind, children, parents = self.util, self.kind, self.children, self.parents
        stack = []
        for leaf in self.leaf_of_slot.get(slot, ()):
            if util[leaf] != value:
                util[leaf] = value
                stack.extend(parents[leaf])
        while stack:
            i = stack.pop()
            vals = [util[c] for c in children[i]]
            u = min(vals) if kind[i] == 1 else max(vals)
            if u != util[i]:
                util[i] = u
                stack.extend(parents[i])


def timed(fn: Any, repeat: int) -> list[float]:
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--updates", type=int, default=100_000, help="set_value calls per run")
    parser.add_argument("--messages", type=int, default=20_000, help="observe calls per run")
    parser.add_argument("--repeat", type=int, default=3, help="runs of each (the fastest counts)")
    parser.add_argument("--output", default=str(Path(__file__).parent / "results" / "goals.json"))
    args = parser.parse_args()
    data = generate()
    text = yaml.safe_dump(data, sort_keys=False)
    t0 = time.perf_counter()
    model = parse_goal_model(text, source="generated.yaml")
    load_s = time.perf_counter() - t0
    ev = Evaluator(model)
    n_goals = len(model.goals)
    n_attrs = len(model.attribute_refs())
    leaves = sum(1 for g in model.goals.values() if not g.children)
    depth = 0
    stack = [(model.root, 1)]
    while stack:
        node, d = stack.pop()
        depth = max(depth, d)
        stack.extend((c, d + 1) for c in model.goals[node].children)
    refined = [g for g in model.goals.values() if g.children]
    branching = statistics.mean(len(g.children) for g in refined)

    rng = random.Random(7)
    topics = [f"/sys/agent{a}" for a in range(N_TOPICS)]
    for topic in topics:  # everything known to start with
        ev.observe(topic, {f"v{k}": rng.random() for k in range(ATTRS_PER_TOPIC)}, 0.0)

    full = timed(lambda: ev.evaluate_all(0.0), 10 * args.repeat)

    n_updates = args.updates
    refs = sorted(model.attribute_refs())
    updates = []
    for _ in range(n_updates):
        ref = rng.choice(refs)
        value = None if rng.random() < 0.1 else rng.random()
        updates.append((ref, value))

    def run_incremental() -> None:
        set_value = ev.set_value
        for ref, value in updates:
            set_value(ref, value, 1.0)

    bare = BareMinMax(model, refs)
    slot_of = {ref: k for k, ref in enumerate(refs)}
    slot_updates = [(slot_of[ref], rng.random()) for ref, _ in updates]

    def run_bare() -> None:
        s = bare.set
        for slot, value in slot_updates:
            s(slot, value)

    # In alternation, so that a busy moment of the shared machine hits both alike.
    inc: list[float] = []
    bare_times: list[float] = []
    for _ in range(args.repeat):
        inc += timed(run_incremental, 1)
        bare_times += timed(run_bare, 1)
    inc_rate = n_updates / min(inc)
    bare_rate = n_updates / min(bare_times)

    messages = [
        (
            rng.choice(topics),
            {
                f"v{k}": (None if rng.random() < 0.1 else rng.random())
                for k in range(ATTRS_PER_TOPIC)
            },
        )
        for _ in range(args.messages)
    ]
    # JSON null means the field is there with value null: the attribute is unknown.

    def run_messages() -> None:
        observe = ev.observe
        for i, (topic, msg) in enumerate(messages):
            observe(topic, msg, 2.0 + i * 1e-6)

    msg_times = timed(run_messages, args.repeat)
    msg_rate = len(messages) / min(msg_times)

    # Explanations are lazy: measure one on demand for the root.
    explain = timed(lambda: ev.explain(model.root), 20)

    result = {
        "benchmark": "goals",
        "python": platform.python_version(),
        "machine": platform.machine(),
        "model": {
            "goals": n_goals,
            "leaves": leaves,
            "obstacles": len(model.obstacles),
            "attributes": n_attrs,
            "depth": depth,
            "mean_branching": round(branching, 2),
        },
        "load_and_resolve_s": round(load_s, 4),
        "full_evaluation_ms": {
            "median": round(statistics.median(full) * 1e3, 3),
            "min": round(min(full) * 1e3, 3),
        },
        "incremental_updates_per_s": round(inc_rate),
        "incremental_update_us": round(1e6 / inc_rate, 2),
        "messages_per_s": round(msg_rate),
        "full_over_incremental_ratio": round(min(full) * inc_rate, 1),
        "explain_root_ms": round(statistics.median(explain) * 1e3, 3),
        "baseline_bare_minmax_updates_per_s": round(bare_rate),
        "incremental_over_baseline": round(inc_rate / bare_rate, 3),
        "unknown_fraction_in_updates": 0.1,
        "aim_updates_per_s": 50_000,
        "aim_over_baseline": 0.6,
        "runs": {"updates": n_updates, "messages": len(messages), "repeat": args.repeat},
    }
    out = Path(args.output)
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
