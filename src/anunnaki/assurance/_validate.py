"""The GSN rules a case must keep (GSN Community Standard v3, core notation).

:func:`validate_gsn` checks a document in the layout the gsn2x tool reads (a mapping of
element id → ``text``, ``supportedBy``, ``inContextOf``, ``undeveloped``):

1. every id is unique and starts with its type's prefix: ``G`` goal, ``S`` strategy, ``Sn``
   solution, ``C`` context, ``A`` assumption, ``J`` justification;
2. every element has a non-empty ``text``;
3. *SupportedBy* links a goal to goals, strategies or solutions, and a strategy to goals;
   a solution, context, assumption or justification supports nothing below it (solutions
   only at the leaves);
4. *InContextOf* links a goal or strategy to contexts, assumptions and justifications only;
5. every goal and strategy is supported or marked ``undeveloped: true``, never both;
6. the SupportedBy graph has no cycle, one top-level goal, and reaches every goal,
   strategy and solution from it; every context, assumption and justification is used.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any, Final

__all__ = ["PREFIXES", "element_type", "validate", "validate_gsn", "validate_gsn_file"]

#: Prefix → element type; ``Sn`` is tried before ``S``.
PREFIXES: Final = (
    ("Sn", "solution"),
    ("G", "goal"),
    ("S", "strategy"),
    ("C", "context"),
    ("A", "assumption"),
    ("J", "justification"),
)

_SUPPORTS: Final = {
    "goal": {"goal", "strategy", "solution"},
    "strategy": {"goal"},
}
_CONTEXTUAL: Final = {"context", "assumption", "justification"}
_KEYS: Final = {"text", "supportedBy", "inContextOf", "undeveloped", "url", "classes", "level"}


def element_type(ident: str) -> str | None:
    """The GSN type an id's prefix names, or ``None``."""
    for prefix, kind in PREFIXES:
        if ident.startswith(prefix):
            return kind
    return None


def validate_gsn(doc: Mapping[str, Any]) -> list[str]:
    """Every breach of the rules above in a gsn2x-layout document; ``[]`` when it keeps them."""
    problems: list[str] = []
    types: dict[str, str] = {}
    for ident, el in doc.items():
        kind = element_type(str(ident))
        if kind is None:
            problems.append(f"{ident}: the id starts with no GSN prefix (G, S, Sn, C, A, J)")
            continue
        types[str(ident)] = kind
        if not isinstance(el, Mapping):
            problems.append(f"{ident}: not a mapping")
            continue
        extra = set(el) - _KEYS
        if extra:
            problems.append(f"{ident}: unknown attributes {sorted(extra)}")
        if not isinstance(el.get("text"), str) or not el["text"].strip():
            problems.append(f"{ident}: no text")
    links: dict[str, list[str]] = {}
    for ident, kind in types.items():
        el = doc[ident]
        if isinstance(el, Mapping):
            links[ident] = list(el.get("supportedBy") or [])
            problems += _links(ident, kind, el, types)
    problems += _cycles(links)
    problems += _reach(types, links)
    problems += _unused(types, doc)
    return problems


def _links(ident: str, kind: str, el: Mapping[str, Any], types: dict[str, str]) -> list[str]:
    """Rules 3 to 5 for one element."""
    problems = []
    below = list(el.get("supportedBy") or [])
    context = list(el.get("inContextOf") or [])
    undeveloped = el.get("undeveloped") is True
    for b in below:
        if b not in types:
            problems.append(f"{ident}: supportedBy names {b!r}, which does not exist")
        elif types[b] not in _SUPPORTS.get(kind, set()):
            problems.append(f"{ident} ({kind}) cannot be supported by {b} ({types[b]})")
    for c in context:
        if c not in types:
            problems.append(f"{ident}: inContextOf names {c!r}, which does not exist")
        elif types[c] not in _CONTEXTUAL:
            problems.append(
                f"{ident}: inContextOf {c} ({types[c]}): only contexts, assumptions and "
                "justifications"
            )
    if context and kind not in ("goal", "strategy"):
        problems.append(f"{ident} ({kind}) cannot have inContextOf")
    if kind in ("goal", "strategy"):
        if below and undeveloped:
            problems.append(f"{ident}: both supported and marked undeveloped")
        if not below and not undeveloped:
            problems.append(f"{ident}: neither supported nor marked undeveloped")
    elif undeveloped:
        problems.append(f"{ident} ({kind}) cannot be undeveloped")
    return problems


def _cycles(links: dict[str, list[str]]) -> list[str]:
    """Rule 6: no SupportedBy cycle (depth-first, colouring nodes on the stack)."""
    problems: list[str] = []
    state: dict[str, int] = {}
    for start, below in links.items():
        if state.get(start):
            continue
        stack = [(start, iter(below))]
        state[start] = 1
        while stack:
            node, it = stack[-1]
            nxt = next(it, None)
            if nxt is None:
                state[node] = 2
                stack.pop()
            elif nxt in links and state.get(nxt) == 1:
                problems.append(f"cycle through {nxt} (from {node})")
            elif nxt in links and not state.get(nxt):
                state[nxt] = 1
                stack.append((nxt, iter(links[nxt])))
    return problems


def _reach(types: dict[str, str], links: dict[str, list[str]]) -> list[str]:
    """Rule 6: one top-level goal, from which every goal, strategy and solution is reached."""
    supported = {b for bs in links.values() for b in bs}
    tops = [i for i, k in types.items() if k == "goal" and i not in supported]
    if len(tops) != 1:
        return [f"{len(tops)} top-level goals ({', '.join(tops)}); a case has one"]
    seen = {tops[0]}
    todo = [tops[0]]
    while todo:
        for b in links.get(todo.pop(), []):
            if b not in seen:
                seen.add(b)
                todo.append(b)
    loose = [i for i, k in types.items() if k not in _CONTEXTUAL and i not in seen]
    return [f"not reached from the top-level goal: {', '.join(loose)}"] if loose else []


def _unused(types: dict[str, str], doc: Mapping[str, Any]) -> list[str]:
    """Rule 6: every context, assumption and justification is some element's context."""
    used = {
        c for el in doc.values() if isinstance(el, Mapping) for c in (el.get("inContextOf") or [])
    }
    unused = [i for i, k in types.items() if k in _CONTEXTUAL and i not in used]
    if unused:
        return [f"contexts, assumptions or justifications nothing refers to: {', '.join(unused)}"]
    return []


def validate(case: Any) -> list[str]:
    """:func:`validate_gsn` of a case's export, plus each node's type against its id."""
    from anunnaki.assurance._export import gsn_document

    problems = [
        f"{n.id}: a {n.type} whose id's prefix says {element_type(n.id)}"
        for n in case
        if element_type(n.id) != n.type
    ]
    return problems + validate_gsn(gsn_document(case))


def validate_gsn_file(path: str | Path) -> list[str]:
    """:func:`validate_gsn` of a GSN YAML file; a repeated id (a duplicate key) is a problem."""
    from anunnaki._safeyaml import load_yaml
    from anunnaki.errors import ModelFileError

    try:
        doc, _ = load_yaml(path)
    except ModelFileError as exc:
        return [str(exc)]
    if not isinstance(doc, Mapping):
        return [f"{path}: not a mapping of GSN elements"]
    return validate_gsn(doc)
