"""A launch file's ``managed:`` section: which kind of :data:`anunnaki.managed.MANAGED`.

The kinds and their slot live in :mod:`anunnaki.managed`; this module reads the section
(the general ``{kind: K, …}`` form or the older ``{K: {…}}``), builds the kind from its
validated options, and relays a managed system's time on ``/clock`` when the kind asks.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pydantic import BaseModel

from anunnaki.managed import MANAGED, ManagedKind

__all__ = ["resolve_kind", "split_managed"]


def split_managed(raw: Any) -> tuple[str | None, dict[str, Any], tuple[str, ...]]:
    """``(kind, options, where)`` of a ``managed:`` section (``where``: the options' path).

    ``{kind: K, …}`` is the general form; ``{K: {…}}`` (one key naming a kind) the older one.
    """
    if raw is None or raw == {}:
        return None, {}, ("managed",)
    if not isinstance(raw, dict):
        raise ValueError("managed must be a mapping: {kind: scripted, trace: …}")
    if "kind" in raw:
        kind = raw["kind"]
        if not isinstance(kind, str):
            raise ValueError(f"managed.kind must be a name, got {kind!r}")
        return kind, {k: v for k, v in raw.items() if k != "kind"}, ("managed",)
    if len(raw) == 1:
        ((kind, options),) = raw.items()
        if options is None:
            options = {}
        if not isinstance(options, dict):
            raise ValueError(f"managed.{kind} must be a mapping of its options")
        return str(kind), dict(options), ("managed", str(kind))
    raise ValueError(
        "give one managed system: {kind: NAME, …options} (or the older {NAME: {…options}}); "
        f"got the keys {', '.join(sorted(map(str, raw)))}"
    )


def resolve_kind(name: str, options: BaseModel, base: Path) -> ManagedKind:
    """Build kind ``name`` from its validated options."""
    factory = MANAGED.factory(name)
    kind: ManagedKind = factory(options, base=base)
    return kind
