"""A case written out: ``case.json``, GSN YAML for gsn2x, an SVG drawing, an HTML report.

* ``case.gsn.yaml`` — the layout the gsn2x tool reads: one mapping per element id with
  ``text``, ``supportedBy``, ``inContextOf``, ``undeveloped: true`` and the status as its
  ``classes`` (docs/assurance.md, "The GSN export");
* ``case.svg`` — the argument drawn in layers (goals as rectangles, strategies as
  parallelograms, solutions as circles, contexts as rounded rectangles, assumptions and
  justifications as ovals marked A and J; undeveloped goals with a hollow diamond), each
  element coloured by its status, its full text in a tooltip, its group ``id="gsn-ID"``;
* ``case.html`` — one self-contained page (inline CSS and SVG, no script, opens offline):
  the summary, the drawing, every claim with its status, every evidence with its figure,
  criterion, result, command and the sha256 of each artefact.
"""

from __future__ import annotations

import html
import json
import textwrap
from pathlib import Path
from typing import Any, Final

import yaml

from anunnaki.assurance._case import STATUSES, Case, Node

__all__ = ["gsn_document", "gsn_yaml", "render_html", "render_svg", "write_case"]

_COLOURS: Final = {
    "supported": ("#d8f3dc", "#2d6a4f"),
    "failed": ("#ffd6d6", "#b00020"),
    "stale": ("#ffe5c2", "#b35c00"),
    "unverified": ("#e6ebf5", "#44546a"),
    "undeveloped": ("#f4f4f4", "#777777"),
    "": ("#ffffff", "#555555"),
}


def gsn_document(case: Case) -> dict[str, dict[str, Any]]:
    """The case in gsn2x's YAML layout, as a mapping (ids in build order)."""
    doc: dict[str, dict[str, Any]] = {}
    for n in case:
        el: dict[str, Any] = {"text": n.text}
        if n.supported_by:
            el["supportedBy"] = list(n.supported_by)
        if n.in_context_of:
            el["inContextOf"] = list(n.in_context_of)
        if n.undeveloped:
            el["undeveloped"] = True
        if n.status:
            el["classes"] = [n.status]
        doc[n.id] = el
    return doc


def gsn_yaml(case: Case) -> str:
    """``case.gsn.yaml``'s text."""
    built = f" {case.built}" if case.built else ""
    head = (
        f"# The assurance case of {case.name} ({case.launch}), built{built} by "
        "'anunnaki assurance build'.\n# Layout: gsn2x (https://github.com/jonasthewolf/gsn2x); "
        "classes: each element's status. Mapping: docs/assurance.md\n"
    )
    body = yaml.safe_dump(gsn_document(case), sort_keys=False, allow_unicode=True, width=100)
    return head + body


# -- the drawing ----------------------------------------------------------------------------
_W, _H, _R = 230, 96, 56
_GAP_X, _GAP_Y = 26, 70
_CHARS = 34


def _layers(case: Case) -> dict[str, int]:
    """Longest-path depth from the root along SupportedBy (every edge points down)."""
    depth = {case.root: 0}
    order = _dfs(case)
    changed = True  # relax until stable: a DAG of a few hundred nodes
    while changed:
        changed = False
        for nid in order:
            d = depth.get(nid)
            if d is None:
                continue
            for c in case.nodes[nid].supported_by:
                if depth.get(c, -1) < d + 1:
                    depth[c] = d + 1
                    changed = True
    return depth


def _dfs(case: Case) -> list[str]:
    out: list[str] = []
    seen: set[str] = set()
    stack = [case.root]
    while stack:
        nid = stack.pop()
        if nid in seen or nid not in case.nodes:
            continue
        seen.add(nid)
        out.append(nid)
        stack.extend(reversed(case.nodes[nid].supported_by))
    return out


def _owners(case: Case) -> dict[str, str]:
    """Each context, assumption and justification → the first element (depth-first) using it."""
    owner: dict[str, str] = {}
    for nid in _dfs(case):
        for c in case.nodes[nid].in_context_of:
            owner.setdefault(c, nid)
    return owner


