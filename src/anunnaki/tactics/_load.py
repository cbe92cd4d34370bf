"""From plain data to a checked tactic set: pydantic's errors as file, line, element and hint."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from pydantic import (
    BaseModel,
    ValidationError,
)

from anunnaki._safeyaml import LineMap, element_path
from anunnaki.errors import ModelFileError, validation_message
from anunnaki.tactics._actions import action_class, action_hint
from anunnaki.tactics._schema import (
    ExpressionCondition,
    GoalState,
    Tactic,
    TacticSet,
    _precondition_form,
)
from anunnaki.tactics._values import (
    CHANNEL_HINT,
    FORMAT_TAG,
    STATE_HINT,
    SourceRef,
    tactic_element,
)

__all__ = [
    "build_tactic_set",
]

# --------------------------------------------------------------------------- loading


def _without_tags(loc: Sequence[str | int]) -> tuple[str | int, ...]:
    """Drop the union tag pydantic puts after ``tactics[i].preconditions[j]``."""
    out = tuple(loc)
    if (
        len(out) > 4
        and out[0] == "tactics"
        and isinstance(out[1], int)
        and isinstance(out[3], int)
        and out[2] == "preconditions"
        and out[4] in ("goal", "expression")
    ):
        return (*out[:4], *out[5:])
    return out


def _model_at(loc: Sequence[str | int], data: Any) -> type[BaseModel] | None:
    """Return the model class of the element at ``loc`` (for "valid fields" hints)."""
    if not loc:
        return TacticSet
    if len(loc) < 2 or loc[0] != "tactics" or not isinstance(loc[1], int):
        return None
    if len(loc) == 2:
        return Tactic
    if len(loc) != 4 or not isinstance(loc[3], int):
        return None
    node = data
    for part in loc:
        node = node[part]  # an extra field was found there, so the path exists
    if loc[2] == "postconditions":
        return GoalState
    if loc[2] == "preconditions":
        return ExpressionCondition if _precondition_form(node) == "expression" else GoalState
    if loc[2] == "actions" and isinstance(node, Mapping):
        tag = node.get("type")
        return action_class(tag) if isinstance(tag, str) else None
    return None


def _data_path(data: Any, loc: Sequence[str | int]) -> tuple[str | int, ...]:
    """Follow an error location through the data as far as it goes."""
    path: list[str | int] = []
    node = data
    for part in loc:
        found = (isinstance(node, Mapping) and part in node) or (
            isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node)
        )
        if not found:
            break
        node = node[part]
        path.append(part)
    return tuple(path)


def _render(data: Any, path: Sequence[str | int]) -> str:
    """Render a data path, naming tactics by name: ``tactics[fail-safe].actions[1].to``."""
    if len(path) >= 2 and path[0] == "tactics" and isinstance(path[1], int):
        try:
            name = data["tactics"][path[1]]["name"]
        except (KeyError, IndexError, TypeError):
            name = None
        if isinstance(name, str) and name.strip():
            return tactic_element(name.strip(), path[2:])
    return element_path(path)


def _hint(err: Mapping[str, Any], loc: Sequence[str | int], data: Any) -> str | None:
    ctx = err.get("ctx") or {}
    if "hint" in ctx:
        return str(ctx["hint"])
    kind = err["type"]
    names = [p for p in loc if isinstance(p, str)]
    last = names[-1] if names else ""
    if kind in ("union_tag_invalid", "union_tag_not_found") or (
        kind == "model_attributes_type" and len(loc) == 4 and loc[2] == "actions"
    ):
        return action_hint() + " (each action says which in 'type')"
    if kind == "literal_error":
        hints = {"state": STATE_HINT, "channel": CHANNEL_HINT}
        return action_hint() if last == "type" else hints.get(last)
    if kind == "missing":
        return f"add '{last}'"
    if kind == "extra_forbidden":
        model = _model_at(loc[:-1], data)
        return None if model is None else "valid fields here: " + ", ".join(model.model_fields)
    if kind == "too_short" and last in ("preconditions", "actions"):
        return f"a tactic needs at least one entry in '{last}'"
    if kind in ("greater_than", "greater_than_equal", "finite_number") and last in (
        "deadline",
        "cooldown",
        "timeout",
    ):
        return "give seconds as a finite number" + (
            " above 0" if kind == "greater_than" else " (0 or more)"
        )
    return None


def _message(err: Mapping[str, Any], loc: Sequence[str | int]) -> str:
    kind = err["type"]
    in_actions = len(loc) == 4 and loc[2] == "actions"
    if kind == "union_tag_invalid":
        return f"unknown action type {err['ctx']['tag']!r}"
    if kind == "union_tag_not_found":
        return "the action has no 'type'"
    if kind == "model_attributes_type" and in_actions:
        return "an action is a mapping with a 'type' and its fields"
    if kind == "extra_forbidden":
        return f"unknown field {loc[-1]!r}"
    if kind == "missing":
        return f"missing field {loc[-1]!r}"
    return validation_message(err)


def validation_error(
    exc: ValidationError, data: Any, lines: LineMap, source: str | Path | None
) -> ModelFileError:
    """Turn a pydantic error about ``data`` into a located :class:`ModelFileError`.

    Of several problems, the one written first in the file is reported, and the message says
    how many more there are.
    """
    found: list[tuple[int, int, ModelFileError]] = []
    for order, err in enumerate(exc.errors(include_url=False)):
        ctx = err.get("ctx") or {}
        loc = _without_tags((*err["loc"], *ctx.get("where", ())))
        path = _data_path(data, loc)
        line = lines.line(path)
        shown = (*path, loc[-1]) if err["type"] == "missing" and len(loc) > len(path) else path
        message = _message(err, loc)
        if "other" in ctx:
            other = lines.line(_data_path(data, tuple(ctx["other"])))
            if other is not None and line is not None:
                message += f", on lines {other} and {line}"
        problem = ModelFileError(
            message,
            path=source,
            line=line,
            element=_render(data, shown) if shown else None,
            hint=_hint(err, loc, data),
        )
        found.append((line if line is not None else 0, order, problem))
    found.sort(key=lambda item: (item[0], item[1]))
    first = found[0][2]
    if len(found) > 1:
        more = len(found) - 1
        first = ModelFileError(
            f"{first.message} (and {more} more problem{'s' if more > 1 else ''})",
            path=first.path,
            line=first.line,
            element=first.element,
            hint=first.hint,
        )
    return first


def build_tactic_set(data: Any, lines: LineMap, source: str | Path | None) -> TacticSet:
    """Validate plain data (read from either file form) into a located :class:`TacticSet`.

    Args:
        data: The file's content as dicts/lists/scalars, without the YAML format tag.
        lines: Element path → line, for error messages and for every element's ``source``.
        source: The file name for messages, or ``None``.

    Raises:
        ModelFileError: the first problem, with file, line, element and a hint.

    """
    if not isinstance(data, Mapping):
        raise ModelFileError(
            "a tactics file holds a mapping with a 'tactics' list",
            path=source,
            line=lines.line(()),
            hint=f"start the file with 'anunnaki: {FORMAT_TAG}' and a 'tactics:' list",
        )
    try:
        tactic_set = TacticSet.model_validate(data)
    except ValidationError as exc:
        raise validation_error(exc, data, lines, source) from None
    path = None if source is None else str(source)

    def at(*parts: str | int) -> SourceRef:
        return SourceRef(path, lines.line(parts))

    tactic_set._locate(at())
    for i, tactic in enumerate(tactic_set.tactics):
        tactic._locate(at("tactics", i))
        for j, cond in enumerate(tactic.preconditions):
            if isinstance(cond, ExpressionCondition):
                cond._locate(at("tactics", i, "preconditions", j, "expression"))
            else:
                cond._locate(at("tactics", i, "preconditions", j))
        for j, action in enumerate(tactic.actions):
            action._locate(at("tactics", i, "actions", j))
        for j, post in enumerate(tactic.postconditions):
            post._locate(at("tactics", i, "postconditions", j))
    return tactic_set
