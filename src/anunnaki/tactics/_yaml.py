"""The YAML form of tactics files: ``anunnaki: tactics/1`` and a ``tactics:`` list.

Reading goes through :func:`anunnaki._safeyaml.load_yaml` (no aliases, no language tags, no
duplicate keys, size and depth limits), so the data and its line map feed the same validation
as the XML form.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from anunnaki._safeyaml import load_yaml
from anunnaki.errors import ModelFileError
from anunnaki.tactics._load import (
    build_tactic_set,
)
from anunnaki.tactics._schema import (
    Tactic,
    TacticSet,
)
from anunnaki.tactics._values import (
    FORMAT_TAG,
    MAX_DEPTH,
)

__all__ = ["dump_tactics_yaml", "parse_tactics_yaml", "tactic_set_to_data"]

_TAG_HINT = f"a tactics file starts with the line 'anunnaki: {FORMAT_TAG}'"


def parse_tactics_yaml(text: str, *, source: str | Path | None = None) -> TacticSet:
    """Parse the YAML form of a tactics file.

    Args:
        text: The document.
        source: The file it came from, for messages and ``source`` references.

    Raises:
        ModelFileError: hostile, malformed or invalid YAML, naming file, line and element.

    """
    name = source if source is not None else "<input>"
    try:
        data, lines = load_yaml(name, text=text, max_depth=MAX_DEPTH)
    except ValueError as exc:
        # A scalar PyYAML cannot build (an integer over 4300 digits, a date like 2024-13-45).
        raise ModelFileError(
            f"invalid YAML value: {str(exc)[:80]}",
            path=source,
            hint="quote values that are meant as text",
        ) from None
    if not isinstance(data, dict):
        raise ModelFileError(
            "a tactics file is a YAML mapping", path=source, line=lines.line(()), hint=_TAG_HINT
        )
    tag = data.get("anunnaki")
    if tag != FORMAT_TAG:
        line = lines.line(("anunnaki",)) if "anunnaki" in data else lines.line(())
        if tag is None:
            message = "missing format tag 'anunnaki'"
        elif isinstance(tag, str) and tag.startswith("tactics/"):
            message = f"unsupported tactics format version {tag[len('tactics/') :]!r}"
        else:
            message = f"this is not a tactics file (anunnaki: {tag})"
        raise ModelFileError(
            message,
            path=source,
            line=line,
            element="anunnaki",
            hint=_TAG_HINT + (f"; this Anunnaki reads {FORMAT_TAG}" if tag is not None else ""),
        )
    body = {key: value for key, value in data.items() if key != "anunnaki"}
    return build_tactic_set(body, lines, source)


def _seconds(value: float) -> float | int:
    """Write whole seconds without ``.0`` (they read back as the same float)."""
    return int(value) if value.is_integer() and abs(value) < 1e15 else value


def _tactic_data(tactic: Tactic) -> dict[str, Any]:
    out: dict[str, Any] = {"name": tactic.name}
    if tactic.description:
        out["description"] = tactic.description
    if tactic.priority:
        out["priority"] = tactic.priority
    out["preconditions"] = [cond.model_dump() for cond in tactic.preconditions]
    out["actions"] = []
    for action in tactic.actions:
        fields = action.model_dump(exclude_defaults=True, exclude={"type"})
        if "timeout" in fields:
            fields["timeout"] = _seconds(fields["timeout"])
        out["actions"].append({"type": action.type, **fields})
    if tactic.postconditions:
        out["postconditions"] = [post.model_dump() for post in tactic.postconditions]
    if tactic.postconditions or tactic.deadline != Tactic.model_fields["deadline"].default:
        out["deadline"] = _seconds(tactic.deadline)
    if tactic.cooldown:
        out["cooldown"] = _seconds(tactic.cooldown)
    if tactic.requires_approval:
        out["requires_approval"] = True
    if tactic.conflicts:
        out["conflicts"] = list(tactic.conflicts)
    return out


def tactic_set_to_data(tactic_set: TacticSet) -> dict[str, Any]:
    """Return the YAML form's data: format tag first, defaults left out."""
    out: dict[str, Any] = {"anunnaki": FORMAT_TAG}
    if tactic_set.name is not None:
        out["name"] = tactic_set.name
    out["tactics"] = [_tactic_data(tactic) for tactic in tactic_set.tactics]
    return out


class _Dumper(yaml.SafeDumper):
    """Indents lists under their key, as people write them."""

    def increase_indent(self, flow: bool = False, indentless: bool = False) -> None:
        super().increase_indent(flow, False)


def dump_tactics_yaml(tactic_set: TacticSet) -> str:
    """Write a tactic set in the YAML form; :func:`parse_tactics_yaml` reads it back equal."""
    return yaml.dump(
        tactic_set_to_data(tactic_set),
        Dumper=_Dumper,
        sort_keys=False,
        allow_unicode=True,
        default_flow_style=False,
        width=100,
    )
