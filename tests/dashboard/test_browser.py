"""The dashboard in headless Chromium: one assertion per pane, on a rover run the test drives.

The run (conftest: the rover example with tactics awaiting approval) is moved on by the
tests, in file order: nominal until t=22 (G1 green), the dim light at t=25 (category 1: O1
holds, G4 and G1 violated, fail-safe and report-degradation pending approval), then the
operator approves the fail-safe from the page, and it switches the rover to manual mode.
Waits are on the page's content with generous deadlines; nothing is timed.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import Any

import pytest
from dashboard_helpers import ARTIFACTS, HERE, TOKEN, RoverRun, png

from anunnaki.bus import Detections, Image
from anunnaki.dashboard import Dashboard

pytestmark = pytest.mark.slow

WAIT = 30_000  # ms: generous, the machine is shared


class World:
    def __init__(self, run: RoverRun, dash: Dashboard, page: Any) -> None:
        self.run = run
        self.dash = dash
        self.page = page


@pytest.fixture(scope="module")
def world(chromium: Any) -> Iterator[World]:
    run = RoverRun(HERE / "data" / "rover-approval.yaml")
    dash = Dashboard(
        run.model, run.tactics, bus=run.bus, clock="sim", port=0, token=TOKEN, name="rover"
    )
    dash.start()
    page = chromium.new_page()
    try:
        run.run_to(22.0)
        page.goto(dash.url)
        page.wait_for_selector("#connection.on", timeout=WAIT)
        yield World(run, dash, page)
    finally:
        page.close()
        dash.close()
        run.close()


def node(page: Any, nid: str) -> Any:
    return page.locator(f"#goal-svg [data-node={nid}]")


def test_goal_model_g1_turns_red_on_a_violation(world: World) -> None:
    page = world.page
    page.wait_for_selector("#goal-svg [data-node=G1].satisfied", timeout=WAIT)
    assert node(page, "G1").locator("text.u").text_content().startswith("u ")
    world.run.run_to(25.2)  # dim light: the oracle reports category 1
    page.wait_for_selector("#goal-svg [data-node=G1].unsatisfied", timeout=WAIT)
    page.wait_for_selector("#goal-svg [data-node=O1].satisfied", timeout=WAIT)  # O1 holds
    assert node(page, "G4").get_attribute("class") == "node unsatisfied"


def test_plan_queue_in_priority_order_with_pending_marked(world: World) -> None:
    page = world.page
    page.wait_for_function("document.querySelectorAll('#plan-queue li').length >= 2", timeout=WAIT)
    rows = page.locator("#plan-queue li")
    assert rows.evaluate_all("els => els.map(e => e.dataset.tactic)") == [
        "fail-safe",
        "report-degradation",
    ]
    assert rows.first.locator(".state").text_content() == "pending approval"


def test_analyze_lists_violated_goals_and_applicable_tactics(world: World) -> None:
    page = world.page
    page.wait_for_selector("#eligible li[data-tactic=fail-safe]", timeout=WAIT)
    violated = page.locator("#violated li").evaluate_all("els => els.map(e => e.textContent)")
    assert {"G1", "G2", "G3", "G4"} <= set(violated)


def test_oracle_shows_the_category(world: World) -> None:
    page = world.page
    box = page.locator("#oracle .assessor[data-assessor='/utu/oracle/output']")
    box.locator(".category.cat-1").wait_for(timeout=WAIT)
    assert box.locator(".category").text_content() == "1"
    assert "confidence 0.90" in box.text_content()


def test_knowledge_shows_agents_and_utilities(world: World) -> None:
    page = world.page
    a4 = page.locator("#knowledge .agent[data-agent=A4]")
    page.wait_for_function(
        "document.querySelector('#knowledge .agent[data-agent=A4] .attrs')"
        ".textContent.includes('A4.category = 1')",
        timeout=WAIT,
    )
    assert "Behavior oracle" in a4.text_content()
    g7 = page.locator("#knowledge .agent[data-agent=A1] .pill[data-goal=G7]")
    assert g7.get_attribute("class") == "pill satisfied"
    assert g7.text_content() == "G7 1.00"


def test_monitor_shows_topics_with_value_rate_and_age(world: World) -> None:
    page = world.page
    row = page.locator("#monitor tr[data-topic='/rover/ultrasonic']")
    row.wait_for(timeout=WAIT)
    cells = row.locator("td").all_text_contents()
    assert cells[1] == "A3"
    assert '"range"' in cells[2]
    assert re.fullmatch(r"\d+\.\d Hz", cells[3])
    assert re.fullmatch(r"\d+\.\d s", cells[4])


def test_explanation_of_a_node_names_the_oracle_attribute(world: World) -> None:
    page = world.page
    node(page, "G4").click()
    page.wait_for_selector("#explanation[data-node=G4] #explanation-text", timeout=WAIT)
    text = page.locator("#explanation").text_content()
    assert "A4.category = 1" in text
    assert "Utu: unsatisfied" in text


def test_operator_action_without_the_token_is_refused(world: World) -> None:
    page = world.page
    page.evaluate("sessionStorage.removeItem('anunnaki-token')")
    page.fill("#token", "")
    page.dispatch_event("#token", "change")
    page.click("#plan-queue li[data-tactic=fail-safe] button[data-op=approve]")
    page.wait_for_selector("#operator-status.bad", timeout=WAIT)
    assert "approve refused: missing or wrong token" in page.text_content("#operator-status")
    world.run.step(25.3)
    assert world.run.decisions("approved") == []


def test_operator_action_with_the_token_is_logged_with_its_caller(world: World) -> None:
    page = world.page
    page.fill("#token", TOKEN)
    page.dispatch_event("#token", "change")
    page.click("#plan-queue li[data-tactic=fail-safe] button[data-op=approve]")
    page.wait_for_selector("#operator-status.ok", timeout=WAIT)
    world.run.step(25.4)  # Utu applies the call at its next step
    (approved,) = world.run.decisions("approved")
    assert approved.tactic == "fail-safe"
    assert approved.data["caller"] == "dashboard:operator@127.0.0.1"
    row = page.locator("#decision-log tr[data-kind=approved]")
    row.wait_for(timeout=WAIT)
    assert "caller=dashboard:operator@127.0.0.1" in row.locator("td.detail").text_content()


def test_execute_shows_the_postcondition_result(world: World) -> None:
    page = world.page
    world.run.run_to(27.0)  # the rover reports manual mode: G3 holds again through G11
    done = page.locator("#executions li[data-tactic=fail-safe][data-result=postcondition_ok]")
    done.wait_for(timeout=WAIT)
    assert "postconditions verified at t=25.50" in done.text_content()
    page.wait_for_selector("#goal-svg [data-node=G3].satisfied", timeout=WAIT)


def test_timeline_marks_the_tactic_at_its_start(world: World) -> None:
    page = world.page
    (started,) = [d for d in world.run.decisions("started") if d.tactic == "fail-safe"]
    marker = page.locator("#timeline g.marker[data-kind=started][data-tactic=fail-safe]")
    marker.wait_for(timeout=WAIT)
    assert float(marker.get_attribute("data-t")) == pytest.approx(started.t)
    line_x = float(marker.locator("line").get_attribute("x1"))
    path = page.locator("#timeline path.utility")
    assert int(path.get_attribute("data-points")) >= 2
    width = page.evaluate("document.getElementById('timeline').clientWidth")
    assert 34 < line_x < width  # inside the plot, not at an edge


def test_camera_pane_draws_frames_with_boxes(world: World) -> None:
    page = world.page
    bus = world.run.bus
    bus.publish(
        "/lm_manager/active", {"lec": "detector", "model": "centernet-fog", "domain": "fog"}
    )
    for seq, boxes in ((1, [[10.0, 10.0, 60.0, 90.0]]), (2, [[5.0, 5.0, 30.0, 40.0]] * 2)):
        bus.publish(
            "/rover/camera/image",
            Image(encoding="png", width=128, height=96, data=png(128, 96, (30, 90, 160)), seq=seq),
        )
        bus.publish(
            "/lec/detector/detections",
            Detections(
                frame_seq=seq,
                model_id="centernet-fog",
                domain="fog",
                width=128,
                height=96,
                boxes=boxes,
                labels=["person"] * len(boxes),
                scores=[0.9] * len(boxes),
            ),
        )
        page.wait_for_selector(
            f"#camera[data-seq='{seq}'][data-boxes='{len(boxes)}']", timeout=WAIT
        )
    assert page.text_content("#camera-model") == "active model centernet-fog · domain fog"
    color = page.evaluate(
        "Array.from(document.getElementById('camera').getContext('2d')"
        ".getImageData(120, 90, 1, 1).data.slice(0, 3))"
    )
    assert color == [30, 90, 160]  # the frame's pixels, outside the boxes


def test_screenshot_is_saved(world: World) -> None:
    ARTIFACTS.mkdir(exist_ok=True)
    out = ARTIFACTS / "dashboard-rover.png"
    world.page.wait_for_timeout(300)  # let the timeline's throttled redraw land
    world.page.screenshot(path=str(out), full_page=True)
    assert out.stat().st_size > 20_000
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
