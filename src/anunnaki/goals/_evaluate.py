"""Evaluation of a goal model as a logic tree (paper Fig. 9), incremental and three-valued.

Every goal and obstacle is a *node* with a utility in [0, 1] and a status: satisfied
(``True``), unsatisfied (``False``) or unknown (``None``). An obstacle's "status" says
whether it *holds*.

* A leaf goal's utility is its expression's value mapped to [0, 1] (booleans 0/1, numbers
  clamped), through its RELAX operator if it has one; an ``avoid`` goal takes ``1 - u``.
  It is satisfied when the utility reaches its threshold (1.0 for crisp goals).
* AND takes the minimum of its children's utilities, OR the maximum; satisfaction is the
  boolean AND / OR of the children's satisfaction.
* An obstacle O obstructing g gives ``u(g) = min(u, 1 - u(O))`` and ``sat(g) = sat and not
  holds(O)`` — unless one of O's resolution goals is satisfied.
* Unknown propagates by Kleene's rules: ``min(0, ?) = 0`` and ``false and ? = false``,
  ``max(1, ?) = 1`` and ``true or ? = true``; otherwise the result is unknown. When the known
  children decide a refined goal's status they decide its utility too, over the known
  children: a satisfied OR takes their maximum (a lower bound), an unsatisfied AND or
  obstructed goal their minimum (an upper bound). A known status has a known utility.

The evaluator keeps every attribute value in a flat list of slots. :meth:`Evaluator.observe`
writes the slots a message feeds and re-evaluates only the nodes that read them and, while
their result changes, their dependents, children before parents. :meth:`Evaluator.tick`
applies what time alone changes: values going stale, message rates decaying through a
silence, temporal RELAX operators. :meth:`Evaluator.evaluate_all` recomputes everything from
scratch and always agrees with the incremental path (a Hypothesis property checks it).

Nothing here reads a clock: every call takes ``now`` in seconds, from whatever clock the
caller injects (wall clock live, simulation clock in simulation, recorded time in replay).
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Final, Literal

from anunnaki.errors import ModelFileError
from anunnaki.goals._expr import ABSENT, AttrRef, Expression, truth
from anunnaki.goals._forecast import Forecaster
from anunnaki.goals._freshness import RateEstimator, is_stale
from anunnaki.goals._history import History
from anunnaki.goals._model import GoalModel
from anunnaki.goals._relax_ops import AtemporalOperator, MayOrOperator, RelaxOperator
from anunnaki.goals._relax_temporal import TemporalOperator

__all__ = ["Evaluator", "Explanation", "NodeState", "Status", "status_name"]

Status = bool | None
StatusName = Literal["satisfied", "unsatisfied", "unknown"]

_LEAF: Final = 0
_AND: Final = 1
_OR: Final = 2
_OBSTACLE: Final = 3
_EPS: Final = 1e-9


def status_name(status: Status) -> StatusName:
    """``True``/``False``/``None`` → ``satisfied``/``unsatisfied``/``unknown``."""
    return "unknown" if status is None else "satisfied" if status else "unsatisfied"


@dataclass(frozen=True)
class NodeState:
    """The evaluated state of one goal or obstacle."""

    id: str
    kind: Literal["goal", "obstacle"]
    utility: float | None
    status: Status

    @property
    def status_name(self) -> StatusName:
        """``satisfied``, ``unsatisfied`` or ``unknown`` (for an obstacle: it holds or not)."""
        return status_name(self.status)


@dataclass
class Explanation:
    """Why a node has its status: a summary and the leaf values that decided it."""

    node: str
    kind: Literal["goal", "obstacle"]
    status: Status
    utility: float | None
    summary: str
    leaves: dict[str, Any] = field(default_factory=dict)
    because: list[Explanation] = field(default_factory=list)

    def render(self, indent: str = "") -> str:
        """Render as indented text, one line per node."""
        lines = [indent + self.summary]
        for sub in self.because:
            lines.append(sub.render(indent + "  "))
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready form."""
        return {
            "node": self.node,
            "kind": self.kind,
            "status": status_name(self.status),
            "utility": self.utility,
            "summary": self.summary,
            "leaves": {k: _jsonable(v) for k, v in self.leaves.items()},
            "because": [b.to_dict() for b in self.because],
        }


