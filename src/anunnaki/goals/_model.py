"""Goal models resolved against a platform binding: the graph the evaluator runs on.

Loading happens in two stages. The schema (:mod:`._schema`) checks each file's shape and
raises at the first malformed element. :class:`GoalModel` then resolves references — the
children of each goal, the goals an obstacle obstructs, the agents and attributes every
expression reads, the topics that carry them — and records every problem as a located
:class:`~anunnaki._findings.Finding`. A strict load (the default) raises on the first
error-level finding; ``anunnaki check`` loads leniently and prints all of them.

Topic names are ROS-style (``/utu/oracle/output``) in every file. On the bus the same name
becomes the key ``<namespace>/utu/oracle/output`` (a zenoh key may not start with ``/``);
see :mod:`anunnaki.bus` and docs/goal-models.md.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ValidationError

from anunnaki._findings import Finding, Severity
from anunnaki._safeyaml import LineMap, load_yaml, validation_error
from anunnaki.errors import ExpressionError, ModelFileError
from anunnaki.goals._expr import AttrRef, Expression, compile_expression
from anunnaki.goals._relax import RelaxOperator, build_operator
from anunnaki.goals._schema import (
    AgentSpec,
    BindingSpec,
    DomainPropertySpec,
    EndpointSpec,
    ForecastSpec,
    GoalModelSpec,
    GoalSpec,
    ObstacleSpec,
    TopicBinding,
)

__all__ = [
    "Agent",
    "Binding",
    "GoalModel",
    "load_binding",
    "load_goal_model",
    "parse_binding",
    "parse_goal_model",
]

NodeKind = Literal["goal", "obstacle"]

RESERVED_WORDS = (
    "and",
    "or",
    "not",
    "in",
    "has",
    "no",
    "true",
    "false",
    "rate",
    "min",
    "max",
    "abs",
)
"""Words of the expression language; an agent id that is one of them cannot be named."""


@dataclass(frozen=True)
class Binding:
    """A loaded platform-binding file."""

    spec: BindingSpec
    path: str | None
    lines: LineMap

    @property
    def platform(self) -> str:
        """The platform's name."""
        return self.spec.platform


@dataclass
class Agent:
    """An agent with the topics it publishes on this platform."""

    id: str
    description: str
    topics: list[TopicBinding]
    staleness: float
    node: str | None = None
    # attribute name -> (topic, dotted field path)
    attributes: dict[str, tuple[str, str]] = field(default_factory=dict)
    # forecast name -> its spec (the binding's ``forecasts:``): attributes computed, not heard
    forecasts: dict[str, ForecastSpec] = field(default_factory=dict)

    def knows(self, attribute: str) -> bool:
        """Whether ``attribute`` can be read: a field it publishes or one of its forecasts."""
        return attribute in self.attributes or attribute in self.forecasts

    def attribute_names(self) -> list[str]:
        """Every attribute an expression may read of this agent, sorted."""
        return sorted({*self.attributes, *self.forecasts})

    @property
    def primary_topic(self) -> str | None:
        """The topic whose message rate ``rate(A)`` measures: the first one listed."""
        return self.topics[0].topic if self.topics else None


def _parse(
    cls: type[BaseModel], data: Any, lines: LineMap | None, path: str | None, tag: str
) -> Any:
    if not isinstance(data, dict):
        raise ModelFileError(
            "the file must be a YAML mapping",
            path=path,
            line=1,
            hint=f"start it with 'anunnaki: {tag}'",
        )
    if data.get("anunnaki") != tag:
        found = data.get("anunnaki")
        raise ModelFileError(
            f"missing or wrong format tag: anunnaki: {found!r}"
            if found is not None
            else "missing format tag",
            path=path,
            line=lines.line(("anunnaki",)) if lines else None,
            element="anunnaki",
            hint=f"the first line of this kind of file is 'anunnaki: {tag}'",
        )
    try:
        return cls.model_validate(data)
    except ValidationError as exc:
        raise validation_error(exc, data, lines, path) from None


