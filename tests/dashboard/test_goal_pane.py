"""The goal-model pane draws the paper's KAOS picture, for both examples, in Chromium.

For the rover with its model manager (``examples/rover/goals-lm.yaml``) and the UAV
(``examples/uav/goals.yaml``): one white hexagon per agent assignment of the goal model, linked
to its goal or obstacle; each obstacle linked to the goals it obstructs; each resolution goal
linked to the obstacle it resolves and drawn under it (G9, O1's resolution, no longer floats at
the top), no two nodes overlapping and the picture scaled to the pane no smaller than 3/4.
Agents, obstacles and their links follow the analysis live, as the goals do. The timeline's
labels lie inside its plot. The analyses are handed to the dashboard's state directly: the
pane, not Utu, is under test (test_browser.py runs the whole loop).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import pytest
from dashboard_helpers import ARTIFACTS, DEADLINE, ROOT

from anunnaki.dashboard import Dashboard
from anunnaki.goals import GoalModel, load_binding, load_goal_model, parse_goal_model
from anunnaki.tactics import TacticSet, load_tactics

pytestmark = pytest.mark.slow

WAIT = int(DEADLINE * 1000)
EXAMPLES = {
    "rover": ("examples/rover/goals-lm.yaml", "binding-lm.yaml", "tactics-lm.yaml"),
    "uav": ("examples/uav/goals.yaml", "binding.yaml", "tactics.yaml"),
}
#: Bounding boxes of the drawn nodes, in the SVG's own units: kind, id(s) and x, y, w, h.
BOXES = """() => Array.from(document.querySelectorAll('#goal-svg .nodes > g')).map((g) => {
  const b = g.getBBox();
  return {agent: g.dataset.agent || null, of: g.dataset.for || null, node: g.dataset.node || null,
          cls: g.getAttribute('class'), x: b.x, y: b.y, w: b.width, h: b.height};
})"""
#: The links: their class, ends (data attributes) and the path's first and last points.
LINKS = """() => Array.from(document.querySelectorAll('#goal-svg .edges path')).map((p) => {
  const n = p.getTotalLength(), a = p.getPointAtLength(0), b = p.getPointAtLength(n);
  return {cls: p.getAttribute('class'), from: p.dataset.from, to: p.dataset.to,
          agent: p.dataset.agent || null, of: p.dataset.for || null,
          marker: p.getAttribute('marker-end'), ax: a.x, ay: a.y, bx: b.x, by: b.y};
})"""


@dataclass
class Pane:
    """One example's goal model, its dashboard and a page on it."""

    name: str
    model: GoalModel
    dash: Dashboard
    page: Any

    def boxes(self) -> list[dict[str, Any]]:
        found: list[dict[str, Any]] = self.page.evaluate(BOXES)
        return found

    def links(self) -> list[dict[str, Any]]:
        found: list[dict[str, Any]] = self.page.evaluate(LINKS)
        return found

    def box(self, node: str) -> dict[str, Any]:
        return next(b for b in self.boxes() if b["node"] == node)

    def analyse(self, t: float, statuses: dict[str, str]) -> None:
        """Hand the dashboard an analysis (as Utu publishes it) with these statuses."""
        nodes = {
            nid: [1.0 if s == "satisfied" else 0.0 if s == "unsatisfied" else None, s]
            for nid, s in statuses.items()
        }
        self.dash.state.take_analysis({"t": t, "nodes": nodes, "violated": []})


def assignments(model: GoalModel) -> set[tuple[str, str]]:
    """(agent, goal or obstacle) for every agent assignment of the goal model."""
    pairs = {(a, g.id) for g in model.goals.values() for a in g.agents}
    return pairs | {(a, o.id) for o in model.obstacles.values() for a in o.agents}


