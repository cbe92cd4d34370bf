"""What every stage shares: the markers in Knowledge, operator entries, restarts, reloads.

An operator call becomes an *entry* (:func:`operator_entry`) that the monitor stage puts in its
next batch; a reload's files are read and checked here (:func:`reloaded_parts`); a restarted
stage finds its place in the log (:func:`resuming`, :func:`mark_restart`, :func:`last_halt`).
Who owns which field of a tactic's runtime (plan or execute) is written here once.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, cast

from anunnaki._safeyaml import read_text_limited
from anunnaki.errors import ModelFileError
from anunnaki.goals import GoalModel, parse_binding, parse_goal_model
from anunnaki.messages import body_of
from anunnaki.tactics import TacticSet
from anunnaki.utu.cycle._knowledge import Knowledge
from anunnaki.utu.cycle._mape import TacticRuntime
from anunnaki.utu.cycle._parts import UtuParts, check_parts, load_tactics_text, parts_from_sources

__all__ = [
    "EXEC_FIELDS",
    "MAX_RELOAD_BYTES",
    "OPERATOR",
    "PLAN_FIELDS",
    "RESTART",
    "RESTORE_WINDOW",
    "TICK",
    "Sources",
    "build_message",
    "end_step",
    "last_halt",
    "mark_restart",
    "model_from_sources",
    "operator_entry",
    "read_reload_file",
    "read_sources",
    "reloaded_parts",
    "resuming",
    "runtime_row",
    "sources_of",
    "tactics_from_sources",
]

log = logging.getLogger("anunnaki.utu")

#: What Knowledge's inputs table calls the end of a step and an operator call.
TICK = "__tick__"
OPERATOR = "__operator__"
#: Input marker: a stage started on a run's knowledge and took up its state (``node``:
#: which part: ``manager`` for the composed one, or ``analyze``/``plan``/``execute``).
RESTART = "__restart__"
#: Seconds of recorded inputs a restarted analyzer re-reads to recover its values and rates.
RESTORE_WINDOW = 120.0

Sources = dict[str, tuple[str | None, str]]


def build_message(c: Callable[..., Any], **fields: Any) -> Any:
    """Build a cycle message from our own, trusted values (validated only at the bus)."""
    return cast(Any, c).trusted(**fields)


# -- restarts ------------------------------------------------------------------------------------
def resuming(knowledge: Knowledge, node: str = "manager") -> bool:
    """Whether ``node`` takes up a run that it (or its predecessor) was part of.

    The whole manager: the knowledge holds a run (inputs or decisions). One node of a
    per-node run, whose peers may have recorded inputs before it came up (the robot runs
    first): analyze when a step was ever marked (it writes the step ends), plan and execute
    when anything was decided (nothing is decided without both of them).
    """
    if node == "analyze":
        return knowledge.has_input(TICK)
    if node in ("plan", "execute"):
        return knowledge.counts()["decisions"] > 0
    return knowledge.holds_run()


def mark_restart(knowledge: Knowledge, node: str) -> float:
    """Record that ``node`` (``manager``, ``analyze``, ``plan``, ``execute``) took up the run.

    An input marker (:data:`RESTART`, where a replay restarts the same part) and a
    ``restarted`` decision (what ``anunnaki log`` and ``explain`` show), at the run's last
    instant. Returns that instant.
    """
    t = knowledge.last_t()
    knowledge.record_input(t, RESTART, {"node": node})
    knowledge.record_decision(t, "restarted", None, node=node)
    knowledge.flush()
    return t


def end_step(
    knowledge: Knowledge, t: float, *, took: bool, decisions: int, executed: bool = True
) -> bool:
    """Mark the end of the step at ``t`` in Knowledge, if it took or decided something.

    ``took``: the analysis of the step took something (:attr:`AnalysisState.took
    <anunnaki.messages.AnalysisState.took>`); ``decisions``: how many plan and execute
    wrote. The marker is where a replay steps; ``executed=False`` says that no execute
    stage acted on the step (its node was gone), so a replay only analyses it. Returns
    whether a marker was written.
    """
    if not took and decisions <= 0:
        return False
    knowledge.record_input(t, TICK, {} if executed else {"executed": False})
    return True


def last_halt(knowledge: Knowledge) -> tuple[bool, bool]:
    """(paused, run-stopped) as the run's decisions left them (a restart keeps a run-stop)."""
    paused = stopped = False
    for d in knowledge.decisions():
        if d.kind == "run_stop":
            paused = stopped = True
        elif d.kind == "paused":
            paused = True
        elif d.kind == "resumed_adaptation":
            paused = stopped = False
    return paused, stopped