def _place(case: Case) -> dict[str, tuple[float, float]]:
    depth = _layers(case)
    order = {nid: i for i, nid in enumerate(_dfs(case))}
    owner = _owners(case)
    layers: dict[int, list[str]] = {}
    for nid, d in depth.items():
        layers.setdefault(d, []).append(nid)
    pos: dict[str, tuple[float, float]] = {}
    parents: dict[str, list[str]] = {}
    for nid in order:
        for c in case.nodes[nid].supported_by:
            parents.setdefault(c, []).append(nid)
    for d in sorted(layers):
        row = layers[d]

        def want(nid: str) -> float:
            ps = [pos[p][0] for p in parents.get(nid, []) if p in pos]
            return sum(ps) / len(ps) if ps else 0.0

        row.sort(key=lambda n: (want(n), order[n]))
        items: list[str] = []
        for nid in row:
            items.append(nid)
            items += [c for c in case.nodes[nid].in_context_of if owner.get(c) == nid]
        y = d * (_H + _GAP_Y) + _H / 2 + 20
        x_prev = -1e9
        for nid in items:
            target = want(nid) if nid in depth else pos[owner[nid]][0] + _W + _GAP_X
            x = max(target, x_prev + _W + _GAP_X)
            pos[nid] = (x, y)
            x_prev = x
    if pos:
        shift = _W / 2 + 20 - min(x for x, _ in pos.values())
        pos = {k: (x + shift, y) for k, (x, y) in pos.items()}
    return pos


def _lines(n: Node) -> list[str]:
    words = n.text if n.type != "solution" else _short_solution(n)
    chars = _CHARS if n.type != "solution" else 17
    wrapped = textwrap.wrap(words, chars) or [""]
    limit = 5 if n.type != "solution" else 4
    if len(wrapped) > limit:
        wrapped = [*wrapped[: limit - 1], wrapped[limit - 1][: chars - 1] + "…"]
    return wrapped


def _short_solution(n: Node) -> str:
    ev = n.evidence
    if ev is None:
        return n.text
    what = ev.model or ev.kind
    return f"{ev.stage}: {what} {ev.result}"


def render_svg(case: Case) -> str:
    """The argument drawn as SVG (self-contained; no fonts or scripts fetched)."""
    pos = _place(case)
    owner = _owners(case)
    width = max((x for x, _ in pos.values()), default=0) + _W / 2 + 20
    height = max((y for _, y in pos.values()), default=0) + _H / 2 + 30
    out = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0f}" height="{height:.0f}" '
        f'viewBox="0 0 {width:.0f} {height:.0f}" font-family="sans-serif" font-size="11">',
        "<defs>"
        '<marker id="solid" viewBox="0 0 10 10" refX="10" refY="5" markerWidth="8" '
        'markerHeight="8" orient="auto"><path d="M0,0 L10,5 L0,10 z" fill="#333"/></marker>'
        '<marker id="hollow" viewBox="0 0 10 10" refX="10" refY="5" markerWidth="8" '
        'markerHeight="8" orient="auto"><path d="M0,0 L10,5 L0,10 z" fill="#fff" '
        'stroke="#333"/></marker></defs>',
    ]
    for n in case:
        if n.id not in pos:
            continue
        x, y = pos[n.id]
        for c in n.supported_by:
            if c in pos:
                cx, cy = pos[c]
                out.append(
                    f'<line x1="{x:.0f}" y1="{y + _half(n):.0f}" x2="{cx:.0f}" '
                    f'y2="{cy - _half(case.nodes[c]):.0f}" stroke="#333" marker-end="url(#solid)"/>'
                )
        for c in n.in_context_of:
            if c in pos and owner.get(c) == n.id:  # a shared context: drawn by its first owner
                cx, cy = pos[c]
                out.append(
                    f'<line x1="{x:.0f}" y1="{y:.0f}" x2="{cx - _W / 2:.0f}" y2="{cy:.0f}" '
                    'stroke="#888" stroke-dasharray="4 3" marker-end="url(#hollow)"/>'
                )
    for n in case:
        if n.id in pos:
            out.append(_shape(n, *pos[n.id]))
    out.append("</svg>")
    return "\n".join(out)


def _half(n: Node) -> float:
    return _R if n.type == "solution" else _H / 2