def touches(x: float, y: float, box: dict[str, Any], slack: float = 0.6) -> bool:
    """(x, y) lies on the box's outline or inside it."""
    return (
        box["x"] - slack <= x <= box["x"] + box["w"] + slack
        and box["y"] - slack <= y <= box["y"] + box["h"] + slack
    )


@pytest.fixture(scope="module", params=sorted(EXAMPLES))
def pane(request: pytest.FixtureRequest, chromium: Any) -> Iterator[Pane]:
    goals, binding, tactics = EXAMPLES[request.param]
    path = ROOT / goals
    model = load_goal_model(path, binding=load_binding(path.parent / binding))
    dash = Dashboard(
        model, load_tactics(path.parent / tactics), clock="sim", port=0, name=request.param
    )
    dash.start()
    page = chromium.new_page()
    try:
        page.goto(dash.url)
        page.wait_for_selector(f"#goal-svg [data-node={model.root}]", timeout=WAIT)
        yield Pane(request.param, model, dash, page)
    finally:
        page.close()
        dash.close()


def test_every_agent_assignment_is_a_hexagon_linked_to_its_goal(pane: Pane) -> None:
    expected = assignments(pane.model)
    assert expected  # both examples assign agents
    hexagons = [b for b in pane.boxes() if b["agent"]]
    assert {(b["agent"], b["of"]) for b in hexagons} == expected
    assert len(hexagons) == len(expected)  # one hexagon per assignment
    points = pane.page.locator("#goal-svg g.agent polygon").evaluate_all(
        "els => els.map(e => e.points.numberOfItems)"
    )
    assert points == [6] * len(expected)  # hexagons
    links = [lk for lk in pane.links() if "responsibility" in lk["cls"].split()]
    assert {(lk["agent"], lk["of"]) for lk in links} == expected
    for lk in links:  # from the hexagon's outline to its goal's
        hexagon = next(b for b in hexagons if (b["agent"], b["of"]) == (lk["agent"], lk["of"]))
        assert touches(lk["ax"], lk["ay"], hexagon), lk
        assert touches(lk["bx"], lk["by"], pane.box(lk["of"])), lk
        assert hexagon["y"] > pane.box(lk["of"])["y"]  # under it, as in the paper


def test_obstacles_and_resolution_goals_are_linked(pane: Pane) -> None:
    links = pane.links()
    obstructs = {(lk["from"], lk["to"]) for lk in links if "obstruct" in lk["cls"].split()}
    resolves = [lk for lk in links if "resolution" in lk["cls"].split()]
    model = pane.model
    assert obstructs == {(o.id, g) for o in model.obstacles.values() for g in o.obstructs}
    assert {(lk["from"], lk["to"]) for lk in resolves} == {
        (g, o.id) for o in model.obstacles.values() for g in o.resolutions
    }
    for lk in links:
        if lk["from"] and not lk["agent"]:
            assert touches(lk["ax"], lk["ay"], pane.box(lk["from"])), lk
            assert touches(lk["bx"], lk["by"], pane.box(lk["to"])), lk
    for lk in resolves + [lk for lk in links if "obstruct" in lk["cls"].split()]:
        assert lk["marker"] and lk["marker"].startswith("url(#arrow-"), lk  # arrows
    # O1's resolution G9 refines no goal: it hangs under O1, with its link, in both examples.
    g9 = next(lk for lk in resolves if (lk["from"], lk["to"]) == ("G9", "O1"))
    assert touches(g9["bx"], g9["by"], pane.box("O1"))
    assert pane.box("G9")["y"] > pane.box("O1")["y"] + pane.box("O1")["h"]
    # No node floats: each goal, obstacle and agent has a link.
    ends = {lk["from"] for lk in links} | {lk["to"] for lk in links}
    for b in pane.boxes():
        assert (b["agent"] or b["node"]) in ends, b


