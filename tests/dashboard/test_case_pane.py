"""The assurance case pane: the case drawn live, each claim coloured by its status.

The scripted rover (Utu stepped by the test, as test_browser.py does) with a live case on
the same bus (:class:`anunnaki.assurance.CaseMonitor`): G2 ("the rover detects and avoids
obstacles") is degraded while the rover runs normally (G6 within its RELAX tolerance), and
violated once the oracle reports category 1 at t = 25.2 s; the page draws it yellow, then
red, with the reason in its tooltip and, on a click, in the pane's detail line.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from dashboard_helpers import DEADLINE, HERE, ROOT, RoverRun, Web

from anunnaki.assurance import Case, CaseMonitor, LiveCase, build_case, render_svg
from anunnaki.dashboard import Dashboard, DashboardState
from anunnaki.goals import load_goal_model
from anunnaki.tactics import TacticSet

WAIT = int(DEADLINE * 1000)


def rover_case(tmp: Path) -> Case:
    """The scripted rover's case, its obstacle and G2's leaves developed by a passing figure."""
    (tmp / "figure.json").write_text('{"value": 0.9}')
    item = "[{kind: result, file: figure.json, path: value, text: figure, at_least: 0.5}]"
    goals = ("O1", "G5", "G6", "G7", "G8", "G11")
    (tmp / "assurance.yaml").write_text(
        f"anunnaki: assurance/1\ngoal_model: {ROOT / 'examples/rover/goals.yaml'}\n"
        "evidence:\n" + "".join(f"  {g}: {item}\n" for g in goals)
    )
    return build_case(ROOT / "examples/rover/utu.yaml", criteria=tmp / "assurance.yaml", root=tmp)


@pytest.fixture(scope="module")
def case(tmp_path_factory: pytest.TempPathFactory) -> Case:
    return rover_case(tmp_path_factory.mktemp("case"))


def test_the_state_keeps_statuses_as_text_and_the_drawing_local(case: Case) -> None:
    rover = ROOT / "examples/rover"
    model = load_goal_model(rover / "goals.yaml", rover / "binding.yaml")
    state = DashboardState(model, TacticSet(tactics=[]))
    assert state.snapshot()["assurance"] is None and not state.snapshot()["assurance_drawing"]
    v = state.version
    state.set_case_drawing(render_svg(case))
    state.take_assurance(
        {"case": "rover", "root": "G1", "seq": 3, "nodes": {"G2": ["violated", "why"]}}
    )
    delta = state.delta(v, decisions_after=0, timeline_after=0)
    assert delta["assurance"]["nodes"] == {"G2": ["violated", "why"]}
    assert delta["assurance_drawing"] is True
    # an older state (a query answered after a newer publication) is not taken
    state.take_assurance(
        {"case": "rover", "root": "G1", "seq": 2, "nodes": {"G2": ["supported", ""]}}
    )
    assert state.snapshot()["assurance"]["nodes"]["G2"] == ["violated", "why"]
    # malformed entries are dropped, long texts cut
    state.take_assurance(
        {"case": "rover", "seq": 4, "nodes": {"G2": "x", "G3": ["failed", "r" * 900]}}
    )
    nodes = state.snapshot()["assurance"]["nodes"]
    assert list(nodes) == ["G3"] and len(nodes["G3"][1]) == 500
    state.take_assurance({"nodes": 3})  # not a state at all: ignored
    assert state.snapshot()["assurance"]["seq"] == 4


@pytest.fixture(scope="module")
def live(case: Case, chromium: Any) -> Iterator[tuple[RoverRun, Dashboard, Any]]:
    run = RoverRun(HERE / "data" / "rover-approval.yaml")
    monitor = CaseMonitor(LiveCase(case), run.bus, svg=render_svg(case))
    dash = Dashboard(run.model, run.tactics, bus=run.bus, clock="sim", port=0, name="rover")
    dash.state.set_case_drawing(render_svg(case))
    dash.start()
    page = chromium.new_page()
    try:
        run.run_to(22.0)
        page.goto(dash.url)
        yield run, dash, page
    finally:
        page.close()
        dash.close()
        monitor.close()
        run.close()


def test_the_pane_draws_the_case_and_turns_a_violated_claim_red(
    live: tuple[RoverRun, Dashboard, Any],
) -> None:
    run, dash, page = live
    assert Web(dash.url).get("/api/assurance.svg").text.startswith("<svg")
    g2 = "#case-drawing g#gsn-G2"
    # G6 is RELAX-ed and satisfied within its tolerance (4.8 Hz for 5 Hz): G2 is degraded
    page.wait_for_selector(f"{g2}[data-status=degraded]", timeout=WAIT)
    assert page.locator("#pane-case").is_visible()
    fill = page.eval_on_selector(f"{g2} > rect", "e => getComputedStyle(e).fill")
    assert fill == "rgb(255, 243, 196)"  # yellow
    g7 = page.eval_on_selector("#case-drawing g#gsn-G7 > rect", "e => getComputedStyle(e).fill")
    assert g7 == "rgb(217, 242, 217)"  # green: supported
    assert "G1" in page.locator("#case-summary").text_content()
    run.run_to(25.2)  # category 1: G3 unsatisfied, and with it G2
    page.wait_for_selector(f"{g2}[data-status=violated]", timeout=WAIT)
    fill = page.eval_on_selector(f"{g2} > rect", "e => getComputedStyle(e).fill")
    assert fill == "rgb(248, 208, 208)"  # red
    title = page.locator(f"{g2} > title").text_content()
    assert title.startswith("G2 [violated]: the goal model finds it unsatisfied")
    page.click(g2)
    detail = page.locator("#case-detail [data-node=G2]")
    detail.wait_for(timeout=WAIT)
    assert "violated — the goal model finds it unsatisfied" in detail.text_content()
    assert "detects and avoids obstacles" in detail.text_content()
    # the tooltip and detail are text: nothing from the bus is markup
    assert page.locator("#case-drawing script").count() == 0


def test_a_page_opened_later_gets_the_statuses_so_far(
    live: tuple[RoverRun, Dashboard, Any], chromium: Any
) -> None:
    _, dash, _ = live
    page = chromium.new_page()
    try:
        page.goto(dash.url)
        page.wait_for_selector("#case-drawing g#gsn-G2[data-status=violated]", timeout=WAIT)
    finally:
        page.close()
