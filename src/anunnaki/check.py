"""Static checks of a goal model, its platform binding and its tactics (``anunnaki check``).

Every finding names the file, the line and the element, and most carry a hint. Checks:

* each file loads (shape, types, bounds; hostile content refused);
* duplicate ids, unknown children / obstructed goals / resolution goals, refinement cycles,
  an ambiguous root, dependency cycles through resolution goals;
* expressions parse and name known agents and attributes (the binding says which topics
  carry which attributes), agents referenced by expressions publish some topic;
* leaf goals without a utility (error) or a responsible agent (warning);
* tactics name known goals, known endpoints of the right kind (topic vs service) with
  payloads that fit the endpoint's schema, and valid expressions;
* (warning) goals whose violation no tactic addresses: a goal is addressed when a tactic's
  precondition names it or an ancestor as unsatisfied/unknown, when it is AND-refined and
  all its children are addressed, or OR-refined and one child is. Goals that only serve as
  resolutions of obstacles are exempt;
* given the modes the platform declares (``anunnaki check --platform uav``, or a launch file,
  whose managed platform says them), every mode a ``change_mode`` action requests is one of
  them;
* (warning) given the models a model manager serves (a launch file's model registry),
  every ``swap_model`` action asks for a model id or domain it has, of the LEC it serves;
* given the fail-safe tactic a Utu configuration names, it is in the tactics file.

Exit codes of the command (one meaning each, docs/goal-models.md#checks): 0 nothing found;
1 findings (errors or warnings) in what was checked — a file that is not valid YAML or does
not fit its format is a finding too; 2 the command cannot check: a usage error, or a file
named on the command line cannot be read at all (missing, a folder, not UTF-8 text, too
large) or is not a kind ``check`` knows.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from anunnaki import topics
from anunnaki._findings import Finding
from anunnaki._safeyaml import read_text_limited
from anunnaki.errors import ExpressionError, ModelFileError
from anunnaki.goals import (
    Binding,
    EndpointSpec,
    Evaluator,
    GoalModel,
    compile_expression,
    load_binding,
    load_goal_model,
)
from anunnaki.tactics import (
    ChangeModeAction,
    EndpointReference,
    GoalState,
    SwapModelAction,
    TacticSet,
    load_tactics,
)

__all__ = [
    "CheckResult",
    "ModelCatalogue",
    "PlatformModes",
    "check_failsafe",
    "check_files",
    "check_modes",
    "check_swaps",
    "check_tactics",
]


@dataclass(frozen=True)
class PlatformModes:
    """The modes a platform declares (what its ``set_mode`` accepts).

    Attributes:
        platform: The platform's name, for messages (``uav``, ``rover``, a launch's system).
        modes: The modes it accepts.
        declared: Where they are declared, for the hint (e.g. ``anunnaki.sim.UavSim.modes``).

    """

    platform: str
    modes: tuple[str, ...]
    declared: str = ""


@dataclass(frozen=True)
class ModelCatalogue:
    """The models a model manager serves: what a ``swap_model`` action may ask it for.

    Attributes:
        lec: The LEC it serves (a registry's ``lec``, e.g. ``detector``).
        ids: Its model ids.
        domains: The domains it has a model for.
        source: Where they are listed (the registry file), for the hint.
        service: The swap service it answers.

    """

    lec: str
    ids: tuple[str, ...]
    domains: tuple[str, ...]
    source: str = ""
    service: str = topics.SWAP


@dataclass
class CheckResult:
    """What :func:`check_files` (or ``anunnaki.launch.check_launch``) found.

    Attributes:
        findings: Every problem found, in the order found.
        unreadable: The check could not be done: a file named on the command line cannot be
            read at all, or is not a kind the check knows (exit code 2).
        model: The goal model, when it loaded.
        tactics: The tactics, when they loaded.
        checked: What else was checked, for the summary line (``scenario …``).

    """

    findings: list[Finding] = field(default_factory=list)
    unreadable: bool = False
    model: GoalModel | None = None
    tactics: TacticSet | None = None
    checked: list[str] = field(default_factory=list)

    @property
    def exit_code(self) -> int:
        """0 nothing found, 1 findings, 2 a file named could not be read (or a usage error)."""
        if self.unreadable:
            return 2
        return 1 if self.findings else 0

    @property
    def errors(self) -> list[Finding]:
        """Error-level findings."""
        return [f for f in self.findings if f.severity == "error"]

    @property
    def warnings(self) -> list[Finding]:
        """Warning-level findings."""
        return [f for f in self.findings if f.severity == "warning"]


_TAG = re.compile(r"""^anunnaki:[ \t]*['"]?([A-Za-z-]+/[0-9]+)""", re.MULTILINE)
_KINDS = {"binding/1": "binding", "tactics/1": "tactics", "goal-model/1": "goal model"}


def _sniff_kind(path: str | Path) -> str:
    """Tell a binding from a tactics file by extension and format tag.

    Returns ``binding``, ``tactics``, ``goal model`` or ``unknown``.

    Raises:
        ModelFileError: the file cannot be read.

    """
    p = Path(path)
    if p.suffix.lower() == ".xml":
        return "tactics"
    try:
        with p.open("rb") as fh:
            head = fh.read(4096).decode("utf-8", errors="replace")
    except OSError as exc:
        raise ModelFileError(
            f"cannot read file: {exc.strerror}", path=p, hint="check the path"
        ) from exc
    found = _TAG.search(head)
    if found is not None:
        return _KINDS.get(found.group(1), "unknown")
    if head.lstrip("\ufeff \t\r\n").startswith("<"):
        return "tactics"
    return "unknown"


def check_files(
    model_path: str | Path,
    *extra: str | Path,
    binding: str | Path | None = None,
    tactics: str | Path | None = None,
    modes: PlatformModes | None = None,
    failsafe: str | None = None,
) -> CheckResult:
    """Check a goal model with an optional binding and tactics file.

    ``extra`` files are recognised by their format tag (``binding/1``, ``tactics/1``) or
    extension (``.xml`` = tactics), so ``check MODEL TACTICS`` works without a binding.
    With ``modes``, the tactics' ``change_mode`` actions are checked against the platform's
    declared modes (:func:`check_modes`); with ``failsafe``, that the tactic is there
    (:func:`check_failsafe`).

    A file that cannot be read at all, or an extra file of no known kind, makes the result
    ``unreadable`` (exit code 2); a file that is read but invalid is a finding (exit code 1).
    """
    result = CheckResult()
    binding, tactics = _sort_extra(result, extra, binding, tactics)
    for path in (model_path, binding, tactics):
        if path is not None and not _readable(result, path):
            result.unreadable = True
    if result.unreadable:
        return result
    loaded_binding: Binding | None = None
    if binding is not None:
        try:
            loaded_binding = load_binding(binding)
        except ModelFileError as exc:
            result.findings.append(Finding.from_error(exc))
    try:
        model = load_goal_model(model_path, loaded_binding, strict=False)
    except ModelFileError as exc:
        result.findings.append(Finding.from_error(exc))
        return result
    result.model = model
    if result.findings:
        # Without its binding every agent looks unobserved and every endpoint unknown: a
        # list of such findings would only hide the one that matters.
        return result
    result.findings.extend(model.findings)
    if not model.errors():
        try:
            Evaluator(model)
        except ModelFileError as exc:
            result.findings.append(Finding.from_error(exc))
    if tactics is not None:
        _check_tactics_file(result, model, tactics, modes=modes, failsafe=failsafe)
    return result


def _readable(result: CheckResult, path: str | Path) -> bool:
    """Whether ``path`` can be read as text at all; if not, the finding says why."""
    try:
        read_text_limited(path)
    except ModelFileError as exc:
        result.findings.append(Finding.from_error(exc))
        return False
    return True


def _sort_extra(
    result: CheckResult,
    extra: tuple[str | Path, ...],
    binding: str | Path | None,
    tactics: str | Path | None,
) -> tuple[str | Path | None, str | Path | None]:
    """Tell the extra files apart: the binding and tactics files; the others are findings."""
    for path in extra:
        try:
            kind = _sniff_kind(path)
        except ModelFileError as exc:
            result.findings.append(Finding.from_error(exc))
            result.unreadable = True
            continue
        if kind == "binding" and binding is None:
            binding = path
            continue
        if kind == "tactics" and tactics is None:
            tactics = path
            continue
        if kind in ("binding", "tactics"):
            message, hint = f"a second {kind} file", "give one binding and one tactics file"
        elif kind == "goal model":
            message, hint = "a second goal model", "give the goal model first, then the others"
        else:
            message = "cannot tell whether this is a binding or a tactics file"
            hint = "start it with 'anunnaki: binding/1' or 'anunnaki: tactics/1'"
        result.findings.append(Finding("error", message, str(path), 1, hint=hint))
        result.unreadable = True
    return binding, tactics


def _check_tactics_file(
    result: CheckResult,
    model: GoalModel,
    tactics: str | Path,
    *,
    modes: PlatformModes | None,
    failsafe: str | None,
) -> None:
    """Load the tactics file and add what is wrong with it to ``result``."""
    try:
        ts = load_tactics(tactics)
    except ModelFileError as exc:
        result.findings.append(Finding.from_error(exc))
        return
    result.tactics = ts
    found = check_tactics(model, ts, str(tactics))
    result.findings.extend(sorted(found, key=lambda f: f.line or 0))
    result.findings.extend(_unaddressed(model, ts))
    if modes is not None:
        result.findings.extend(check_modes(ts, str(tactics), modes))
    if failsafe is not None:
        result.findings.extend(check_failsafe(ts, str(tactics), failsafe))


def check_tactics(model: GoalModel, ts: TacticSet, path: str | None) -> list[Finding]:
    """Check that tactics name known goals, endpoints and attributes."""
    return [
        *_goal_findings(model, ts, path),
        *_endpoint_findings(model, ts, path),
        *_expression_findings(model, ts, path),
    ]


def check_modes(ts: TacticSet, path: str | None, modes: PlatformModes) -> list[Finding]:
    """An error for every ``change_mode`` action asking for a mode the platform lacks.

    A tactic that requests an undeclared mode fails at run time, when it is needed most (the
    platform refuses the request); this finds it before the run.
    """
    out: list[Finding] = []
    declared = ", ".join(modes.modes) or "none"
    where = f" ({modes.declared})" if modes.declared else ""
    for tactic in ts.tactics:
        for i, action in enumerate(tactic.actions):
            if not isinstance(action, ChangeModeAction) or action.mode in modes.modes:
                continue
            out.append(
                Finding(
                    "error",
                    f"tactic '{tactic.name}' requests mode '{action.mode}', which the "
                    f"{modes.platform} platform does not declare",
                    path,
                    action.source.line,
                    f"tactics[{tactic.name}].actions[{i}].mode",
                    f"the {modes.platform} platform's modes{where}: {declared}; request one "
                    "of them, or declare the mode on the platform",
                )
            )
    return out


def check_failsafe(ts: TacticSet, path: str | None, failsafe: str) -> list[Finding]:
    """An error when the fail-safe tactic a Utu configuration names is not a tactic.

    Utu runs the fail-safe when no other tactic can help; a name that is not in the
    tactics file stops a run at bring-up.
    """
    names = sorted(t.name for t in ts.tactics)
    if failsafe in names:
        return []
    return [
        Finding(
            "error",
            f"the fail-safe tactic {failsafe!r} is not in the tactics file",
            path,
            None,
            "failsafe",
            f"name one of the tactics ({', '.join(names) or 'none'})",
        )
    ]


def check_swaps(
    model: GoalModel, ts: TacticSet, path: str | None, models: ModelCatalogue
) -> list[Finding]:
    """A warning for every ``swap_model`` action the model manager would refuse.

    Only actions sent to the manager's swap service count (a tactic may address another
    manager). The manager refuses a swap for another LEC, to a model id it does not have, or
    to a domain it has no model for: the tactic then fails when it is needed, and Utu
    escalates. A warning, not an error: one tactics file may serve registries that do not
    (yet) have a model for every domain it names.
    """
    out: list[Finding] = []
    for tactic in ts.tactics:
        for i, action in enumerate(tactic.actions):
            if not isinstance(action, SwapModelAction):
                continue
            if model.endpoint_name(action.service) != models.service:
                continue
            refused = _refused_swap(tactic.name, action, models)
            if refused is not None:
                key, message, hint = refused
                element = f"tactics[{tactic.name}].actions[{i}].{key}"
                out.append(Finding("warning", message, path, action.source.line, element, hint))
    return out


def _refused_swap(
    tactic: str, action: SwapModelAction, models: ModelCatalogue
) -> tuple[str, str, str] | None:
    """Why the model manager would refuse ``action``: (field, message, hint), or ``None``."""
    listed = f" ({models.source})" if models.source else ""
    if action.lec != models.lec:
        return (
            "lec",
            f"tactic '{tactic}' swaps a model of lec '{action.lec}', but the model manager "
            f"serves lec '{models.lec}': it will refuse the swap",
            f"write 'lec: {models.lec}', the registry's lec{listed}",
        )
    if action.model is not None and action.model not in models.ids:
        return (
            "model",
            f"tactic '{tactic}' swaps to model '{action.model}', which the model registry "
            "does not have: the model manager will refuse the swap",
            f"the registry's models{listed}: {', '.join(models.ids) or 'none'}; name one of "
            "them, or add the model to the registry",
        )
    if action.domain is not None and action.domain not in models.domains:
        return (
            "domain",
            f"tactic '{tactic}' swaps to domain '{action.domain}', for which the model "
            "registry has no model: the model manager will refuse the swap",
            f"the registry's domains{listed}: {', '.join(models.domains) or 'none'}; name "
            "one of them, or add a model for the domain to the registry",
        )
    return None


def _goal_findings(model: GoalModel, ts: TacticSet, path: str | None) -> list[Finding]:
    """A finding for every reference to a goal the model does not have."""
    from anunnaki.goals import did_you_mean as _did_you_mean

    return [
        Finding(
            "error",
            f"unknown goal '{goal}'",
            path,
            ref.line,
            ref.element,
            _did_you_mean(goal, model.goals),
        )
        for goal, refs in ts.referenced_goals().items()
        if goal not in model.goals
        for ref in refs
    ]


def _endpoint_findings(model: GoalModel, ts: TacticSet, path: str | None) -> list[Finding]:
    """Findings for unknown endpoints, topics requested (or services published), payloads."""
    out: list[Finding] = []
    for ep in ts.referenced_endpoints():
        spec = model.endpoint(ep.name)
        if spec is None:
            out.append(_unknown_endpoint(model, ep, path))
            continue
        if spec.kind != ep.kind:
            out.append(
                Finding(
                    "error",
                    f"{ep.name} is a {spec.kind}, not a {ep.kind}",
                    path,
                    ep.line,
                    ep.element,
                    "publish to topics, request services",
                )
            )
        if spec.logical is not None and ep.name == spec.name:
            out.append(
                Finding(
                    "warning",
                    f"{ep.name} is named directly; its logical name is '{spec.logical}'",
                    path,
                    ep.line,
                    ep.element,
                    f"write {spec.logical} instead, so the tactic runs unchanged on every "
                    "binding that maps it (docs/tactics.md, 'Logical endpoints')",
                )
            )
        for problem in _payload_problems(spec, ep.payload):
            out.append(Finding("error", problem, path, ep.line, ep.element))
    return out


def _unknown_endpoint(model: GoalModel, ep: EndpointReference, path: str | None) -> Finding:
    """The finding for a tactic's endpoint that neither the model nor its binding has."""
    known = sorted(n for n, e in model.endpoints.items() if e.kind == ep.kind)
    logical = sorted(
        k for k, n in model.logical.items() if (e := model.endpoints.get(n)) and e.kind == ep.kind
    )
    if ep.name.startswith("/"):
        hint = f"the binding's {ep.kind}s: {', '.join(known) or 'none'}"
        if logical:
            hint += (
                f"; to migrate, name a logical endpoint ({', '.join(logical)}) in the "
                "tactic, which every binding maps to its own name"
            )
    else:
        hint = (
            f"the binding maps no logical {ep.kind} '{ep.name}'; its logical {ep.kind}s: "
            f"{', '.join(logical) or 'none'} (add 'logical: {ep.name}' to the binding's "
            f"{ep.kind} that does this)"
        )
    return Finding("error", f"unknown {ep.kind} {ep.name}", path, ep.line, ep.element, hint)


def _expression_findings(model: GoalModel, ts: TacticSet, path: str | None) -> list[Finding]:
    """Findings for expressions that do not compile or name unknown agents or attributes."""
    out: list[Finding] = []
    for eref in ts.expressions():
        try:
            expr = compile_expression(
                eref.expression, path=path, line=eref.line, element=eref.element
            )
        except ExpressionError as exc:
            out.append(Finding.from_error(exc))
            continue
        for agent in sorted(expr.agents):
            if agent not in model.agents:
                out.append(
                    Finding(
                        "error",
                        f"unknown agent '{agent}' in '{expr.text}'",
                        path,
                        eref.line,
                        eref.element,
                    )
                )
        for attr in sorted(expr.refs):
            agent_obj = model.agents.get(attr.agent)
            if agent_obj is not None and not agent_obj.knows(attr.attribute):
                out.append(
                    Finding(
                        "error",
                        f"unknown attribute '{attr}' in '{expr.text}'",
                        path,
                        eref.line,
                        eref.element,
                        f"{attr.agent} publishes: "
                        + (", ".join(agent_obj.attribute_names()) or "none"),
                    )
                )
    return out


_JSON_TYPES: dict[str, tuple[type, ...]] = {
    "string": (str,),
    "number": (int, float),
    "integer": (int,),
    "boolean": (bool,),
    "object": (dict,),
    "array": (list,),
}


def _payload_problems(spec: EndpointSpec, payload: dict[str, Any]) -> list[str]:
    problems: list[str] = []
    if not spec.payload:
        return problems
    for name, value in payload.items():
        fld = spec.payload.get(name)
        if fld is None:
            problems.append(
                f"{spec.name} takes no field '{name}' (fields: {', '.join(spec.payload)})"
            )
            continue
        types = _JSON_TYPES.get(fld.type)
        bad_type = types is not None and (
            not isinstance(value, types) or (fld.type != "boolean" and isinstance(value, bool))
        )
        if bad_type:
            article = "an" if fld.type[0] in "aeiou" else "a"
            problems.append(
                f"field '{name}' of {spec.name} must be {article} {fld.type}, got {value!r}"
            )
        elif fld.enum is not None and value not in fld.enum:
            choices = ", ".join(map(str, fld.enum))
            problems.append(
                f"field '{name}' of {spec.name} must be one of {choices}; got {value!r}"
            )
    for name, fld in spec.payload.items():
        if fld.required and name not in payload:
            problems.append(f"{spec.name} needs field '{name}'")
    return problems


def _unaddressed(model: GoalModel, ts: TacticSet) -> list[Finding]:
    named = _addressed_goals(ts)
    covered: dict[str, bool] = {}

    def has_named_ancestor(goal: str, seen: set[str]) -> bool:
        for parent in model.parents.get(goal, []):
            if parent in seen:
                continue
            seen.add(parent)
            if parent in named or has_named_ancestor(parent, seen):
                return True
        return False

    def cover(goal: str, depth: int = 0) -> bool:
        if goal in covered:
            return covered[goal]
        g = model.goals[goal]
        ok = goal in named
        if not ok and g.children and depth < 256:
            kids = [cover(c, depth + 1) for c in g.children if c in model.goals]
            ok = all(kids) if g.refinement == "and" else any(kids)
        covered[goal] = ok
        return ok

    # Goals that serve only as resolutions of obstacles are not requirements of their own:
    # while one is unsatisfied its obstacle simply obstructs, which the tree handles.
    resolution_only = {
        g
        for o in model.obstacles.values()
        for g in o.resolutions
        if not model.parents.get(g) and g != model.root
    }
    out: list[Finding] = []
    for gid in model.goals:
        if gid in resolution_only:
            continue
        if not cover(gid) and not has_named_ancestor(gid, set()):
            out.append(
                Finding(
                    "warning",
                    "no tactic addresses a violation of this goal",
                    model.path,
                    model.line_of("goals", gid),
                    f"goals[{gid}]",
                    f"add a tactic with precondition 'goal: {gid}, state: unsatisfied' "
                    "(or on an ancestor)",
                )
            )
    return out


def _addressed_goals(ts: TacticSet) -> set[str]:
    """The goals whose violation (or unknown status) some tactic's precondition names."""
    return {
        cond.goal
        for tactic in ts.tactics
        for cond in tactic.preconditions
        if isinstance(cond, GoalState) and cond.state in ("unsatisfied", "unknown")
    }
