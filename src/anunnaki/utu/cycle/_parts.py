"""A Utu configuration with its files loaded and checked: what every part of the cycle needs.

Loading is the bring-up check of guideline B5: every file is read, parsed and checked as
``anunnaki check`` does before any part declares anything on the bus, and a problem raises
a :class:`~anunnaki.errors.ModelFileError` naming the file, line and element.
"""

from __future__ import annotations

import dataclasses
import sqlite3
from dataclasses import dataclass, field
from pathlib import Path

from anunnaki._findings import Finding
from anunnaki.check import check_failsafe, check_tactics
from anunnaki.errors import AnunnakiError, ModelFileError
from anunnaki.goals import GoalModel, parse_binding, parse_goal_model
from anunnaki.tactics import TacticSet, parse_tactics_xml, parse_tactics_yaml
from anunnaki.utu._config import UtuConfig
from anunnaki.utu.cycle._knowledge import Knowledge

__all__ = [
    "NodeConfigError",
    "UtuParts",
    "check_parts",
    "load_parts",
    "load_tactics_text",
    "open_knowledge",
    "parts_from_sources",
    "record_run",
]


class NodeConfigError(AnunnakiError):
    """A Utu node or manager cannot be brought up with the configuration it was given."""


def load_tactics_text(text: str, path: str | None) -> TacticSet:
    """Parse a tactics file's text, XML or YAML by its look."""
    source = path or "<tactics>"
    if text.lstrip("\ufeff \t\r\n").startswith("<"):
        return parse_tactics_xml(text, source=source)
    return parse_tactics_yaml(text, source=source)


@dataclass(frozen=True)
class UtuParts:
    """A Utu configuration with its files loaded and checked (what every node needs).

    Attributes:
        config: The configuration (paths absolute).
        sources: ``goal_model``/``binding``/``tactics`` -> (path, text), as recorded in
            the knowledge base.
        model: The goal model with its binding applied.
        tactics: The tactics.
        warnings: Warning-level findings of the tactics check (not fatal).

    """

    config: UtuConfig
    sources: dict[str, tuple[str | None, str]]
    model: GoalModel
    tactics: TacticSet
    warnings: list[Finding] = field(default_factory=list)


def check_parts(parts: UtuParts) -> UtuParts:
    """Check the tactics against the model and the fail-safe's name; raise on an error."""
    t = parts.sources.get("tactics")
    path = t[0] if t else None
    findings = check_tactics(parts.model, parts.tactics, path)
    failsafe = parts.config.failsafe
    if failsafe is not None:
        findings += check_failsafe(parts.tactics, path, failsafe)
    errors = [f for f in findings if f.severity == "error"]
    if errors:
        raise errors[0].to_error()
    return dataclasses.replace(parts, warnings=findings)


def parts_from_sources(config: UtuConfig, sources: dict[str, tuple[str | None, str]]) -> UtuParts:
    """Parse and check recorded file texts (a reload, a replay, a restart)."""
    b = sources.get("binding")
    binding = parse_binding(b[1], source=b[0] or "<binding>") if b else None
    if "goal_model" not in sources:
        raise ModelFileError("no goal model was given", hint="give goal_model")
    gpath, gtext = sources["goal_model"]
    model = parse_goal_model(gtext, source=gpath or "<goal-model>", binding=binding)
    t = sources.get("tactics")
    tactics = load_tactics_text(t[1], t[0]) if t else TacticSet(tactics=[])
    return check_parts(UtuParts(config, dict(sources), model, tactics))


def load_parts(config: UtuConfig) -> UtuParts:
    """Load and check the goal model, binding and tactics of ``config`` (guideline B5).

    Raises:
        ModelFileError: A file is missing or invalid, or a tactic names an unknown goal,
            endpoint or the fail-safe is not a tactic; the message names file and line.

    """
    sources: dict[str, tuple[str | None, str]] = {}
    for kind in ("goal_model", "binding", "tactics"):
        path = getattr(config, kind)
        if path is None:
            continue
        try:
            sources[kind] = (path, Path(path).read_text(encoding="utf-8"))
        except OSError as exc:
            raise ModelFileError(
                f"cannot read the {kind.replace('_', ' ')}: {exc.strerror}",
                path=path,
                hint="check the path in the Utu configuration (relative to its file)",
            ) from exc
    return parts_from_sources(config, sources)


def record_run(knowledge: Knowledge, parts: UtuParts) -> None:
    """Record the run's settings and, on a fresh knowledge base, the files' texts in force.

    What ``replay`` and ``reload`` start from; whoever opens the run's knowledge base first
    (the manager, or the knowledge node) records them.
    """
    config = parts.config
    knowledge.set_meta(
        "settings",
        {
            "dwell": config.dwell,
            "warmup": config.warmup,
            "failsafe": config.failsafe,
            "escalate_to_run_stop": config.escalate_to_run_stop,
            "run_stop_service": config.run_stop.service,
        },
    )
    if not knowledge.models_at():
        for kind, (path, text) in parts.sources.items():
            knowledge.record_model(0.0, kind, path, text)


def open_knowledge(path: str) -> Knowledge:
    """Open (or create) a knowledge base, or say clearly why it cannot be.

    Raises:
        NodeConfigError: SQLite cannot open the file (missing folder, no permission, …).

    """
    try:
        return Knowledge(path)
    except sqlite3.Error as exc:
        raise NodeConfigError(
            f"cannot open the knowledge base {path}: {exc} (check that its folder exists "
            "and is writable)"
        ) from exc