def test_nodes_do_not_overlap_and_the_picture_fits_the_pane(pane: Pane) -> None:
    boxes = pane.boxes()
    for i, a in enumerate(boxes):
        for b in boxes[i + 1 :]:
            apart = (
                a["x"] + a["w"] <= b["x"]
                or b["x"] + b["w"] <= a["x"]
                or a["y"] + a["h"] <= b["y"]
                or b["y"] + b["h"] <= a["y"]
            )
            assert apart, (a, b)
    size = pane.page.evaluate(
        """() => { const s = document.getElementById('goal-svg');
        const r = s.getBoundingClientRect();
        return {natural: Number(s.getAttribute('width')), shown: r.width,
                pane: document.getElementById('goal-tree').clientWidth}; }"""
    )
    assert size["shown"] <= size["pane"] + 0.5  # no horizontal scrolling
    assert size["shown"] / size["natural"] >= 0.75, size  # still readable


#: Each hexagon and each responsibility link: the agent, what it hangs under, its class.
LOOKS = """() => Array.from(document.querySelectorAll(
  '#goal-svg g.agent, #goal-svg path.responsibility')).map(
  (e) => [e.tagName, e.dataset.agent, e.dataset.for, e.getAttribute('class')])"""


def expect_looks(pane: Pane, statuses: dict[str, str]) -> None:
    """Wait until every hexagon and responsibility link shows how its goal stands.

    As the goal's status; for an obstacle, the other way round (one that holds fails).
    """
    flip = {"satisfied": "unsatisfied", "unsatisfied": "satisfied", "unknown": "unknown"}
    health = {n: flip[s] if n in pane.model.obstacles else s for n, s in statuses.items()}
    want = sorted(
        [tag, a, of, f"{kind} {health[of]}"]
        for a, of in assignments(pane.model)
        for tag, kind in (("g", "agent"), ("path", "edge responsibility"))
    )
    pane.page.wait_for_function(
        f"(want) => JSON.stringify(({LOOKS})().sort()) === JSON.stringify(want)",
        arg=want,
        timeout=WAIT,
    )


def test_agents_obstacles_and_links_follow_the_analysis(pane: Pane) -> None:
    model, page = pane.model, pane.page
    goals = {nid: "satisfied" for nid in model.goals}
    absent = {oid: "unsatisfied" for oid in model.obstacles}  # no obstacle holds
    # O1 holds; its resolution G9 (A4 and A6 are responsible for it) is not satisfied yet.
    pane.analyse(10.0, {**goals, **absent, "G9": "unsatisfied", "O1": "satisfied"})
    page.wait_for_selector(
        "#goal-svg path.obstruct.holds[data-from=O1]", state="attached", timeout=WAIT
    )
    page.wait_for_selector("#goal-svg [data-node=O1].satisfied", timeout=WAIT)
    # Each hexagon (and link) as its goal stands; an obstacle that holds counts as failing.
    expect_looks(pane, {**goals, **absent, "G9": "unsatisfied", "O1": "satisfied"})
    assert page.locator("#goal-svg g.agent.unsatisfied[data-for=G9]").count() == 2  # A4, A6
    assert page.locator("#goal-svg path.resolution.resolves[data-from=G9]").count() == 0
    # The robust model is in: G9 holds and resolves O1; its agents are green again.
    pane.analyse(11.0, {**goals, **absent, "O1": "satisfied"})
    page.wait_for_selector(
        "#goal-svg path.resolution.resolves[data-from=G9][data-to=O1]",
        state="attached",
        timeout=WAIT,
    )
    expect_looks(pane, {**goals, **absent, "O1": "satisfied"})
    # The condition has passed: O1 is absent, its obstruction link no longer highlighted.
    pane.analyse(12.0, {**goals, **absent})
    page.wait_for_selector("#goal-svg [data-node=O1].unsatisfied", timeout=WAIT)
    page.wait_for_selector(
        "#goal-svg path.obstruct:not(.holds)[data-from=O1]", state="attached", timeout=WAIT
    )
    expect_looks(pane, {**goals, **absent})
    # Unknown values make the agents' outlines grey.
    unknown = {nid: "unknown" for nid in [*model.goals, *model.obstacles]}
    pane.analyse(13.0, unknown)
    expect_looks(pane, unknown)
    pane.analyse(14.0, {**goals, **absent, "G9": "unsatisfied", "O1": "satisfied"})
    page.wait_for_selector("#goal-svg g.agent.unsatisfied[data-for=G9]", timeout=WAIT)
    ARTIFACTS.mkdir(exist_ok=True)
    page.locator("#pane-goals").screenshot(path=str(ARTIFACTS / f"goal-pane-{pane.name}.png"))