def _jsonable(v: Any) -> Any:
    return None if v is ABSENT else v


@dataclass
class _Topic:
    name: str
    staleness: float
    # (slot, field path split on '.')
    fields: list[tuple[int, tuple[str, ...]]] = field(default_factory=list)
    rated: list[int] = field(default_factory=list)  # agent indices whose primary topic this is
    last: float | None = None
    stale: bool = True


class Evaluator:
    """Evaluates a :class:`GoalModel` incrementally as messages and time arrive.

    Args:
        model: The resolved goal model.
        conditions: Extra named expressions over the same inputs (e.g. tactic
            preconditions), read on demand with :meth:`condition`.
        on_error: Called with (node id, exception) when a node's computation raises; the
            node becomes unknown and evaluation goes on. Defaults to ignoring.

    """

    def __init__(
        self,
        model: GoalModel,
        *,
        conditions: Mapping[str, Expression] | None = None,
        on_error: Callable[[str, BaseException], None] | None = None,
    ) -> None:
        self.model = model
        self.now = float("-inf")
        self._on_error = on_error
        self.ids: list[str] = [*model.goals, *model.obstacles]
        self.index: dict[str, int] = {n: i for i, n in enumerate(self.ids)}
        n = len(self.ids)
        self.util: list[float | None] = [None] * n
        self.stat: list[Status] = [None] * n
        self._kind: list[int] = [0] * n
        self._fn: list[Callable[[list[Any]], Any] | None] = [None] * n
        self._children: list[tuple[int, ...]] = [()] * n
        self._obstr: list[tuple[tuple[int, tuple[int, ...]], ...]] = [()] * n
        self._thresh: list[float] = [1.0] * n
        self._avoid: list[bool] = [False] * n
        self._relax: list[RelaxOperator | None] = [None] * n
        self._temporal: list[int] = []
        self._hist: dict[int, tuple[History, History | None, Callable[..., Any] | None]] = {}
        self._alts: dict[int, list[Callable[[list[Any]], Any]]] = {}
        self._deps: list[list[int]] = [[] for _ in range(n)]
        self._changed: set[int] = set()
        # slots
        self.slots: list[Any] = []
        self._slot_ref: list[AttrRef | str] = []
        self._slot_of_ref: dict[AttrRef, int] = {}
        self._rate_slot: dict[str, int] = {}
        self._slot_readers: list[list[int]] = []
        self._build_slots_and_nodes()
        self._build_forecasts()
        self._conditions: dict[str, Callable[[list[Any]], Any]] = {}
        for name, expr in (conditions or {}).items():
            self._conditions[name] = expr.bind(self._slot, self._rslot)
        self._order = self._topological_order()
        self._height = [0] * n
        for pos, i in enumerate(self._order):
            self._height[i] = pos
        # What computes each node: its kind's own computation when nothing obstructs it
        # (one call per node on the hot path), the general one otherwise.
        self._calc: list[Callable[[int], tuple[float | None, Status]]] = [
            self._calculator(i) for i in range(n)
        ]
        self._thresh_eps = [t - _EPS for t in self._thresh]
        self._reader_tuples = [tuple(sorted(set(r))) for r in self._slot_readers]
        self._deps_t = [tuple(sorted(set(d))) for d in self._deps]
        self._build_topics()
        self.evaluate_all()
        self._changed.clear()

    # -- construction -------------------------------------------------------------------
    def _slot(self, ref: AttrRef) -> int:
        i = self._slot_of_ref.get(ref)
        if i is None:
            i = len(self.slots)
            self.slots.append(None)
            self._slot_ref.append(ref)
            self._slot_readers.append([])
            self._slot_of_ref[ref] = i
        return i

    def _rslot(self, agent: str) -> int:
        i = self._rate_slot.get(agent)
        if i is None:
            i = len(self.slots)
            self.slots.append(None)
            self._slot_ref.append(f"rate({agent})")
            self._slot_readers.append([])
            self._rate_slot[agent] = i
        return i

    def _bind(self, node: int, expr: Expression) -> Callable[[list[Any]], Any]:
        used: list[int] = []

        def slot_of(ref: AttrRef) -> int:
            s = self._slot(ref)
            used.append(s)
            return s

        def rate_slot_of(agent: str) -> int:
            s = self._rslot(agent)
            used.append(s)
            return s

        fn = expr.bind(slot_of, rate_slot_of)
        for s in used:
            self._slot_readers[s].append(node)
        return fn

    def _build_slots_and_nodes(self) -> None:
        m = self.model
        for gid, g in m.goals.items():
            i = self.index[gid]
            self._avoid[i] = g.objective == "avoid"
            if g.children:
                self._kind[i] = _AND if g.refinement == "and" else _OR
                self._children[i] = tuple(self.index[c] for c in g.children if c in m.goals)
                for c in self._children[i]:
                    self._deps[c].append(i)
            else:
                self._kind[i] = _LEAF
                self._thresh[i] = g.threshold if g.threshold is not None else 1.0
                expr = m.expressions.get((gid, "utility"))
                if expr is not None:
                    self._fn[i] = self._bind(i, expr)
                op = m.relax.get(gid)
                self._relax[i] = op
                if op is not None:
                    self._setup_relax(i, gid, op)
        for oid, o in m.obstacles.items():
            i = self.index[oid]
            self._kind[i] = _OBSTACLE
            self._thresh[i] = o.threshold
            expr = m.expressions.get((oid, "condition"))
            if expr is not None:
                self._fn[i] = self._bind(i, expr)
        for gid, obstacle_ids in m.obstructed_by.items():
            gi = self.index[gid]
            entries: list[tuple[int, tuple[int, ...]]] = []
            for oid in obstacle_ids:
                oi = self.index[oid]
                res = tuple(self.index[r] for r in m.obstacles[oid].resolutions if r in m.goals)
                entries.append((oi, res))
                self._deps[oi].append(gi)
                for r in res:
                    self._deps[r].append(gi)
            self._obstr[gi] = tuple(entries)

    def _build_forecasts(self) -> None:
        """A slot per forecast (the binding's ``forecasts:``) and the slots it reads."""
        self._forecasts: list[tuple[int, int, int | float, int | float, Forecaster]] = []
        self._fc_field: dict[int, list[int]] = {}  # field slot -> forecasts sampling it
        self._fc_input: dict[int, list[int]] = {}  # any input slot -> forecasts reading it

        def source(ref: str | float) -> int | float:
            if isinstance(ref, str):
                agent, _, attr = ref.partition(".")
                return self._slot(AttrRef(agent, attr))
            return float(ref)

        for agent in self.model.agents.values():
            for name, spec in agent.forecasts.items():
                k = len(self._forecasts)
                out = self._slot(AttrRef(agent.id, name))
                fld = self._slot(AttrRef(agent.id, spec.of))
                dist, speed = source(spec.distance), source(spec.speed)
                self._forecasts.append((out, fld, dist, speed, Forecaster(spec.window)))
                self._fc_field.setdefault(fld, []).append(k)
                for slot in {fld, dist, speed}:
                    if isinstance(slot, int):
                        self._fc_input.setdefault(slot, []).append(k)

    def _refresh_forecasts(self, slots: Iterable[int], now: float | None) -> list[int]:
        """Recompute the forecasts reading ``slots``; with ``now``, sample their fields first.

        Returns the nodes to re-evaluate (the readers of the forecasts that changed).
        """
        hit: set[int] = set()
        for slot in slots:
            if now is not None:
                for k in self._fc_field.get(slot, ()):
                    self._forecasts[k][4].sample(now, self.slots[slot])
            hit.update(self._fc_input.get(slot, ()))
        dirty: list[int] = []
        values = self.slots
        for k in sorted(hit):
            out, fld, dist, speed, fc = self._forecasts[k]
            value = fc.value(
                values[fld],
                values[dist] if isinstance(dist, int) else dist,
                values[speed] if isinstance(speed, int) else speed,
            )
            if values[out] != value:
                values[out] = value
                dirty.extend(self._reader_tuples[out])
        return dirty

    def _setup_relax(self, i: int, gid: str, op: RelaxOperator) -> None:
        m = self.model
        alts = [
            self._bind(i, e)
            for (eid, role), e in sorted(m.expressions.items())
            if eid == gid and role.startswith("alternative")
        ]
        if alts:
            self._alts[i] = alts
        if op.kind == "temporal":
            self._temporal.append(i)
            event_expr = m.expressions.get((gid, "event"))
            event_fn = self._bind(i, event_expr) if event_expr is not None else None
            self._hist[i] = (History(), History() if event_fn is not None else None, event_fn)

    def _topological_order(self) -> list[int]:
        n = len(self.ids)
        indeg = [0] * n
        for d in self._deps:
            for j in set(d):
                indeg[j] += 1
        ready = [i for i in range(n) if indeg[i] == 0]
        order: list[int] = []
        while ready:
            i = ready.pop()
            order.append(i)
            for j in set(self._deps[i]):
                indeg[j] -= 1
                if indeg[j] == 0:
                    ready.append(j)
        if len(order) != n:
            stuck = sorted(self.ids[i] for i in range(n) if indeg[i] > 0)
            raise ModelFileError(
                "the goal model's dependencies form a cycle through " + ", ".join(stuck),
                path=self.model.path,
                element="obstacles",
                hint="a resolution goal may not depend on the goal its obstacle obstructs",
            )
        return order

    def _build_topics(self) -> None:
        self._topics: dict[str, _Topic] = {}
        self._rates: list[RateEstimator] = []
        self._rate_agents: list[str] = []
        for agent in self.model.agents.values():
            for tb in agent.topics:
                topic = self._topics.get(tb.topic)
                if topic is None:
                    topic = self._topics[tb.topic] = _Topic(tb.topic, agent.staleness)
                topic.staleness = min(topic.staleness, agent.staleness)
                for attr, fpath in tb.attributes.items():
                    ref = AttrRef(agent.id, attr)
                    if ref in self._slot_of_ref:
                        topic.fields.append((self._slot_of_ref[ref], tuple(fpath.split("."))))
            if agent.id in self._rate_slot and agent.primary_topic is not None:
                self._rates.append(RateEstimator(self.model.spec.rate_window))
                self._rate_agents.append(agent.id)
                self._topics[agent.primary_topic].rated.append(len(self._rates) - 1)
        self._next_stale = float("inf")

    # -- computing nodes ----------------------------------------------------------------
    def _leaf_utility(self, i: int) -> float | None:
        op = self._relax[i]
        if isinstance(op, MayOrOperator):
            alts = self._alts.get(i, [])
            u: float | None = op.utility_of_alternatives([truth(f(self.slots)) for f in alts])
            return None if u is None else (1.0 - u if self._avoid[i] else u)
        fn = self._fn[i]
        if fn is None:
            return None
        value = fn(self.slots)
        if op is None:
            u = truth(value)
        elif isinstance(op, TemporalOperator):
            if not math.isfinite(self.now):
                return None  # no time yet: nothing has been observed
            p_hist, e_hist, _ = self._hist[i]
            u = op.utility_at(p_hist, e_hist, self.now)
            if op.horizon < math.inf:
                p_hist.prune(self.now - op.horizon)
                if e_hist is not None:
                    e_hist.prune(self.now - op.horizon)
        elif value is None or isinstance(value, str) or not isinstance(op, AtemporalOperator):
            u = None
        else:
            u = op.utility(float(value))
        if u is not None and self._avoid[i]:
            u = 1.0 - u
        return u

    def _calculator(self, i: int) -> Callable[[int], tuple[float | None, Status]]:
        if self._obstr[i]:
            return self._compute
        k = self._kind[i]
        if k == _AND:
            return self._compute_and
        if k == _OR:
            return self._compute_or
        if k == _OBSTACLE or (self._relax[i] is None and not self._avoid[i]):
            return self._compute_crisp
        return self._compute_relaxed

    def _compute(self, i: int) -> tuple[float | None, Status]:
        k = self._kind[i]
        u: float | None
        s: Status
        if k == _AND:
            u, s = self._compute_and(i)
        elif k == _OR:
            u, s = self._compute_or(i)
        elif k == _OBSTACLE or (self._relax[i] is None and not self._avoid[i]):
            u, s = self._compute_crisp(i)
        else:
            u, s = self._compute_relaxed(i)
        obstr = self._obstr[i]
        if obstr:
            u, s = self._obstruct(u, s, obstr)
        return u, s

    def _compute_crisp(self, i: int) -> tuple[float | None, Status]:
        """The common leaf: a crisp expression (or an obstacle's condition) mapped to [0, 1]."""
        fn = self._fn[i]
        if fn is None:
            return None, None
        v = fn(self.slots)
        if v is True:
            return 1.0, self._thresh_eps[i] <= 1.0
        if v is False:
            return 0.0, self._thresh_eps[i] <= 0.0
        u = None if v is None else truth(v)
        return u, None if u is None else u >= self._thresh_eps[i]

    def _compute_relaxed(self, i: int) -> tuple[float | None, Status]:
        """A leaf through its RELAX operator, or an ``avoid`` goal."""
        u = self._leaf_utility(i)
        return u, None if u is None else u >= self._thresh_eps[i]

    def _compute_and(self, i: int) -> tuple[float | None, Status]:
        util, stat = self.util, self.stat
        lo = 1.0
        u_unknown = False
        s: Status = True
        for c in self._children[i]:
            cu = util[c]
            if cu is None:
                u_unknown = True
            elif cu < lo:
                lo = cu
            cs = stat[c]
            if cs is False:
                s = False
            elif cs is None and s is True:
                s = None
        # Kleene: min(0, ?) = 0. An AND that a known unsatisfied child fails takes the
        # minimum of the known children (an upper bound), so its utility is known too.
        return (None if u_unknown and lo > 0.0 and s is not False else lo), s

    def _compute_or(self, i: int) -> tuple[float | None, Status]:
        util, stat = self.util, self.stat
        hi = 0.0
        u_unknown = False
        s: Status = False
        for c in self._children[i]:
            cu = util[c]
            if cu is None:
                u_unknown = True
            elif cu > hi:
                hi = cu
            cs = stat[c]
            if cs is True:
                s = True
            elif cs is None and s is False:
                s = None
        # Kleene: max(1, ?) = 1. An OR that a known satisfied child satisfies takes the
        # maximum of the known children (a lower bound: an unknown child could only raise
        # it), so a satisfied OR never reports an unknown utility.
        return (None if u_unknown and hi < 1.0 and s is not True else hi), s

    def _obstruct(
        self, u: float | None, s: Status, obstr: tuple[tuple[int, tuple[int, ...]], ...]
    ) -> tuple[float | None, Status]:
        util, stat = self.util, self.stat
        for o, res in obstr:
            if any(stat[r] is True for r in res):
                continue  # resolved: the obstacle no longer obstructs
            ou = util[o]
            if ou is None:
                if u is not None and u > 0.0 and s is not False:
                    u = None  # an unsatisfied goal keeps its (upper-bound) utility
            elif u is not None:
                u = min(u, 1.0 - ou)
            elif ou >= 1.0 or stat[o] is True:
                u = 1.0 - ou  # Kleene: min(?, 0) = 0; a holding obstacle caps it (upper bound)
            os_ = stat[o]
            if os_ is True:
                s = False
            elif os_ is None and s is True:
                s = None
        return u, s

    def _safe_compute(self, i: int) -> tuple[float | None, Status]:
        try:
            return self._compute(i)
        except Exception as exc:  # a misbehaving operator must not kill the loop
            if self._on_error is not None:
                self._on_error(self.ids[i], exc)
            return None, None

    def _propagate(self, dirty: Iterable[int]) -> None:
        """Re-evaluate ``dirty`` nodes, then their dependents while results change.

        Nodes are processed in topological order (a heap of their positions in it), so each
        node is computed after every changed input it reads; a node whose result is
        unchanged stops the propagation along that path. A node is queued again for each
        input that changed; its copies come off the heap together and it is computed once.
        """
        height, order = self._height, self._order
        heap = [height[i] for i in dirty]
        heapq.heapify(heap)
        util, stat, deps, changed = self.util, self.stat, self._deps_t, self._changed
        calc = self._calc
        pop, push = heapq.heappop, heapq.heappush
        last = -1
        while heap:
            h = pop(heap)
            if h == last:
                continue
            last = h
            i = order[h]
            try:
                u, s = calc[i](i)
            except Exception as exc:  # a misbehaving operator must not kill the loop
                if self._on_error is not None:
                    self._on_error(self.ids[i], exc)
                u, s = None, None
            if u != util[i] or s is not stat[i]:
                util[i] = u
                stat[i] = s
                changed.add(i)
                for j in deps[i]:
                    push(heap, height[j])

    # -- inputs -------------------------------------------------------------------------
    def observe(self, topic: str, message: Mapping[str, Any], now: float) -> None:
        """Take one message that arrived on ``topic`` at time ``now`` (seconds).

        The fields the binding maps become the attributes' new values (a field missing from
        the message makes ``has`` false and the value unknown); topics nobody reads are
        ignored. Only the nodes that read a changed value are re-evaluated.
        """
        self.now = max(self.now, now)
        tp = self._topics.get(topic)
        if tp is None:
            return
        tp.last = now
        tp.stale = False
        deadline = now + tp.staleness
        self._next_stale = min(self._next_stale, deadline)
        slots = self.slots
        readers = self._reader_tuples
        dirty: list[int] = []
        for slot, fpath in tp.fields:
            value = _get_field(message, fpath)
            if slots[slot] != value or type(slots[slot]) is not type(value):
                slots[slot] = value
                dirty.extend(readers[slot])
        if self._forecasts:
            dirty.extend(self._refresh_forecasts([slot for slot, _ in tp.fields], now))
        for r in tp.rated:
            est = self._rates[r]
            est.arrive(now)
            slot = self._rate_slot[self._rate_agents[r]]
            value = est.rate(now)
            if slots[slot] != value:
                slots[slot] = value
                dirty.extend(readers[slot])
        if self._temporal:
            self._sample_temporal(dirty)
        if dirty:
            self._propagate(dirty)
        if now >= self._next_stale:
            self.tick(now)

    def set_value(self, ref: AttrRef | str, value: Any, now: float) -> None:
        """Set one attribute directly (tools and tests; live inputs go through observe)."""
        self.now = max(self.now, now)
        if isinstance(ref, str):
            agent, _, attr = ref.partition(".")
            ref = AttrRef(agent, attr)
        slot = self._slot_of_ref.get(ref)
        if slot is None:
            return
        self.slots[slot] = value
        dirty = list(self._reader_tuples[slot])
        if self._forecasts:
            dirty.extend(self._refresh_forecasts([slot], now))
        if self._temporal:
            self._sample_temporal(dirty)
        self._propagate(dirty)

    def _sample_temporal(self, dirty: Iterable[int]) -> None:
        wanted = set(dirty)
        for i in self._temporal:
            if i not in wanted:
                continue
            p_hist, e_hist, event_fn = self._hist[i]
            fn = self._fn[i]
            if fn is not None:
                p_hist.append(self.now, _holds(fn(self.slots)))
            if e_hist is not None and event_fn is not None:
                e_hist.append(self.now, _holds(event_fn(self.slots)))

    def tick(self, now: float) -> bool:
        """Apply what the passing of time changes, up to ``now``.

        Values of topics silent past their staleness deadline become unknown; rates decay
        through silences; temporal RELAX goals are re-evaluated. Returns whether any input
        value changed (a replay must then tick at the same instant to agree).
        """
        self.now = max(self.now, now)
        slots = self.slots
        readers = self._reader_tuples
        dirty = self._expire_stale(now)
        for r, est in enumerate(self._rates):
            if est.in_gap(now):
                slot = self._rate_slot[self._rate_agents[r]]
                value = est.rate(now)
                if slots[slot] != value:
                    slots[slot] = value
                    dirty.extend(readers[slot])
        changed = bool(dirty)
        if self._temporal:
            self._sample_temporal(dirty)
            dirty.extend(self._temporal)
        if dirty:
            self._propagate(dirty)
        return changed

    def _expire_stale(self, now: float) -> list[int]:
        """Make the values of topics silent past their staleness unknown; the nodes to redo."""
        slots = self.slots
        readers = self._reader_tuples
        dirty: list[int] = []
        gone: list[int] = []  # slots gone unknown
        next_stale = float("inf")
        for tp in self._topics.values():
            if tp.last is None or tp.stale:
                continue
            deadline = tp.last + tp.staleness
            if is_stale(tp.last, now, tp.staleness):
                tp.stale = True
                for slot, _ in tp.fields:
                    if slots[slot] is not None:
                        slots[slot] = None
                        dirty.extend(readers[slot])
                        gone.append(slot)
            elif deadline < next_stale:
                next_stale = deadline
        self._next_stale = next_stale
        if gone and self._forecasts:
            dirty.extend(self._refresh_forecasts(gone, None))
        return dirty

    def expire(self, topic: str, now: float) -> None:
        """Make a topic's values unknown now (its publisher is known to be gone)."""
        self.now = max(self.now, now)
        tp = self._topics.get(topic)
        if tp is None:
            return
        tp.stale = True
        dirty: list[int] = []
        for slot, _ in tp.fields:
            if self.slots[slot] is not None:
                self.slots[slot] = None
                dirty.extend(self._reader_tuples[slot])
        if self._forecasts:
            dirty.extend(self._refresh_forecasts([slot for slot, _ in tp.fields], None))
        if self._temporal:
            self._sample_temporal(dirty)
        if dirty:
            self._propagate(dirty)

    def evaluate_all(self, now: float | None = None) -> None:
        """Recompute every node from the current values, children first."""
        if now is not None and now > self.now:
            self.now = now
        for i in self._order:
            u, s = self._safe_compute(i)
            if u != self.util[i] or s is not self.stat[i]:
                self._changed.add(i)
            self.util[i] = u
            self.stat[i] = s

    # -- outputs ------------------------------------------------------------------------
    def state(self, node: str) -> NodeState:
        """The state of one goal or obstacle."""
        i = self.index[node]
        kind: Literal["goal", "obstacle"] = "obstacle" if self._kind[i] == _OBSTACLE else "goal"
        return NodeState(node, kind, self.util[i], self.stat[i])

    def states(self) -> dict[str, NodeState]:
        """The state of every node."""
        return {n: self.state(n) for n in self.ids}

    @property
    def root(self) -> NodeState:
        """The root goal's state."""
        return self.state(self.model.root)

    def drain_changes(self) -> list[str]:
        """Ids of the nodes whose utility or status changed since the last call."""
        out = [self.ids[i] for i in sorted(self._changed)]
        self._changed.clear()
        return out

    def satisfied_for_tactics(self, node: str) -> bool:
        """Whether ``node`` counts as satisfied when tactics are selected.

        An unknown status counts as the model's ``unknown_policy`` says (default
        ``unsatisfied``: fail-safe).
        """
        s = self.stat[self.index[node]]
        if s is None:
            return self.model.unknown_policy == "satisfied"
        return s

    def condition(self, name: str) -> Any:
        """The current value of a named condition given at construction (``None`` = unknown)."""
        value = self._conditions[name](self.slots)
        return None if value is ABSENT else value

    def value(self, ref: AttrRef | str) -> Any:
        """The current value of an attribute (``None`` = unknown) or of ``rate(A)``."""
        if isinstance(ref, str):
            if ref.startswith("rate(") and ref.endswith(")"):
                slot = self._rate_slot.get(ref[5:-1])
                return None if slot is None else self.slots[slot]
            agent, _, attr = ref.partition(".")
            ref = AttrRef(agent, attr)
        slot = self._slot_of_ref.get(ref)
        return None if slot is None else self.slots[slot]

    def values(self) -> dict[str, Any]:
        """Every input slot by name (``A1.mode``, ``rate(A3)``)."""
        return {str(r): _jsonable(v) for r, v in zip(self._slot_ref, self.slots, strict=True)}

    def explain(self, node: str) -> Explanation:
        """Explain ``node``'s status, naming the leaf values that decided it (built on demand)."""
        return self._explain(self.index[node], depth=0)

    def _leaf_inputs(self, i: int) -> dict[str, Any]:
        gid = self.ids[i]
        out: dict[str, Any] = {}
        for (eid, _role), expr in self.model.expressions.items():
            if eid != gid:
                continue
            for ref in sorted(expr.refs):
                out[str(ref)] = _jsonable(self.value(ref))
            for agent in sorted(expr.rated):
                out[f"rate({agent})"] = self.value(f"rate({agent})")
        return out

    def _explain(self, i: int, depth: int) -> Explanation:
        nid = self.ids[i]
        k = self._kind[i]
        u, s = self.util[i], self.stat[i]
        kind: Literal["goal", "obstacle"] = "obstacle" if k == _OBSTACLE else "goal"
        ustr = "?" if u is None else f"{u:.3g}"
        if k == _OBSTACLE:
            verdict = {True: "holds", False: "does not hold", None: "unknown"}[s]
        else:
            verdict = status_name(s)
        because: list[Explanation] = []
        leaves: dict[str, Any] = {}
        if k in (_LEAF, _OBSTACLE):
            leaves = self._leaf_inputs(i)
            summary = f"{nid} {verdict} (utility {ustr}): {self._leaf_detail(i, leaves)}"
        else:
            rule = (
                "AND: all children must be satisfied"
                if k == _AND
                else ("OR: one child must be satisfied")
            )
            because = [self._explain(c, depth + 1) for c in self._deciding(i)]
            summary = f"{nid} {verdict} (utility {ustr}): {rule}"
        for o, res in self._obstr[i]:
            resolved = [self.ids[r] for r in res if self.stat[r] is True]
            if resolved:
                summary += f"; obstacle {self.ids[o]} resolved by {', '.join(resolved)}"
            elif self.stat[o] is not False:
                summary += f"; obstructed by {self.ids[o]}"
                because.append(self._explain(o, depth + 1))
        for b in because:
            for key, v in b.leaves.items():
                leaves.setdefault(key, v)
        return Explanation(nid, kind, s, u, summary, leaves, because)

    def _leaf_detail(self, i: int, leaves: Mapping[str, Any]) -> str:
        """What a leaf goal or obstacle computes, with its inputs, RELAX and threshold."""
        nid = self.ids[i]
        k = self._kind[i]
        expr = self.model.expressions.get((nid, "utility" if k == _LEAF else "condition"))
        alternatives = [
            e.text
            for (eid, role), e in sorted(self.model.expressions.items())
            if eid == nid and role.startswith("alternative")
        ]
        if expr is not None:
            text = expr.text
        elif alternatives:
            text = " MAY ... OR ".join(alternatives)
        else:
            text = "<no utility>"
        event = self.model.expressions.get((nid, "event"))
        if event is not None:
            text += f" (event: {event.text})"
        inputs = ", ".join(f"{key} = {_fmt(v)}" for key, v in leaves.items())
        detail = f"{text}" + (f" with {inputs}" if inputs else "")
        op = self._relax[i]
        if op is not None:
            spec = self.model.goals[nid].relax
            detail += f"; RELAX {getattr(spec, 'operator', type(op).__name__)}"
        if k == _LEAF:
            detail += f"; threshold {self._thresh[i]:g}"
        if self._avoid[i]:
            detail += "; avoid: utility = 1 - value"
        return detail

    def _deciding(self, i: int) -> list[int]:
        """The children of an AND/OR node that decide its status (what to explain)."""
        k, s = self._kind[i], self.stat[i]
        children = self._children[i]
        obstructed = s is False and any(
            self.stat[o] is True and not any(self.stat[r] is True for r in res)
            for o, res in self._obstr[i]
        )
        if k == _AND:
            deciding = [c for c in children if self.stat[c] is not True]
        else:
            deciding = [c for c in children if self.stat[c] is not False]
            deciding = [c for c in deciding if self.stat[c] is True] or deciding
        if obstructed and (not deciding or k == _OR):
            deciding = []  # the children are fine: the obstacle decided
        elif not deciding or (k == _OR and s is False):
            deciding = list(children)
        if s is None:
            deciding = [c for c in children if self.stat[c] is None] or deciding
        return deciding


def _fmt(v: Any) -> str:
    if v is None:
        return "unknown"
    if v is ABSENT:
        return "absent"
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, str):
        return repr(v)
    return str(v).lower() if isinstance(v, bool) else str(v)


def _holds(value: Any) -> bool | None:
    t = truth(value)
    return None if t is None else t >= 1.0 - _EPS


def _get_field(message: Mapping[str, Any], path: tuple[str, ...]) -> Any:
    cur: Any = message
    for part in path:
        if isinstance(cur, Mapping) and part in cur:
            cur = cur[part]
        else:
            return ABSENT
    if isinstance(cur, Mapping | list):
        return ABSENT  # only scalars are attributes
    return cur