def _shape(n: Node, x: float, y: float) -> str:
    fill, stroke = _COLOURS.get(n.status, _COLOURS[""])
    e = html.escape
    title = f"{n.id} [{n.status or n.type}]: {n.text}"
    if n.in_context_of:
        title += f" (in context of {', '.join(n.in_context_of)})"
    if n.evidence is not None and n.evidence.stale:
        title += f" STALE: {n.evidence.stale}"
    parts = [f'<g id="gsn-{e(n.id)}" class="gsn {n.type} {n.status}"><title>{e(title)}</title>']
    w, h = _W, _H
    if n.type == "goal":
        parts.append(
            f'<rect x="{x - w / 2:.0f}" y="{y - h / 2:.0f}" width="{w}" height="{h}" '
            f'fill="{fill}" stroke="{stroke}" stroke-width="1.5"/>'
        )
        if n.undeveloped:
            yb = y + h / 2
            parts.append(
                f'<path d="M{x:.0f},{yb:.0f} l8,8 l-8,8 l-8,-8 z" fill="#fff" stroke="{stroke}"/>'
            )
    elif n.type == "strategy":
        k = 14
        parts.append(
            f'<path d="M{x - w / 2 + k:.0f},{y - h / 2:.0f} h{w - k} l{-k},{h} h{-(w - k)} z" '
            f'fill="{fill}" stroke="{stroke}" stroke-width="1.5"/>'
        )
    elif n.type == "solution":
        parts.append(
            f'<circle cx="{x:.0f}" cy="{y:.0f}" r="{_R}" fill="{fill}" stroke="{stroke}" '
            'stroke-width="1.5"/>'
        )
    elif n.type == "context":
        parts.append(
            f'<rect x="{x - w / 2:.0f}" y="{y - h / 2:.0f}" width="{w}" height="{h}" '
            f'rx="18" fill="#fff" stroke="{stroke}"/>'
        )
    else:
        parts.append(
            f'<ellipse cx="{x:.0f}" cy="{y:.0f}" rx="{w / 2:.0f}" ry="{h / 2:.0f}" '
            f'fill="#fff" stroke="{stroke}"/>'
        )
        parts.append(
            f'<text x="{x + w / 2 - 8:.0f}" y="{y + h / 2:.0f}" font-weight="bold">'
            f"{'A' if n.type == 'assumption' else 'J'}</text>"
        )
    lines = _lines(n)
    width = 2 * _R - 14 if n.type == "solution" else w - 14
    top = y - (len(lines) + 1) * 13 / 2 + 10
    parts.append(
        f'<text x="{x:.0f}" y="{top:.0f}" text-anchor="middle" font-weight="bold">{e(n.id)}</text>'
    )
    for i, line in enumerate(lines):
        parts.append(
            f'<text x="{x:.0f}" y="{top + 13 * (i + 1):.0f}" text-anchor="middle" '
            f'textLength="{min(width, 6.2 * len(line)):.0f}" '
            f'lengthAdjust="spacingAndGlyphs">{e(line)}</text>'
        )
    parts.append("</g>")
    return "".join(parts)


# -- the report -----------------------------------------------------------------------------
_CSS: Final = """
body{font-family:sans-serif;margin:1.5em;color:#222;max-width:1400px}
h1{font-size:1.4em} h2{font-size:1.15em;margin-top:1.6em}
table{border-collapse:collapse;width:100%;font-size:.9em}
td,th{border:1px solid #ccc;padding:.35em .5em;vertical-align:top;text-align:left}
code{font-size:.85em;word-break:break-all}
.badge{display:inline-block;padding:.1em .5em;border-radius:.7em;font-size:.85em;font-weight:bold}
.drawing{overflow:auto;border:1px solid #ddd;max-height:80vh}
.sha{font-family:monospace;font-size:.8em;word-break:break-all}
.stale-why{color:#b35c00}
"""


def _counts(by: dict[str, int]) -> str:
    return ", ".join(f"{by[s]} {s}" for s in STATUSES if s in by) or "none"


def _badge(status: str) -> str:
    fill, stroke = _COLOURS.get(status, _COLOURS[""])
    return (
        f'<span class="badge" style="background:{fill};color:{stroke};border:1px solid '
        f'{stroke}">{html.escape(status or "—")}</span>'
    )


