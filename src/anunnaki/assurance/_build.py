"""The argument, generated from a launch's goal model and developed with measured evidence.

Mapping (docs/assurance.md, "From the goal model to GSN"):

* each goal → a GSN goal (``G3``), its text the goal's description;
* an AND/OR refinement → a strategy ``S-G3`` ("argument over the sub-goals": all of them,
  or "any one suffices" for OR) supported by the sub-goals;
* each agent → a context ``C-A1`` of the goals it is responsible for;
* each obstacle → a hazard: a context ``C-O1`` and a strategy ``S-O1`` below each goal it
  obstructs, arguing that the hazard is detected when it occurs (``G-O1-detected``) and
  then resolved (``G-O1-resolved``, an OR strategy over its resolution goals);
* each domain property → an assumption ``A-D1`` of the root goal;
* a RELAX-ed goal's tolerance → its stated acceptance criterion, a context ``C-G11-accept``;
* each evidence item of the criteria file → solutions ``Sn-G11-1`` … of the goal (or of an
  obstacle's ``G-O1-detected``).
"""

from __future__ import annotations

import datetime as _dt
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from anunnaki.assurance._case import Case, Evidence, Node, propagate
from anunnaki.assurance._criteria import Criteria, load_criteria
from anunnaki.assurance._evidence import Sources, collect, relative, run_tests
from anunnaki.assurance._relax_text import acceptance
from anunnaki.assurance._validate import element_type, validate
from anunnaki.errors import ModelFileError
from anunnaki.goals import GoalModel, did_you_mean

if TYPE_CHECKING:
    from anunnaki.launch import Launch

__all__ = ["CRITERIA_FILE", "build_case", "case_from_model"]

#: The criteria file looked for beside the launch file when none is given.
CRITERIA_FILE = "assurance.yaml"

#: Artefact roles that are the measurement itself (a results file, a sidecar, a test file);
#: the others are what was measured.
_MEASUREMENT = ("results", "sidecar:", "oracle-sidecar:", "tests")


def build_case(
    launch: str | Path,
    *,
    criteria: str | Path | None = None,
    root: str | Path | None = None,
    tests: bool = False,
    prior: Case | None = None,
    loaded: Launch | None = None,
) -> Case:
    """Build the assurance case of a launch file.

    Args:
        launch: The launch file (``anunnaki: launch/1``); its goal model, binding, tactics
            and model registry are read as ``anunnaki run`` reads them.
        criteria: The criteria file (default: ``assurance.yaml`` beside the launch file,
            when there is one; without any, every leaf is undeveloped).
        root: The project root the criteria's paths are relative to (default: the working
            folder).
        tests: Run the tests the criteria name (one pytest process) and record the outcome;
            otherwise they are ``not run`` and support nothing.
        prior: The case built before: a figure whose measurement is unchanged while an
            artefact it rests on changed since then is stale.
        loaded: ``launch`` as the caller has loaded it already (``anunnaki run``): not read
            again.

    Raises:
        ModelFileError: A bad launch or criteria file, a missing results file, a figure
            not where the criteria say; naming the file and element.

    """
    from anunnaki.launch import load_launch  # the launch layer: its loader, nothing started
    from anunnaki.lec import load_registry

    started = time.perf_counter()
    base = Path(root or Path.cwd()).resolve()
    launch_path = Path(launch)
    if loaded is None:
        loaded = load_launch(launch_path)
    cfg = loaded.parts.config
    files: dict[str, Path] = {"launch": launch_path.resolve(), "goal_model": Path(cfg.goal_model)}
    if cfg.binding:
        files["binding"] = Path(cfg.binding)
    if cfg.tactics:
        files["tactics"] = Path(cfg.tactics)
    registry = None
    registry_of = getattr(loaded.managed, "model_registry", None)
    reg_path = registry_of() if callable(registry_of) else None
    if reg_path:
        files["registry"] = Path(reg_path).resolve()
        registry = load_registry(files["registry"])
    scenario = getattr(getattr(loaded.managed, "options", None), "scenario", None)
    if isinstance(scenario, str) and Path(scenario).is_file():
        files["scenario"] = Path(scenario).resolve()
    crit, notes = _criteria_for(launch_path, criteria, files["goal_model"], base)
    if crit is not None and crit.source is not None:
        files["criteria"] = Path(crit.source).resolve()
    src = Sources(
        root=base,
        files=files,
        registry=registry,
        criteria_source=None if crit is None else crit.source,
    )
    if tests and crit is not None:
        ids = [t for items in crit.evidence.values() for item in items for t in item.tests]
        src.test_results = run_tests(list(dict.fromkeys(ids)), base)
    case = case_from_model(loaded.parts.model, crit, src, name=loaded.name)
    case.launch = src.rel(launch_path)
    case.project_root = str(base)
    case.notes = notes
    case.artefacts = [src.artefact(role, path) for role, path in files.items()]
    if prior is not None and prior.launch == case.launch:  # another launch's case: no prior
        mark_changed_since(case, prior)
    problems = validate(case)
    if problems:  # a bug here, not the user's: the generator broke a GSN rule
        raise AssertionError("generated GSN breaks the standard: " + "; ".join(problems))
    propagate(case)
    case.built = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    case.build_seconds = round(time.perf_counter() - started, 3)
    return case