# -- operator calls ------------------------------------------------------------------------------
def operator_entry(op: str, message: Any) -> dict[str, Any]:
    """Turn an operator service request into an op entry, or ``{"error": …}`` to refuse it.

    The operations are ``run_stop``, ``pause``, ``resume``, ``approve``, ``reload``; the
    request names its ``caller`` (recorded with the decision). A reload is checked here, as
    ``anunnaki check`` does, so a broken file is refused with its error before it reaches
    the cycle; the entry then carries the files' *texts*, so every stage applies the same
    version even if a file changes meanwhile.
    """
    body = body_of(message)
    caller = str(body.get("caller") or "unknown")
    entry: dict[str, Any] = {"op": op, "caller": caller}
    if op == "approve":
        tactic = body.get("tactic")
        if not isinstance(tactic, str):
            return {"error": "give 'tactic': the name of a pending tactic"}
        approve = body.get("approve", True)
        if not isinstance(approve, bool):
            return {"error": "'approve' must be true or false"}
        entry["tactic"] = tactic
        entry["approve"] = approve
    elif op == "run_stop":
        entry["reason"] = str(body.get("reason", "operator"))
    elif op == "reload":
        files = {k: body.get(k) for k in ("goal_model", "binding", "tactics")}
        if not any(isinstance(v, str) for v in files.values()):
            return {"error": "give goal_model, binding and/or tactics paths"}
        entry.update({k: v for k, v in files.items() if isinstance(v, str)})
    elif op not in ("pause", "resume"):
        return {"error": f"unknown operation {op!r}"}
    return entry


#: The largest file a hot reload reads (goal models and tactics are small).
MAX_RELOAD_BYTES = 4 << 20


def read_sources(
    base: Mapping[str, tuple[str | None, str]],
    files: Mapping[str, Any],
    roots: Sequence[Path] | None = None,
) -> Sources:
    """``base`` with the named files read (``goal_model``, ``binding``, ``tactics``).

    With ``roots``, a file must lie in one of those folders (symlinks resolved); it must be
    a regular file of at most :data:`MAX_RELOAD_BYTES` (a pipe or a device would block or
    never end), read without following it anywhere else.
    """
    sources = dict(base)
    for kind in ("goal_model", "binding", "tactics"):
        path = files.get(kind)
        if isinstance(path, str):
            sources[kind] = (path, read_reload_file(kind, path, roots))
    return sources


def read_reload_file(kind: str, path: str, roots: Sequence[Path] | None) -> str:
    what = kind.replace("_", " ")
    real = Path(path).resolve()
    if roots is not None and not any(real.is_relative_to(r) for r in roots):
        raise ModelFileError(
            f"refused: the {what} is outside the folders a reload may read",
            path=path,
            hint="put it next to the running files, or list its folder in the Utu "
            f"configuration's reload_dirs (now: {', '.join(map(str, roots)) or 'none'})",
        )
    try:
        return read_text_limited(real, max_bytes=MAX_RELOAD_BYTES)
    except ModelFileError as exc:  # a pipe, a device, too big, unreadable: refused, never read
        raise ModelFileError(
            f"refused: the {what}: {exc.message}", path=path, line=exc.line, hint=exc.hint
        ) from None


def model_from_sources(sources: Mapping[str, tuple[str | None, str]]) -> GoalModel:
    """Parse the goal model (with its binding) from recorded texts."""
    b = sources.get("binding")
    binding = parse_binding(b[1], source=b[0] or "<binding>") if b else None
    if "goal_model" not in sources:
        raise ModelFileError("no goal model was recorded", hint="give goal_model")
    path, text = sources["goal_model"]
    return parse_goal_model(text, source=path or "<goal-model>", binding=binding)


def tactics_from_sources(sources: Mapping[str, tuple[str | None, str]]) -> TacticSet:
    """Parse the tactics from recorded texts (none when there is no tactics file)."""
    t = sources.get("tactics")
    return load_tactics_text(t[1], t[0]) if t else TacticSet(tactics=[])


def reloaded_parts(parts: UtuParts, op: Mapping[str, Any]) -> UtuParts:
    """The parts a reload op asks for (its texts, or its files read now), checked.

    Raises:
        ModelFileError: A file is unreadable or invalid (the message names file and line).

    """
    texts = op.get("sources")
    if isinstance(texts, Mapping):
        sources = {**parts.sources, **sources_of(op)}
    else:
        sources = read_sources(parts.sources, op, parts.config.reload_roots())
    if "goal_model" not in sources:  # a manager built from objects: keep its model
        if "binding" in sources:
            raise ModelFileError(
                "this manager was built without its goal-model file; give goal_model too"
            )
        replaced = dataclasses.replace(
            parts, sources=sources, tactics=tactics_from_sources(sources)
        )
        return check_parts(replaced)
    return parts_from_sources(parts.config, sources)


# -- plan ----------------------------------------------------------------------------------------
# Who owns which part of a tactic's runtime: plan selects (when it became eligible, the last
# "deferred" reason, whether it fired in this episode, queued/pending/rejected); execute
# owns everything that happens once it starts (every other field).
PLAN_FIELDS = frozenset({"tactic", "state", "eligible_since", "blocked_logged", "fired"})
EXEC_FIELDS = tuple(f.name for f in dataclasses.fields(TacticRuntime) if f.name not in PLAN_FIELDS)


def sources_of(op: Mapping[str, Any]) -> Sources:
    return {str(k): (v[0], str(v[1])) for k, v in dict(op["sources"]).items()}


def runtime_row(rt: TacticRuntime) -> dict[str, Any]:
    return {"state": rt.state, **{f: getattr(rt, f) for f in EXEC_FIELDS}}