def render_html(case: Case, svg: str | None = None) -> str:
    """The self-contained report."""
    e = html.escape
    cov = case.coverage()
    svg = svg if svg is not None else render_svg(case)
    rows = []
    for nid in _dfs(case):
        n = case.nodes[nid]
        if n.type == "solution":
            continue
        ctx = ", ".join(n.in_context_of)
        below = ", ".join(f'<a href="#{e(c)}">{e(c)}</a>' for c in n.supported_by)
        rows.append(
            f'<tr id="{e(n.id)}"><td><b>{e(n.id)}</b><br>{e(n.type)}'
            f"{' (leaf)' if n.leaf else ''}</td><td>{_badge(n.status)}</td><td>{e(n.text)}</td>"
            f"<td>{below or '<em>undeveloped</em>'}</td><td>{e(ctx)}</td></tr>"
        )
    ev_rows = []
    parents: dict[str, list[str]] = {}
    for n in case:
        for c in n.supported_by:
            parents.setdefault(c, []).append(n.id)
    for n in case.solutions():
        ev = n.evidence
        assert ev is not None
        arts = "<br>".join(
            f"{e(a.role)}: <code>{e(a.path)}</code><br><span class=sha>{e(a.sha256)}</span>"
            + (
                f'<br><span class="stale-why">measured on {e(a.measured_sha256)}</span>'
                if a.measured_sha256 and a.measured_sha256 != a.sha256
                else ""
            )
            for a in ev.artefacts
        )
        stale = f'<div class="stale-why">stale: {e(ev.stale)}</div>' if ev.stale else ""
        conds = f"<br>conditions: {e(', '.join(ev.conditions))}" if ev.conditions else ""
        for_ = ", ".join(f'<a href="#{e(p)}">{e(p)}</a>' for p in parents.get(n.id, []))
        ev_rows.append(
            f'<tr id="{e(n.id)}"><td><b>{e(n.id)}</b><br>for {for_}</td>'
            f"<td>{_badge(n.status)}</td><td>{e(ev.stage)}</td><td>{e(ev.figure)}{conds}{stale}"
            f"</td><td>{e(ev.criterion)}</td><td>{e(ev.result)}</td>"
            f"<td><code>{e(ev.command)}</code></td><td>{arts}</td></tr>"
        )
    by = cov.get("by_status", {})
    summary = ", ".join(f"{s} {len(by[s])} ({', '.join(by[s])})" for s in STATUSES if s in by)
    share = cov["share"]
    legend = " ".join(_badge(s) for s in STATUSES)
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>Assurance case: {e(case.name)}</title><style>{_CSS}</style></head>
<body>
<h1>Assurance case: {e(case.name)}</h1>
<p>Launch <code>{e(case.launch)}</code>; built{_when(case)} by
<code>anunnaki assurance build</code>. Top-level claim <b>{e(case.root)}</b>:
{_badge(case.nodes[case.root].status)}</p>
<p><b>Evidence coverage</b>: {cov["supported"]} of {cov["leaf_goals"]} leaf goals supported
({"—" if share is None else f"{100 * share:.0f} %"}): {e(summary)}.
{cov["solutions"]} evidence items: {e(_counts(cov["solutions_by_status"]))}.</p>
{"".join(f"<p><b>Note</b>: {e(note)}</p>" for note in case.notes)}
<p>Statuses: {legend}. A claim is <b>supported</b> only by evidence that meets its criterion
and whose artefacts are unchanged since it was measured; an <b>undeveloped</b> claim has no
evidence, a <b>stale</b> one rests on an artefact that changed, an <b>unverified</b> one on
tests not run, a <b>failed</b> one on evidence that misses its criterion.</p>
<h2>The argument (GSN)</h2>
<div class="drawing">{svg}</div>
<h2>Claims, strategies and their context</h2>
<table><tr><th>id</th><th>status</th><th>statement</th><th>supported by</th>
<th>in context of</th></tr>
{"".join(rows)}
</table>
<h2>Evidence</h2>
<table><tr><th>id</th><th>status</th><th>AMLAS stage</th><th>figure</th><th>criterion</th>
<th>result</th><th>re-measure with</th><th>artefacts (sha256 at build)</th></tr>
{"".join(ev_rows)}
</table>
<h2>Artefacts of the launch</h2>
<table><tr><th>role</th><th>file</th><th>sha256</th></tr>
{"".join(_artefact_row(a.role, a.path, a.sha256) for a in case.artefacts)}
</table>
</body></html>
"""


def _when(case: Case) -> str:
    """`` 2026-12-02T19:00:00Z in 0.3 s`` ('' for a case made reproducible: no time in it)."""
    out = f" {html.escape(case.built)}" if case.built else ""
    return out + (f" in {case.build_seconds} s" if case.build_seconds is not None else "")


def _artefact_row(role: str, path: str, sha: str) -> str:
    e = html.escape
    return f"<tr><td>{e(role)}</td><td><code>{e(path)}</code></td><td class=sha>{e(sha)}</td></tr>"


def write_case(case: Case, out: str | Path) -> dict[str, Path]:
    """Write ``case.json``, ``case.gsn.yaml``, ``case.svg`` and ``case.html`` into ``out``."""
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    svg = render_svg(case)
    files = {
        "json": folder / "case.json",
        "gsn": folder / "case.gsn.yaml",
        "svg": folder / "case.svg",
        "html": folder / "case.html",
    }
    files["json"].write_text(json.dumps(case.to_json(), indent=1) + "\n", encoding="utf-8")
    files["gsn"].write_text(gsn_yaml(case), encoding="utf-8")
    files["svg"].write_text(svg + "\n", encoding="utf-8")
    files["html"].write_text(render_html(case, svg), encoding="utf-8")
    return files
