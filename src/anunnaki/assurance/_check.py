"""Staleness: an artefact whose sha256 changed since the case recorded it.

:func:`check_case` hashes every artefact a case's evidence rests on again; a figure whose
artefact changed (a model re-trained, a registry entry swapped, a results file re-written,
a test edited) or is gone is marked stale, and the statuses above it follow.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from anunnaki.assurance._case import Case, propagate
from anunnaki.lec import sha256_file

__all__ = ["Change", "check_case"]


@dataclass(frozen=True)
class Change:
    """One artefact that is not as the case recorded it.

    Attributes:
        node: The solution whose figure rests on it, or ``(argument)`` for a file the
            argument was built from.
        role: The artefact's role (``model:uav-fog``, ``results`` …).
        path: Its path as recorded.
        recorded: Its sha256 in the case.
        now: Its sha256 today, or ``None`` when it is gone.

    """

    node: str
    role: str
    path: str
    recorded: str
    now: str | None


def check_case(case: Case, root: str | Path | None = None) -> list[Change]:
    """Re-hash the case's artefacts; mark stale what changed (in place) and return the changes.

    A change to a file the argument was built from (the launch, goal model, binding,
    tactics, registry or criteria file) is reported with ``node`` ``(argument)``: the
    argument itself may differ now, so the case needs building again.

    Args:
        case: The case (``read_case``).
        root: Where relative artefact paths lie (default: the root it was built from, or
            the working folder where that folder does not exist here).

    """
    recorded = Path(case.project_root) if case.project_root else None
    base = Path(root) if root else recorded if recorded and recorded.is_dir() else Path.cwd()
    hashes: dict[Path, str | None] = {}
    changes: list[Change] = []
    for node in case.solutions():
        ev = node.evidence
        assert ev is not None
        why = []
        for a in ev.artefacts:
            path = Path(a.path) if Path(a.path).is_absolute() else base / a.path
            if path not in hashes:
                hashes[path] = sha256_file(path) if path.is_file() else None
            now = hashes[path]
            if now != a.sha256:
                changes.append(Change(node.id, a.role, a.path, a.sha256, now))
                why.append(
                    f"{a.path} {'is gone' if now is None else 'changed'} since the "
                    f"case was built ({a.sha256[:12]}… → {(now or '')[:12]}…)"
                )
        if why:
            ev.stale = "; ".join(why) if ev.stale is None else f"{ev.stale}; {'; '.join(why)}"
            node.text = f"{node.text} (STALE: {'; '.join(why)})"
    for a in case.artefacts:  # the files the argument itself was built from
        path = Path(a.path) if Path(a.path).is_absolute() else base / a.path
        now = sha256_file(path) if path.is_file() else None
        if now != a.sha256:
            changes.append(Change("(argument)", a.role, a.path, a.sha256, now))
    propagate(case)
    return changes