def test_timeline_labels_lie_inside_the_plot(pane: Pane) -> None:
    page = pane.page
    root = pane.model.root
    # A long run (wide labels on the time axis) with a tactic started just before its end.
    pane.analyse(1234.5, {root: "unsatisfied"})
    pane.analyse(1298.75, {root: "satisfied"})
    pane.dash.state.take_decisions(
        [{"id": 1, "t": 1298.5, "kind": "started", "tactic": "swap-to-robust-model", "data": {}}]
    )
    page.wait_for_selector("#timeline g.marker[data-kind=started] text", timeout=WAIT)
    page.wait_for_function(
        "() => Array.from(document.querySelectorAll('#timeline text.tick'))"
        ".some((e) => e.textContent === '1298.75')",
        timeout=WAIT,
    )
    found = page.evaluate(
        """() => { const s = document.getElementById('timeline').getBoundingClientRect();
        return {plot: [s.left, s.top, s.right, s.bottom],
                texts: Array.from(document.querySelectorAll('#timeline text')).map((t) => {
                  const r = t.getBoundingClientRect();
                  return [t.textContent, r.left, r.top, r.right, r.bottom]; })}; }"""
    )
    left, top, right, bottom = found["plot"]
    assert any(t[0] == "1298.75" for t in found["texts"])  # the right-hand axis label
    assert any(t[0] == "swap-to-robust-model" for t in found["texts"])
    for text, x0, y0, x1, y1 in found["texts"]:
        assert left <= x0 and x1 <= right + 0.5 and top <= y0 and y1 <= bottom + 0.5, text


def test_a_model_too_wide_to_fit_scrolls_at_three_quarters(chromium: Any) -> None:
    leaves = [f"G{i}" for i in range(2, 42)]  # 40 leaves: about 3000 px wide at full size
    text = "\n".join(
        [
            "anunnaki: goal-model/1",
            "name: wide",
            "root: G1",
            "agents: [{id: A1, topics: [{topic: /wide/status, attributes: [v]}]}]",
            "goals:",
            f"  - {{id: G1, refinement: and, children: [{', '.join(leaves)}]}}",
            *(f"  - {{id: {g}, utility: A1.v >= 0, agents: [A1]}}" for g in leaves),
        ]
    )
    dash = Dashboard(
        parse_goal_model(text), TacticSet(name="wide", tactics=[]), clock="sim", port=0
    )
    dash.start()
    page = chromium.new_page()
    try:
        page.goto(dash.url)
        page.wait_for_selector("#goal-svg [data-node=G41]", timeout=WAIT)
        size = page.evaluate(
            """() => { const s = document.getElementById('goal-svg');
            const tree = document.getElementById('goal-tree');
            return {natural: Number(s.getAttribute('width')),
                    shown: s.getBoundingClientRect().width,
                    pane: tree.clientWidth, scroll: tree.scrollWidth}; }"""
        )
    finally:
        page.close()
        dash.close()
    assert size["natural"] * 0.75 > size["pane"]  # it cannot fit at a readable scale …
    assert abs(size["shown"] - round(size["natural"] * 0.75)) <= 1, size  # … so it stops there
    assert size["scroll"] > size["pane"]  # and the pane scrolls