def parse_binding(text: str, *, source: str = "<binding>") -> Binding:
    """Parse a binding from YAML text."""
    data, lines = load_yaml(source, text=text)
    return Binding(_parse(BindingSpec, data, lines, source, "binding/1"), source, lines)


def load_binding(path: str | Path) -> Binding:
    """Load a platform-binding file (``anunnaki: binding/1``)."""
    data, lines = load_yaml(path)
    return Binding(_parse(BindingSpec, data, lines, str(path), "binding/1"), str(path), lines)


class GoalModel:
    """A goal model resolved against a binding; immutable once built.

    Attributes:
        spec: The validated file content.
        path: The goal-model file (``None`` when built from memory).
        binding: The binding applied, if any (its agents' topics replace the inline ones).
        agents: Agents by id, with their topics and attribute → (topic, field) map.
        goals / obstacles / domain_properties: Elements by id.
        endpoints: Actuation endpoints by ROS name (inline ones, then the binding's).
        logical: Logical endpoint name (``set_mode``) → ROS name; the binding's mapping of a
            logical name replaces the goal model's (and drops that inline endpoint).
        root: The root goal's id.
        parents: Goal id → ids of goals it refines.
        obstructed_by: Goal id → ids of obstacles obstructing it.
        expressions: ``(element id, role)`` → compiled expression; roles are ``utility``,
            ``condition``, ``event`` and ``alternative<i>``.
        relax: Leaf goal id → built RELAX operator.
        findings: Every problem found while resolving (errors and warnings).

    """

    def __init__(
        self,
        spec: GoalModelSpec,
        *,
        path: str | None = None,
        lines: LineMap | None = None,
        binding: Binding | None = None,
    ) -> None:
        self.spec = spec
        self.path = path
        self.lines = lines or LineMap()
        self.binding = binding
        self.name = spec.name
        self.unknown_policy = spec.unknown_policy
        self.findings: list[Finding] = []
        self.goals: dict[str, GoalSpec] = {}
        self.obstacles: dict[str, ObstacleSpec] = {}
        self.domain_properties: dict[str, DomainPropertySpec] = {}
        self.agents: dict[str, Agent] = {}
        self.endpoints: dict[str, EndpointSpec] = {}
        self.logical: dict[str, str] = {}
        self.parents: dict[str, list[str]] = {}
        self.obstructed_by: dict[str, list[str]] = {}
        self.expressions: dict[tuple[str, str], Expression] = {}
        self.relax: dict[str, RelaxOperator] = {}
        self._index: dict[tuple[str, str], int] = {}
        self._silent: dict[str, list[str]] = {}
        self.root = ""
        self._resolve()

    # -- locating -----------------------------------------------------------------------
    def line_of(self, section: str, ident: str, *key: str | int) -> int | None:
        """Line of element ``ident`` in ``section`` (``goals``, ``agents``, …) or of a key in it."""
        i = self._index.get((section, ident))
        if i is None:
            return None
        return self.lines.line((section, i, *key))

    def _add(
        self,
        severity: Severity,
        message: str,
        *,
        section: str | None = None,
        ident: str | None = None,
        key: tuple[str | int, ...] = (),
        element: str | None = None,
        hint: str | None = None,
        path: str | None = None,
        line: int | None = None,
    ) -> None:
        if section and ident and line is None:
            line = self.line_of(section, ident, *key)
        if element is None and section and ident:
            element = f"{section}[{ident}]" + "".join(f".{k}" for k in key)
        self.findings.append(Finding(severity, message, path or self.path, line, element, hint))

    def _known(
        self, name: str, known: Mapping[str, Any], message: str, *, at: tuple[str, str, str]
    ) -> bool:
        """Whether ``name`` is in ``known``; else an error at ``section[ident].key`` (``at``).

        The error's hint names the nearest known names.
        """
        if name in known:
            return True
        section, ident, key = at
        hint = _did_you_mean(name, known)
        self._add("error", message, section=section, ident=ident, key=(key,), hint=hint)
        return False

    # -- resolution ---------------------------------------------------------------------
    def _resolve(self) -> None:
        self._collect()
        self._bind_agents()
        self._check_forecasts()
        self._map_logical()
        self._check_agent_ids()
        self._link()
        self._find_root()
        self._find_detached()
        self._compile()

    def _logical_names(
        self, endpoints: list[EndpointSpec], lines: LineMap, path: str | None
    ) -> dict[str, str]:
        """Logical name → ROS name of one file's endpoints (a name mapped twice: an error)."""
        out: dict[str, str] = {}
        for i, ep in enumerate(endpoints):
            if ep.logical is None:
                continue
            if ep.logical in out and out[ep.logical] != ep.name:
                self._add(
                    "error",
                    f"logical endpoint '{ep.logical}' is mapped twice ({out[ep.logical]} "
                    f"and {ep.name})",
                    path=path,
                    line=lines.line(("endpoints", i, "logical")) or lines.line(("endpoints", i)),
                    element=f"endpoints[{ep.name}].logical",
                    hint="map each logical name to one topic or service",
                )
                continue
            out[ep.logical] = ep.name
        return out

    def _map_logical(self) -> None:
        """Build :attr:`logical`: the goal model's names, then the binding's over them."""
        inline = self._logical_names(self.spec.endpoints, self.lines, self.path)
        self.logical = dict(inline)
        if self.binding is None:
            return
        bound = self._logical_names(
            self.binding.spec.endpoints, self.binding.lines, self.binding.path
        )
        in_binding = {ep.name for ep in self.binding.spec.endpoints}
        for logical, name in bound.items():
            old = inline.get(logical)
            if old is not None and old != name and old not in in_binding:
                # The platform puts this logical endpoint elsewhere: the default is gone.
                self.endpoints.pop(old, None)
            self.logical[logical] = name

    def endpoint(self, name: str) -> EndpointSpec | None:
        """The endpoint a tactic means by ``name``: a logical name or a ROS name."""
        return self.endpoints.get(self.logical.get(name, name))

    def endpoint_name(self, name: str) -> str:
        """The ROS name a tactic's ``name`` stands for (a ROS name stands for itself)."""
        return self.logical.get(name, name)

    def _check_agent_ids(self) -> None:
        # Ids may contain '-' and may be words the expression language reserves; an agent
        # with such an id cannot be named in an expression ('A-1.x' reads as 'A - 1.x').
        for aid in self.agents:
            try:
                compile_expression(f"{aid}.x == 1 and {aid} has x and rate({aid}) > 0")
            except ExpressionError:
                self._add(
                    "warning",
                    f"agent id '{aid}' cannot be named in expressions",
                    section="agents",
                    ident=aid,
                    hint="use letters, digits and '_' only, and none of the words "
                    + ", ".join(RESERVED_WORDS),
                )

    def _collect(self) -> None:
        seen: dict[str, str] = {}
        sections: list[tuple[str, list[Any]]] = [
            ("agents", self.spec.agents),
            ("goals", self.spec.goals),
            ("obstacles", self.spec.obstacles),
            ("domain_properties", self.spec.domain_properties),
        ]
        for section, items in sections:
            for i, item in enumerate(items):
                if item.id in seen:
                    first = seen[item.id]
                    self._add(
                        "error",
                        f"duplicate id '{item.id}' (first defined in {first})",
                        line=self.lines.line((section, i)),
                        element=f"{section}[{item.id}]",
                        hint="ids must be unique across agents, goals, obstacles and "
                        "domain properties",
                    )
                    continue
                line = self.lines.line((section, i))
                seen[item.id] = f"{section} at line {line}" if line else section
                self._index[(section, item.id)] = i
                if section == "goals":
                    self.goals[item.id] = item
                elif section == "obstacles":
                    self.obstacles[item.id] = item
                elif section == "domain_properties":
                    self.domain_properties[item.id] = item
        for i, ep in enumerate(self.spec.endpoints):
            if ep.name in self.endpoints:
                self._add(
                    "error",
                    f"endpoint {ep.name} is declared twice",
                    line=self.lines.line(("endpoints", i)),
                    element=f"endpoints[{ep.name}]",
                    hint="declare each topic or service once",
                )
                continue
            self._index[("endpoints", ep.name)] = i
            self.endpoints[ep.name] = ep

    def _bind_agents(self) -> None:
        inline: dict[str, AgentSpec] = {}
        for a in self.spec.agents:
            inline.setdefault(a.id, a)
        bound = self.binding.spec.agents if self.binding else {}
        for aid, a in inline.items():
            topics = list(a.topics)
            staleness = a.staleness
            node = a.node
            forecasts = {}
            if aid in bound:
                topics = list(bound[aid].topics)
                staleness = bound[aid].staleness or staleness
                node = bound[aid].node or node
                forecasts = dict(bound[aid].forecasts)
            agent = Agent(aid, a.description, topics, staleness or self.spec.staleness, node)
            agent.forecasts = forecasts
            for tb in topics:
                for attr, fpath in tb.attributes.items():
                    agent.attributes.setdefault(attr, (tb.topic, fpath))
            self.agents[aid] = agent
        if self.binding:
            for aid in bound:
                if aid not in inline:
                    self._add(
                        "error",
                        f"binding names agent '{aid}', which the goal model does not declare",
                        path=self.binding.path,
                        line=self.binding.lines.line(("agents", aid)),
                        element=f"agents.{aid}",
                        hint=f"declared agents: {', '.join(sorted(inline)) or 'none'}",
                    )
            in_binding: set[str] = set()
            for i, ep in enumerate(self.binding.spec.endpoints):
                if ep.name in in_binding:
                    self._add(
                        "error",
                        f"endpoint {ep.name} is declared twice",
                        path=self.binding.path,
                        line=self.binding.lines.line(("endpoints", i)),
                        element=f"endpoints[{ep.name}]",
                        hint="declare each topic or service once",
                    )
                    continue
                in_binding.add(ep.name)
                if ep.name in self.endpoints and ep != self.endpoints[ep.name]:
                    self._add(
                        "warning",
                        f"endpoint {ep.name} overrides the goal model's",
                        path=self.binding.path,
                        line=self.binding.lines.line(("endpoints", i)),
                        element=f"endpoints[{ep.name}]",
                    )
                self.endpoints[ep.name] = ep

    def _check_forecasts(self) -> None:
        """Each forecast reads a field its agent publishes, and attributes that exist."""
        if self.binding is None:
            return
        path, lines = self.binding.path, self.binding.lines

        def bad(aid: str, name: str, key: str, message: str, hint: str) -> None:
            where = ("agents", aid, "forecasts", name)
            self._add(
                "error",
                message,
                path=path,
                line=lines.line((*where, key)) or lines.line(where),
                element=f"agents.{aid}.forecasts.{name}.{key}",
                hint=hint,
            )

        for aid, agent in self.agents.items():
            for name, fc in agent.forecasts.items():
                if name in agent.attributes:
                    bad(
                        aid,
                        name,
                        "of",
                        f"forecast '{name}' of {aid} has the name of an attribute {aid} publishes",
                        f"rename the forecast, e.g. {name}_forecast",
                    )
                if fc.of not in agent.attributes:
                    known = ", ".join(sorted(agent.attributes)) or "none"
                    bad(
                        aid,
                        name,
                        "of",
                        f"forecast '{name}' extrapolates '{fc.of}', which {aid} does not publish",
                        f"'of' names one of {aid}'s attributes: {known}",
                    )
                for key in ("distance", "speed"):
                    ref = getattr(fc, key)
                    if not isinstance(ref, str):
                        continue
                    other, _, attr = ref.partition(".")
                    target = self.agents.get(other)
                    if target is None:
                        bad(
                            aid,
                            name,
                            key,
                            f"forecast '{name}' reads {key} from unknown agent '{other}'",
                            _did_you_mean(other, self.agents),
                        )
                    elif attr not in target.attributes:
                        known = ", ".join(sorted(target.attributes)) or "none"
                        bad(
                            aid,
                            name,
                            key,
                            f"forecast '{name}' reads {key} from '{ref}', which {other} "
                            "does not publish",
                            f"{other} publishes: {known} (a forecast reads published "
                            "attributes, or takes a number)",
                        )

    def _link(self) -> None:
        for g in self.goals.values():
            self._link_goal(g)
        for o in self.obstacles.values():
            self._link_obstacle(o)
        self._find_cycles()

    def _link_goal(self, g: GoalSpec) -> None:
        """Record ``g`` as its children's parent; report unknown children and agents."""
        if g.children and g.threshold is not None:
            self._add(
                "warning",
                "'threshold' is ignored on a refined goal: it is satisfied by the "
                f"{g.refinement.upper() if g.refinement else 'AND'} of its children",
                section="goals",
                ident=g.id,
                key=("threshold",),
                hint="remove it, or give the threshold to the leaf goals",
            )
        for c in sorted({c for c in g.children if g.children.count(c) > 1}):
            self._add(
                "warning",
                f"child goal '{c}' is listed twice",
                section="goals",
                ident=g.id,
                key=("children",),
                hint="list each child once",
            )
        for c in g.children:
            if self._known(
                c, self.goals, f"unknown child goal '{c}'", at=("goals", g.id, "children")
            ):
                self.parents.setdefault(c, []).append(g.id)
        for a in g.agents:
            self._known(a, self.agents, f"unknown agent '{a}'", at=("goals", g.id, "agents"))

    def _link_obstacle(self, o: ObstacleSpec) -> None:
        """Record what ``o`` obstructs; report unknown obstructed and resolution goals."""
        for gid in o.obstructs:
            what = f"obstructs unknown goal '{gid}'"
            if self._known(gid, self.goals, what, at=("obstacles", o.id, "obstructs")):
                self.obstructed_by.setdefault(gid, []).append(o.id)
        for gid in o.resolutions:
            what = f"unknown resolution goal '{gid}'"
            self._known(gid, self.goals, what, at=("obstacles", o.id, "resolutions"))

    def _find_cycles(self) -> None:
        # Iterative DFS over refinement edges (goal -> children); a model is a DAG.
        state: dict[str, int] = {}  # 1 = on stack, 2 = done
        for start in self.goals:
            if state.get(start):
                continue
            stack: list[tuple[str, Iterator[str]]] = [(start, iter(self.goals[start].children))]
            state[start] = 1
            while stack:
                node, it = stack[-1]
                nxt = next(it, None)
                if nxt is None:
                    state[node] = 2
                    stack.pop()
                    continue
                if nxt not in self.goals:
                    continue
                if state.get(nxt) == 1:
                    cycle = [n for n, _ in stack]
                    cycle = [*cycle[cycle.index(nxt) :], nxt]
                    self._add(
                        "error",
                        "refinement cycle " + " -> ".join(cycle),
                        section="goals",
                        ident=node,
                        key=("children",),
                        hint="a goal may not (indirectly) refine itself",
                    )
                    self.goals[node] = self.goals[node].model_copy(
                        update={"children": [c for c in self.goals[node].children if c != nxt]}
                    )
                    self.parents[nxt] = [p for p in self.parents.get(nxt, []) if p != node]
                elif not state.get(nxt):
                    state[nxt] = 1
                    stack.append((nxt, iter(self.goals[nxt].children)))

    def _find_root(self) -> None:
        if self.spec.root is not None:
            if self.spec.root not in self.goals:
                self._add(
                    "error",
                    f"root goal '{self.spec.root}' is not defined",
                    line=self.lines.line(("root",)),
                    element="root",
                    hint=_did_you_mean(self.spec.root, self.goals),
                )
            else:
                self.root = self.spec.root
                return
        resolution = {g for o in self.obstacles.values() for g in o.resolutions}
        tops = [g for g in self.goals if not self.parents.get(g) and g not in resolution]
        if len(tops) == 1:
            self.root = tops[0]
        elif not tops:
            self.root = next(iter(self.goals), "")
        else:
            self.root = tops[0]
            self._add(
                "error",
                f"several goals refine nothing ({', '.join(tops)}); which is the root?",
                line=self.lines.line(("goals",)),
                element="goals",
                hint=f"add 'root: {tops[0]}' at the top, or make the others children",
            )

    def _find_detached(self) -> None:
        # Goals outside the tree under the root (and outside every resolution goal's own
        # sub-tree) are evaluated, but no parent reads them and `evaluate` does not show them.
        if not self.root or any(f.element == "goals" for f in self.findings):
            return  # no root, or "several goals refine nothing" already names them
        resolution = [g for o in self.obstacles.values() for g in o.resolutions]
        reached: set[str] = set()
        stack = [self.root, *(g for g in resolution if g in self.goals)]
        while stack:
            gid = stack.pop()
            if gid in reached:
                continue
            reached.add(gid)
            stack.extend(c for c in self.goals[gid].children if c in self.goals)
        for gid in self.goals:
            if gid not in reached and not self.parents.get(gid):
                self._add(
                    "warning",
                    f"goal '{gid}' is not under the root goal {self.root}, nor a resolution "
                    "of an obstacle: nothing reads its status",
                    section="goals",
                    ident=gid,
                    hint=f"add it to the children of a goal under {self.root}, or remove it",
                )

    def _compile_one(
        self, section: str, ident: str, key: str, text: str | None, role: str
    ) -> Expression | None:
        if text is None:
            return None
        try:
            expr = compile_expression(
                text,
                path=self.path,
                line=self.line_of(section, ident, key),
                element=f"{section}[{ident}].{key}",
            )
        except ExpressionError as exc:
            self.findings.append(Finding.from_error(exc))
            return None
        self.expressions[(ident, role)] = expr
        self._check_refs(section, ident, key, expr)
        return expr

    def _check_refs(self, section: str, ident: str, key: str, expr: Expression) -> None:
        for agent_id in sorted(expr.agents):
            what = f"unknown agent '{agent_id}' in '{expr.text}'"
            if not self._known(agent_id, self.agents, what, at=(section, ident, key)):
                continue
            if not self.agents[agent_id].topics:
                self._silent.setdefault(agent_id, []).append(ident)
        for ref in sorted(expr.refs):
            agent = self.agents.get(ref.agent)
            if agent is None or not agent.topics:
                continue
            if not agent.knows(ref.attribute):
                known = ", ".join(agent.attribute_names()) or "none"
                self._add(
                    "error",
                    f"unknown attribute '{ref}' in '{expr.text}'",
                    section=section,
                    ident=ident,
                    key=(key,),
                    hint=f"{ref.agent} publishes: {known}",
                )

    def _compile(self) -> None:
        for g in self.goals.values():
            if not g.children:
                self._compile_leaf(g)
        for o in self.obstacles.values():
            self._compile_obstacle(o)
        for d in self.domain_properties.values():
            self._compile_one("domain_properties", d.id, "condition", d.condition, "condition")
        for agent_id, readers in self._silent.items():
            names = ", ".join(dict.fromkeys(readers))
            self._add(
                "error",
                f"agent '{agent_id}' publishes no topic, so what {names} read"
                " can never be observed",
                section="agents",
                ident=agent_id,
                hint=f"bind {agent_id} to a topic: pass the platform binding file, or give "
                "the agent 'topics:' in the goal model",
            )

    def _compile_leaf(self, g: GoalSpec) -> None:
        """Compile a leaf goal's utility (and RELAX); it needs one and a responsible agent."""
        expr = self._compile_one("goals", g.id, "utility", g.utility, "utility")
        if g.utility is None and getattr(g.relax, "operator", None) != "may_or":
            self._add(
                "error",
                "leaf goal without a utility function",
                section="goals",
                ident=g.id,
                hint="give it 'utility: <expression>' or refine it into children",
            )
        if g.relax is not None:
            self._compile_relax(g)
        if expr is not None and expr.value_type == "string":
            self._add(
                "error",
                f"utility '{expr.text}' is a string; a utility is a boolean or a number",
                section="goals",
                ident=g.id,
                key=("utility",),
            )
        responsible = set(g.agents) | (expr.agents if expr else set())
        for (eid, _role), e in self.expressions.items():
            if eid == g.id:
                responsible |= e.agents
        if not responsible:
            self._add(
                "warning",
                "leaf goal without a responsible agent",
                section="goals",
                ident=g.id,
                hint="list the agents responsible for it under 'agents:'",
            )

    def _compile_obstacle(self, o: ObstacleSpec) -> None:
        """Compile an obstacle's condition, which it needs and which is no string."""
        cond = self._compile_one("obstacles", o.id, "condition", o.condition, "condition")
        if cond is not None and cond.value_type == "string":
            self._add(
                "error",
                f"condition '{cond.text}' is a string; a condition is a boolean or a number",
                section="obstacles",
                ident=o.id,
                key=("condition",),
                hint="compare it, e.g. A1.mode == 'manual'",
            )
        if o.condition is None:
            self._add(
                "error",
                "obstacle without a condition",
                section="obstacles",
                ident=o.id,
                hint="give it 'condition: <expression>', e.g. A4.category >= 1",
            )

    def _compile_relax(self, g: GoalSpec) -> None:
        assert g.relax is not None
        event = getattr(g.relax, "event", None)
        if isinstance(event, str):
            self._compile_one("goals", g.id, "relax", event, "event")
        alternatives = getattr(g.relax, "alternatives", None)
        if isinstance(alternatives, list | tuple):
            for i, alt in enumerate(alternatives):
                self._compile_one("goals", g.id, "relax", str(alt), f"alternative{i}")
        self.relax[g.id] = build_operator(g.relax)

    # -- queries ------------------------------------------------------------------------
    def errors(self) -> list[Finding]:
        """The error-level findings."""
        return [f for f in self.findings if f.severity == "error"]

    def is_leaf(self, goal_id: str) -> bool:
        """Whether a goal has no children."""
        return not self.goals[goal_id].children

    def topic_routes(self) -> dict[str, list[tuple[str, dict[str, str]]]]:
        """Topic → list of (agent, {attribute: field path}) it feeds."""
        routes: dict[str, list[tuple[str, dict[str, str]]]] = {}
        for agent in self.agents.values():
            for tb in agent.topics:
                routes.setdefault(tb.topic, []).append((agent.id, dict(tb.attributes)))
        return routes

    def attribute_refs(self) -> set[AttrRef]:
        """Every attribute any expression reads."""
        return {r for e in self.expressions.values() for r in e.refs}

    def nodes(self) -> Mapping[str, GoalSpec | ObstacleSpec]:
        """Goals and obstacles by id."""
        return {**self.goals, **self.obstacles}


