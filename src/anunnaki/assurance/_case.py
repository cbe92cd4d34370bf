"""The case as data: GSN nodes, evidence records, and how support propagates.

A :class:`Case` is what ``anunnaki assurance build`` writes as ``case.json`` and every
export is drawn from. Its nodes are GSN elements (goal, strategy, solution, context,
assumption, justification) linked by ``supported_by`` and ``in_context_of``; each solution
carries one :class:`Evidence` record: the figure, its acceptance criterion, pass or fail,
the command that re-measures it and the sha256 of every artefact it rests on.

Status of a node (:func:`propagate`):

* a solution: ``supported`` (its figure meets its criterion), ``failed`` (it does not),
  ``unverified`` (a test not run) or ``stale`` (an artefact changed since the figure was
  measured);
* a goal with nothing below it: ``undeveloped``;
* otherwise from below: AND over a goal's supporters and an AND strategy's sub-goals, OR
  over an OR strategy's. ``supported`` only when that holds; otherwise the most telling
  reason from below (AND: the worst, OR: the best of failed > stale > unverified >
  undeveloped).

Neither an undeveloped nor a stale node is ever ``supported``.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Final, Literal

from anunnaki.errors import ModelFileError

__all__ = [
    "CASE_FORMAT",
    "STATUSES",
    "Artefact",
    "Case",
    "Evidence",
    "Node",
    "NodeType",
    "combine",
    "propagate",
    "read_case",
]

CASE_FORMAT: Final = "anunnaki-assurance-case/1"

NodeType = Literal["goal", "strategy", "solution", "context", "assumption", "justification"]

#: Every status a node may have, best first.
STATUSES: Final = ("supported", "undeveloped", "unverified", "stale", "failed")

_RANK: Final = {s: i for i, s in enumerate(STATUSES)}


@dataclass
class Artefact:
    """A file a figure rests on, with its sha256 when the case was built.

    Attributes:
        role: What it is to the figure: ``model:ID``, ``oracle:ID``, ``results``,
            ``registry``, ``goal_model``, ``tests`` …
        path: The file, relative to the project root where it lies inside it.
        sha256: Hex sha256 of its bytes at build time.
        measured_sha256: The sha256 the measurement itself recorded, when it recorded one
            (a results file naming the oracle it measured); the figure is stale when it is
            not ``sha256``.

    """

    role: str
    path: str
    sha256: str
    measured_sha256: str | None = None


@dataclass
class Evidence:
    """One measured figure, the content of a GSN solution.

    Attributes:
        kind: The criteria file's kind (``detector``, ``robustness``, ``result`` …).
        stage: The AMLAS stage.
        figure: The figure in words (with seeds and spread where measured).
        value: The number the criterion is checked on (``None`` for tests).
        criterion: The acceptance criterion in words.
        result: ``pass``, ``fail`` or ``not run``.
        command: The command that re-measures it.
        artefacts: Every file it rests on, hashed.
        model: The registry model the figure is about, if one.
        conditions: The conditions (oracle contexts) it was measured in, if known: live,
            it supports a claim only while the perceived condition is one of them.
        stale: Why it is stale (an artefact changed since it was measured), or ``None``.

    """

    kind: str
    stage: str
    figure: str
    value: float | None
    criterion: str
    result: Literal["pass", "fail", "not run"]
    command: str
    artefacts: list[Artefact] = field(default_factory=list)
    model: str | None = None
    conditions: list[str] | None = None
    stale: str | None = None

    @property
    def status(self) -> str:
        """The solution's own status: stale, supported, failed or unverified."""
        if self.stale is not None:
            return "stale"
        return {"pass": "supported", "fail": "failed"}.get(self.result, "unverified")


@dataclass
class Node:
    """One GSN element.

    Attributes:
        id: Its GSN identifier (``G3``, ``S-G3``, ``Sn-G3-1``, ``C-A1``, ``A-D1`` …).
        type: goal, strategy, solution, context, assumption or justification.
        text: Its statement.
        supported_by: Ids of the goals, strategies and solutions below it.
        in_context_of: Ids of its contexts, assumptions and justifications.
        refinement: A strategy's ``and`` (all sub-goals) or ``or`` (any one suffices).
        source: The goal-model element it comes from (``G3``, ``O1``, ``A4``, ``D1``).
        leaf: A goal that is a leaf of the goal model.
        evidence: A solution's evidence.
        status: Set by :func:`propagate`.

    """

    id: str
    type: NodeType
    text: str
    supported_by: list[str] = field(default_factory=list)
    in_context_of: list[str] = field(default_factory=list)
    refinement: Literal["and", "or"] | None = None
    source: str | None = None
    leaf: bool = False
    evidence: Evidence | None = None
    status: str = ""

    @property
    def undeveloped(self) -> bool:
        """A goal or strategy with nothing supporting it."""
        return self.type in ("goal", "strategy") and not self.supported_by