def _criteria_for(
    launch: Path, criteria: str | Path | None, goal_model: Path, base: Path
) -> tuple[Criteria | None, list[str]]:
    """The criteria to apply, and notes: the file given, or the one beside the launch.

    A criteria file that names another goal model than the launch's is refused when given,
    and left out with a note when it was only found beside the launch.
    """
    given = criteria is not None
    if criteria is None:
        beside = launch.resolve().parent / CRITERIA_FILE
        if not beside.is_file():
            return None, []
        criteria = beside
    crit = load_criteria(criteria)
    if crit.goal_model is None:
        return crit, []
    meant = (Path(criteria).resolve().parent / crit.goal_model).resolve()
    if meant == goal_model.resolve():
        return crit, []
    if given:
        raise ModelFileError(
            f"the criteria develop {meant.name}, but the launch's goal model is {goal_model.name}",
            path=crit.source,
            element="goal_model",
            hint="give the criteria file written for this goal model (--criteria)",
        )
    note = (
        f"{relative(base, Path(criteria))} develops {relative(base, meant)}, not this "
        f"launch's goal model {relative(base, goal_model)}: no evidence attached "
        "(give --criteria FILE)"
    )
    return None, [note]


def _reachable(model: GoalModel) -> list[str]:
    order: list[str] = []
    seen: set[str] = set()
    todo = [model.root]
    while todo:
        gid = todo.pop(0)
        if gid in seen or gid not in model.goals:
            continue
        seen.add(gid)
        order.append(gid)
        todo.extend(model.goals[gid].children)
        for oid in model.obstructed_by.get(gid, []):
            todo.extend(model.obstacles[oid].resolutions)
    return order


def case_from_model(
    model: GoalModel,
    crit: Criteria | None = None,
    src: Sources | None = None,
    *,
    name: str = "",
) -> Case:
    """The argument of ``model`` with the evidence ``crit`` names (statuses not yet set).

    Without ``src`` (where the evidence is read from) the case has no evidence: every leaf
    is undeveloped. :func:`propagate` sets the statuses.
    """
    if src is None:
        src = Sources(root=Path.cwd(), files={})
        crit = None
    nodes: dict[str, Node] = {}
    root = goal_id(model.root)
    _goal_nodes(model, _reachable(model), nodes)
    _hazard_nodes(model, nodes)
    _root_context(model, src, nodes)
    if crit is not None:
        _attach(model, crit, src, nodes)
    for n in nodes.values():  # keep links unique and in order
        n.supported_by = list(dict.fromkeys(n.supported_by))
        n.in_context_of = list(dict.fromkeys(n.in_context_of))
    ordered = {root: nodes[root], **nodes}
    return Case(name=name or model.name, root=root, nodes=ordered)