def _did_you_mean(name: str, known: Mapping[str, Any]) -> str:
    import difflib

    close = difflib.get_close_matches(name, list(known), n=1)
    if close:
        return f"did you mean '{close[0]}'?"
    return f"known: {', '.join(sorted(known)) or 'none'}"


def _from_data(
    data: Any,
    lines: LineMap,
    path: str,
    binding: Binding | None,
    strict: bool,
) -> GoalModel:
    spec = _parse(GoalModelSpec, data, lines, path, "goal-model/1")
    model = GoalModel(spec, path=path, lines=lines, binding=binding)
    if strict:
        errors = model.errors()
        if errors:
            raise errors[0].to_error()
    return model


def parse_goal_model(
    text: str,
    *,
    source: str = "<goal-model>",
    binding: Binding | None = None,
    strict: bool = True,
) -> GoalModel:
    """Parse a goal model from YAML text (see :func:`load_goal_model`)."""
    data, lines = load_yaml(source, text=text)
    return _from_data(data, lines, source, binding, strict)


def load_goal_model(
    path: str | Path,
    binding: str | Path | Binding | None = None,
    *,
    strict: bool = True,
) -> GoalModel:
    """Load a goal model, optionally with a platform binding.

    Args:
        path: The goal-model YAML file (``anunnaki: goal-model/1``).
        binding: A binding file or a loaded :class:`Binding`; its agents' topics replace the
            inline ones and its endpoints are added.
        strict: Raise on the first error-level finding. With ``False`` the model is returned
            with ``findings`` filled in (what ``anunnaki check`` does).

    Raises:
        ModelFileError: the file is unreadable, hostile, malformed, or (strict) inconsistent.

    """
    if binding is not None and not isinstance(binding, Binding):
        binding = load_binding(binding)
    data, lines = load_yaml(path)
    return _from_data(data, lines, str(path), binding, strict)