@dataclass
class Case:
    """An assurance case: the argument's nodes in build order, the root first."""

    name: str
    root: str
    nodes: dict[str, Node]
    built: str = ""
    launch: str = ""
    project_root: str = ""
    build_seconds: float | None = None
    artefacts: list[Artefact] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def __iter__(self) -> Iterator[Node]:
        return iter(self.nodes.values())

    def solutions(self) -> list[Node]:
        """Every solution node."""
        return [n for n in self if n.evidence is not None]

    def leaf_goals(self) -> list[Node]:
        """The goal model's leaf goals, as GSN goals."""
        return [n for n in self if n.type == "goal" and n.leaf]

    def reproducible(self) -> Case:
        """Drop what changes at every build (time, duration, folder), in place; returns self.

        What ``make results`` ships (docs/assurance/): the same files from the same inputs,
        byte for byte. The project root becomes ``.`` (the paths are relative to it).
        """
        self.built = ""
        self.build_seconds = None
        self.project_root = "."
        return self

    def coverage(self) -> dict[str, Any]:
        """The share of the goal model's leaf goals whose evidence supports them."""
        leaves = self.leaf_goals()
        by: dict[str, list[str]] = {s: [] for s in STATUSES}
        for n in leaves:
            by[n.status].append(n.id)
        supported = len(by["supported"])
        return {
            "leaf_goals": len(leaves),
            "supported": supported,
            "share": round(supported / len(leaves), 4) if leaves else None,
            "by_status": {s: ids for s, ids in by.items() if ids},
            "solutions": len(self.solutions()),
            "solutions_by_status": _count(n.status for n in self.solutions()),
            "root": self.nodes[self.root].status,
        }

    def to_json(self) -> dict[str, Any]:
        """``case.json``'s content."""
        return {
            "format": CASE_FORMAT,
            "name": self.name,
            "root": self.root,
            "built": self.built,
            "launch": self.launch,
            "project_root": self.project_root,
            "build_seconds": self.build_seconds,
            "coverage": self.coverage(),
            "artefacts": [asdict(a) for a in self.artefacts],
            "notes": list(self.notes),
            "nodes": [_node_json(n) for n in self],
        }

    @classmethod
    def from_json(cls, data: Any, source: str = "case.json") -> Case:
        """Read ``case.json``'s content back."""
        if not isinstance(data, dict) or data.get("format") != CASE_FORMAT:
            raise ModelFileError(
                "not an assurance case",
                path=source,
                hint="give the folder 'anunnaki assurance build' wrote (its case.json)",
            )
        try:
            nodes = {}
            for item in data["nodes"]:
                raw = dict(item)
                ev = raw.pop("evidence", None)
                evidence = None
                if ev is not None:
                    arts = [Artefact(**a) for a in ev.pop("artefacts", [])]
                    evidence = Evidence(**ev, artefacts=arts)
                raw.pop("undeveloped", None)
                node = Node(**raw, evidence=evidence)
                nodes[node.id] = node
            return cls(
                name=data["name"],
                root=data["root"],
                nodes=nodes,
                built=data.get("built", ""),
                launch=data.get("launch", ""),
                project_root=data.get("project_root", ""),
                build_seconds=data.get("build_seconds"),
                artefacts=[Artefact(**a) for a in data.get("artefacts", [])],
                notes=list(data.get("notes", [])),
            )
        except (KeyError, TypeError) as exc:
            raise ModelFileError(
                f"malformed assurance case ({exc})",
                path=source,
                hint="rebuild it with 'anunnaki assurance build'",
            ) from None


def _node_json(n: Node) -> dict[str, Any]:
    out = asdict(n)
    out["undeveloped"] = n.undeveloped
    if n.evidence is None:
        out.pop("evidence")
    return out


def _count(items: Iterable[str]) -> dict[str, int]:
    out: dict[str, int] = {}
    for s in items:
        out[s] = out.get(s, 0) + 1
    return out


def read_case(folder: str | Path) -> Case:
    """Read the ``case.json`` of a case folder (or the file itself)."""
    path = Path(folder)
    if path.is_dir():
        path = path / "case.json"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ModelFileError(
            "no assurance case here",
            path=path,
            hint="build one first: anunnaki assurance build LAUNCH.yaml --out FOLDER",
        ) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ModelFileError(f"cannot read the case: {exc}", path=path) from None
    return Case.from_json(data, str(path))


def combine(statuses: list[str], refinement: Literal["and", "or"]) -> str:
    """The status of a conjunction (AND) or disjunction (OR) of supporters' statuses."""
    if not statuses:
        return "undeveloped"
    if refinement == "and":
        return max(statuses, key=_RANK.__getitem__)
    if "supported" in statuses:
        return "supported"
    return min(statuses, key=_RANK.__getitem__)


def propagate(case: Case, leaf_status: dict[str, str] | None = None) -> None:
    """Set every node's status from its evidence up (in place).

    Args:
        case: The case.
        leaf_status: Overrides for solutions' statuses by node id (what the live
            evaluation passes); a solution not named keeps its evidence's status.

    """
    done: dict[str, str] = {}
    for node in case:
        if node.type in ("context", "assumption", "justification"):
            node.status = ""
            done[node.id] = ""
    order = _post_order(case)
    for nid in order:
        node = case.nodes[nid]
        if node.evidence is not None:
            status = (leaf_status or {}).get(nid, node.evidence.status)
        elif not node.supported_by:
            status = "undeveloped"
        else:
            below = [done.get(c, "undeveloped") for c in node.supported_by]
            how = node.refinement if node.type == "strategy" and node.refinement else "and"
            status = combine(below, how)
        node.status = status
        done[nid] = status


def _post_order(case: Case) -> list[str]:
    """Supported-by descendants before their parents (the graph is checked acyclic)."""
    seen: set[str] = set()
    out: list[str] = []
    for start in case.nodes:
        if start in seen:
            continue
        stack: list[tuple[str, Iterator[str]]] = [(start, iter(case.nodes[start].supported_by))]
        seen.add(start)
        while stack:
            nid, children = stack[-1]
            nxt = next(children, None)
            if nxt is None:
                stack.pop()
                out.append(nid)
            elif nxt not in seen and nxt in case.nodes:
                seen.add(nxt)
                stack.append((nxt, iter(case.nodes[nxt].supported_by)))
    return out