def _add(nodes: dict[str, Node], node: Node) -> Node:
    return nodes.setdefault(node.id, node)


def goal_id(gid: str) -> str:
    """A goal's GSN id: its own when it starts with ``G`` (and no other prefix), else ``G-ID``."""
    return gid if element_type(gid) == "goal" else f"G-{gid}"


def _goal_nodes(model: GoalModel, goals: list[str], nodes: dict[str, Node]) -> None:
    """Goals, their refinement strategies, acceptance criteria and agents."""
    kinds = {a.id: a.kind for a in model.spec.agents}
    for gid in goals:
        g = model.goals[gid]
        node = Node(goal_id(gid), "goal", g.description or gid, source=gid, leaf=not g.children)
        _add(nodes, node)
    for gid in goals:
        g = model.goals[gid]
        node = nodes[goal_id(gid)]
        if g.children:
            kids = [goal_id(c) for c in g.children if goal_id(c) in nodes]
            listed = ", ".join(kids)
            text = (
                f"Argument over the alternatives of {gid}: any one of {listed} suffices"
                if g.refinement == "or"
                else f"Argument over the sub-goals of {gid}: all of {listed} hold"
            )
            how: Literal["and", "or"] = "or" if g.refinement == "or" else "and"
            s = Node(f"S-{gid}", "strategy", text, kids, refinement=how, source=gid)
            _add(nodes, s)
            node.supported_by.append(s.id)
        acc = acceptance(g)
        if acc is not None:
            text = f"Acceptance criterion of {gid}: {acc.text}"
            c = _add(nodes, Node(f"C-{gid}-accept", "context", text, source=gid))
            node.in_context_of.append(c.id)
        for aid in g.agents:
            agent = model.agents.get(aid)
            if agent is None:
                continue
            topics = ", ".join(tb.topic for tb in agent.topics)
            text = f"Agent {aid}: {agent.description or aid}"
            text += f" ({kinds[aid]})" if kinds.get(aid) else ""
            text += f"; observed on {topics}" if topics else ""
            c = _add(nodes, Node(f"C-{aid}", "context", text, source=aid))
            node.in_context_of.append(c.id)


def _hazard_nodes(model: GoalModel, nodes: dict[str, Node]) -> None:
    """Each obstacle as a hazard: detected, then resolved by any one of its resolutions."""
    for oid, o in model.obstacles.items():
        targets = [goal_id(g) for g in o.obstructs if goal_id(g) in nodes]
        if not targets:
            continue
        cond = f" (condition {o.condition})" if o.condition else ""
        hazard = f"Hazard {oid}: {o.description or oid}{cond}"
        _add(nodes, Node(f"C-{oid}", "context", hazard, source=oid))
        text = f"Hazard {oid} is detected when it occurs{cond}"
        detected = _add(nodes, Node(f"G-{oid}-detected", "goal", text, source=oid))
        kids = [detected.id]
        res = [goal_id(r) for r in o.resolutions if goal_id(r) in nodes]
        if res:
            text = f"Argument over the resolutions of {oid}: any one of {', '.join(res)} suffices"
            sr = _add(
                nodes,
                Node(f"S-{oid}-resolutions", "strategy", text, res, refinement="or", source=oid),
            )
            text = f"When hazard {oid} occurs, one of its resolutions holds"
            resolved = _add(nodes, Node(f"G-{oid}-resolved", "goal", text, [sr.id], source=oid))
            kids.append(resolved.id)
        text = f"Argument over hazard {oid}: it is detected, then resolved"
        s = _add(
            nodes,
            Node(f"S-{oid}", "strategy", text, kids, [f"C-{oid}"], refinement="and", source=oid),
        )
        for gid in targets:
            nodes[gid].supported_by.append(s.id)


def _root_context(model: GoalModel, src: Sources, nodes: dict[str, Node]) -> None:
    """The launch as context, the evidence rule as justification, domain properties."""
    root = nodes[goal_id(model.root)]
    for did, d in model.domain_properties.items():
        cond = f" ({d.condition})" if d.condition else ""
        a = _add(nodes, Node(f"A-{did}", "assumption", f"{d.description or did}{cond}", source=did))
        root.in_context_of.append(a.id)
    files = ", ".join(f"{role} {src.rel(p)}" for role, p in src.files.items() if role != "launch")
    launch = src.files.get("launch")
    text = f"The system as launched by {src.rel(launch) if launch else '?'}: {files}"
    c = _add(nodes, Node("C-launch", "context", text))
    j = _add(nodes, Node("J-evidence", "justification", _RULE))
    root.in_context_of[:0] = [c.id, j.id]


_RULE = (
    "Evidence is the project's own measurements, filed under the AMLAS stages (data "
    "management, model learning, model verification, model deployment); a claim is "
    "supported only by evidence that meets its criterion and whose artefacts are "
    "unchanged since it was measured"
)


def _attach(model: GoalModel, crit: Criteria, src: Sources, nodes: dict[str, Node]) -> None:
    for key, items in crit.evidence.items():
        if key in model.goals and goal_id(key) in nodes:
            target = nodes[goal_id(key)]
            relax = acceptance(model.goals[key])
        elif key in model.obstacles and f"G-{key}-detected" in nodes:
            target = nodes[f"G-{key}-detected"]
            relax = None
        else:
            known: dict[str, Any] = {**{g: 1 for g in model.goals}, **dict(model.obstacles)}
            why = "not in the argument (unreachable from the root)" if key in known else "unknown"
            raise ModelFileError(
                f"evidence for {key!r}: {why}",
                path=crit.source,
                element=f"evidence.{key}",
                hint=did_you_mean(key, known)
                if key not in known
                else "develop a goal of the argument",
            )
        n = 0
        for i, item in enumerate(items):
            for ev in collect(item, relax, src, f"evidence.{key}[{i}]"):
                n += 1
                sid = f"Sn-{key}-{n}"
                nodes[sid] = Node(sid, "solution", _solution_text(ev), source=key, evidence=ev)
                target.supported_by.append(sid)


def _solution_text(ev: Evidence) -> str:
    text = f"{ev.stage.capitalize()}: {ev.figure}. Criterion {ev.criterion}: {ev.result}"
    return text + (f" (STALE: {ev.stale})" if ev.stale else "")


def mark_changed_since(case: Case, prior: Case) -> None:
    """Mark stale each figure whose measurement is as in ``prior`` while what it measured changed.

    The figure then still rests on the artefacts of ``prior``: their sha256 there becomes the
    one it was measured on, so it stays stale until it is measured again (or the artefact
    is put back).
    """
    before = {n.id: n.evidence for n in prior if n.evidence is not None}
    for node in case.solutions():
        ev = node.evidence
        old = before.get(node.id)
        if ev is None or old is None or old.figure != ev.figure:
            continue
        was = {a.role: a for a in old.artefacts}
        measured_same = all(
            a.role in was and was[a.role].sha256 == a.sha256
            for a in ev.artefacts
            if a.role.startswith(_MEASUREMENT)
        )
        if not measured_same:
            continue
        for a in ev.artefacts:
            prev = was.get(a.role)
            if prev is None or a.role.startswith(_MEASUREMENT):
                continue
            basis = prev.measured_sha256 or prev.sha256
            if a.measured_sha256 is None and basis != a.sha256:
                a.measured_sha256 = basis
        changed = [a for a in ev.artefacts if a.measured_sha256 and a.measured_sha256 != a.sha256]
        if changed and ev.stale is None:
            ev.stale = "; ".join(
                f"{a.path} changed since the figure was measured "
                f"({a.measured_sha256[:12]}… → {a.sha256[:12]}…)"  # type: ignore[index]
                for a in changed
            )
        node.text = _solution_text(ev)
