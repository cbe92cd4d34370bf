"""The dashboard in headless Chromium: one assertion per pane, on a rover run the tests drive.

The run (the rover example with tactics awaiting approval) goes through phases, and each test
first asks for the phase it needs (``world.at(...)``), which moves trace time on as far as
that: nominal until t=22 (G1 green); the dim light at t=25.2 (category 1: O1 holds, G4 and G1
violated, fail-safe and report-degradation pending approval); the fail-safe approved by the
operator; recovered at t=27 (the rover in manual mode); the ultrasonic sensor silent from
t=45 (at t=48 its topic is stale and G13 unknown). Time only moves forward, and the tests are
in phase order, so any selection of them (``-k plan``) runs in file order and passes. Waits
are on the page's content with generous deadlines; nothing is timed.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import Any

import pytest
from dashboard_helpers import (
    ARTIFACTS,
    DEADLINE,
    HERE,
    PATIENCE,
    TOKEN,
    RoverRun,
    Web,
    png,
    wait_for,
)

from anunnaki.dashboard import Dashboard, ObserverConfig
from anunnaki.messages import Assessment, Detections, Image

pytestmark = pytest.mark.slow

WAIT = int(DEADLINE * 1000)  # ms: generous, the machine is shared
# Predicates of wait_for_function are arrow functions: the page's CSP forbids eval, and a
# bare expression is evaluated with it whenever the wait has to poll.
PHASES = ("nominal", "violation", "approved", "recovered", "silent")
CALLER = "dashboard:operator@127.0.0.1"
#: The page has its stream (a snapshot arrived): the badge then says live, waiting or ended.
CONNECTED = "#connection[data-state]:not([data-state=reconnecting])"


class World:
    """The shared run, its dashboard (with a token) and one page on it."""

    def __init__(self, run: RoverRun, dash: Dashboard, page: Any) -> None:
        self.run = run
        self.dash = dash
        self.page = page
        self.phase = 0

    def at(self, phase: str) -> None:
        """Move the run on to ``phase`` (never back: a test asking for a past phase fails)."""
        want = PHASES.index(phase)
        if self.phase > want:
            pytest.fail(
                f"the shared run is past {phase!r} (at {PHASES[self.phase]!r}); "
                "this module's tests run in file order, which is phase order"
            )
        while self.phase < want:
            self.phase += 1
            self._enter(PHASES[self.phase])

    def passed(self, phase: str) -> None:
        """Record that a test brought the run to ``phase`` itself."""
        self.phase = max(self.phase, PHASES.index(phase))

    def _enter(self, phase: str) -> None:
        run = self.run
        if phase == "violation":
            run.run_to(25.2)  # dim light: the oracle reports category 1
        elif phase == "approved" and not run.decisions("approved"):
            reply = Web(self.dash.url).post(
                "/api/operator/approve",
                json={"tactic": "fail-safe"},
                headers={"Authorization": f"Bearer {TOKEN}"},
            )
            assert reply.status_code == 200, reply.text
            run.step(round(max(run.t, 25.3) + 0.1, 1))  # Utu applies it at its next step
            assert run.decisions("approved")
        elif phase == "recovered":
            run.run_to(27.0)  # the rover reports manual mode: G3 holds again through G11
        elif phase == "silent":
            run.run_to(48.0)  # the ultrasonic sensor stopped publishing at t=45

    def use_token(self, token: str) -> None:
        self.page.fill("#token", token)
        self.page.dispatch_event("#token", "change")


@pytest.fixture(scope="module")
def world(chromium: Any) -> Iterator[World]:
    run = RoverRun(HERE / "data" / "rover-approval.yaml")
    dash = Dashboard(
        run.model,
        run.tactics,
        bus=run.bus,
        clock="sim",
        port=0,
        token=TOKEN,
        name="rover",
        **PATIENCE,
    )
    dash.start()
    page = chromium.new_page()
    try:
        run.run_to(22.0)
        page.goto(dash.url)
        page.wait_for_selector(CONNECTED, timeout=WAIT)
        yield World(run, dash, page)
    finally:
        page.close()
        dash.close()
        run.close()


def node(page: Any, nid: str) -> Any:
    return page.locator(f"#goal-svg [data-node={nid}]")


def utility_text(page: Any, nid: str) -> str:
    text: str = node(page, nid).locator("text.u").text_content()
    return text


def wait_utility(page: Any, nid: str, text: str) -> None:
    """Wait until node ``nid`` shows ``text`` as its utility (fails at the deadline)."""
    page.wait_for_function(
        "([nid, text]) => { const t = document.querySelector("
        "`#goal-svg [data-node=${nid}] text.u`); return t !== null && t.textContent === text; }",
        arg=[nid, text],
        timeout=WAIT,
    )
    assert utility_text(page, nid) == text


def test_goal_model_g1_turns_red_on_a_violation(world: World) -> None:
    page = world.page
    world.at("nominal")
    page.wait_for_selector("#goal-svg [data-node=G1].satisfied", timeout=WAIT)
    # Each node shows Utu's utility: G6 is RELAX-ed (the sensor at 4.8 Hz for 5 Hz) and
    # G1 inherits it; G7 is a satisfied leaf; G13 an unsatisfied one (a pedestrian within
    # 0.8 m), which G12 tolerates because the buzzer sounds (G14).
    wait_utility(page, "G1", "u 0.60")
    wait_utility(page, "G6", "u 0.60")
    wait_utility(page, "G7", "u 1.00")
    wait_utility(page, "G13", "u 0.00")
    assert node(page, "G13").get_attribute("class") == "node unsatisfied"
    world.at("violation")
    page.wait_for_selector("#goal-svg [data-node=G1].unsatisfied", timeout=WAIT)
    page.wait_for_selector("#goal-svg [data-node=O1].satisfied", timeout=WAIT)  # O1 holds
    assert node(page, "G4").get_attribute("class") == "node unsatisfied"
    wait_utility(page, "G1", "u 0.00")
    wait_utility(page, "G4", "u 0.00")  # obstructed by O1
    wait_utility(page, "O1", "u 1.00")


def test_plan_queue_in_priority_order_with_pending_marked(world: World) -> None:
    page = world.page
    world.at("violation")
    page.wait_for_function(
        "() => document.querySelectorAll('#plan-queue li').length >= 2", timeout=WAIT
    )
    rows = page.locator("#plan-queue li")
    assert rows.evaluate_all("els => els.map(e => e.dataset.tactic)") == [
        "fail-safe",
        "report-degradation",
    ]
    assert rows.first.locator(".state").text_content() == "pending approval"


def test_analyze_lists_violated_goals_and_applicable_tactics(world: World) -> None:
    page = world.page
    world.at("violation")
    page.wait_for_selector("#eligible li[data-tactic=fail-safe]", timeout=WAIT)
    violated = page.locator("#violated li").evaluate_all("els => els.map(e => e.textContent)")
    assert {"G1", "G2", "G3", "G4"} <= set(violated)


def test_oracle_shows_the_category(world: World) -> None:
    page = world.page
    world.at("violation")
    box = page.locator("#oracle .assessor[data-assessor='/utu/oracle/output']")
    box.locator(".category.cat-1").wait_for(timeout=WAIT)
    assert box.locator(".category").text_content() == "1"
    assert "confidence 0.90" in box.text_content()


def test_oracle_shows_each_assessor_with_its_perceived_context(world: World) -> None:
    page = world.page
    world.at("violation")
    world.run.bus.publish(
        "/utu/oracle/fog",
        Assessment(
            category=2,
            confidence=0.75,
            context={"phenomenon": "fog", "density": 4},
            model_id="centernet-default",
            assessor="fog-oracle",
        ),
    )
    world.run.bus.publish(
        "/utu/oracle/ground_truth",
        Assessment(
            category=0,
            confidence=0.6,
            context={"phenomenon": "low_light", "lux": 3},
            model_id="centernet-low-light",
            assessor="ground_truth",
        ),
    )
    fog = page.locator("#oracle .assessor[data-assessor=fog-oracle]")
    truth = page.locator("#oracle .assessor[data-assessor=ground_truth]")
    fog.wait_for(timeout=WAIT)
    truth.wait_for(timeout=WAIT)
    assert fog.locator(".category").get_attribute("class") == "category cat-2"
    assert fog.locator(".category").text_content() == "2"
    assert "confidence 0.75" in fog.text_content()
    assert "context: phenomenon=fog density=4" in fog.text_content()
    assert "model centernet-default · /utu/oracle/fog" in fog.text_content()
    assert truth.locator(".category").text_content() == "0"
    assert "context: phenomenon=low_light lux=3" in truth.text_content()
    assert "model centernet-low-light · /utu/oracle/ground_truth" in truth.text_content()
    # The rover's own oracle keeps its row: one row per assessor.
    assert page.locator("#oracle .assessor").count() == 3


def test_knowledge_shows_agents_and_utilities(world: World) -> None:
    page = world.page
    world.at("violation")
    a4 = page.locator("#knowledge .agent[data-agent=A4]")
    page.wait_for_function(
        "() => document.querySelector('#knowledge .agent[data-agent=A4] .attrs')"
        ".textContent.includes('A4.category = 1')",
        timeout=WAIT,
    )
    assert "Behavior oracle" in a4.text_content()
    g7 = page.locator("#knowledge .agent[data-agent=A1] .pill[data-goal=G7]")
    assert g7.get_attribute("class") == "pill satisfied"
    assert g7.text_content() == "G7 1.00"


def test_monitor_shows_topics_with_value_rate_age_and_staleness(world: World) -> None:
    page = world.page
    world.at("violation")
    row = page.locator("#monitor tr[data-topic='/rover/ultrasonic']")
    row.wait_for(timeout=WAIT)
    cells = row.locator("td").all_text_contents()
    assert cells[1] == "A3"
    assert '"range"' in cells[2]
    assert re.fullmatch(r"\d+\.\d Hz", cells[3])
    assert re.fullmatch(r"\d+\.\d s", cells[4])
    assert cells[5] == "1.0 s"  # A3's staleness (binding.yaml)
    status = page.locator("#monitor tr[data-topic='/rover/status'] td.limit")
    assert status.text_content() == "2.0 s"  # the goal model's default


def test_explanation_of_a_node_names_the_oracle_attribute(world: World) -> None:
    page = world.page
    world.at("violation")
    page.wait_for_selector("#goal-svg [data-node=G4].unsatisfied", timeout=WAIT)
    # The tree shows Utu's verdict; the explanation is the dashboard's own evaluator, fed on
    # its own subscriptions: click once that evaluator has the oracle's category 1 too.
    wait_for(
        lambda: world.dash.state.snapshot()["values"].get("A4.category") == 1,
        what="the dashboard's own evaluator at category 1",
    )
    node(page, "G4").click()
    page.wait_for_selector("#explanation[data-node=G4] #explanation-text", timeout=WAIT)
    text = page.locator("#explanation").text_content()
    assert "A4.category = 1" in text
    assert "Utu: unsatisfied" in text


def test_read_only_page_offers_no_operator_controls(world: World, chromium: Any) -> None:
    world.at("violation")  # a tactic is pending: a page with a token shows approve/reject
    world.page.wait_for_selector(
        "#plan-queue li[data-tactic=fail-safe] button[data-op=approve]", timeout=WAIT
    )
    run = world.run
    # Its pending tactic comes from its start-up query to Utu: give Utu time to answer.
    seed = ObserverConfig(query_timeout=DEADLINE)
    with Dashboard(run.model, run.tactics, bus=run.bus, clock="sim", port=0, topics=seed) as dash:
        page = chromium.new_page()
        try:
            page.goto(dash.url)
            page.wait_for_selector(CONNECTED, timeout=WAIT)
            page.wait_for_selector("#plan-queue li[data-tactic=fail-safe].pending", timeout=WAIT)
            assert page.locator("#readonly").is_visible()
            assert not page.locator("#operator").is_visible()
            for button in ("#op-pause", "#op-resume", "#op-runstop", "#token"):
                assert not page.locator(button).is_visible(), button
            assert page.locator("#plan-queue button").count() == 0
            assert page.locator("button[data-op]:visible").count() == 0
        finally:
            page.close()
        refused = Web(dash.url).post(
            "/api/operator/approve",
            json={"tactic": "fail-safe"},
            headers={"Authorization": f"Bearer {TOKEN}"},
        )
        assert refused.status_code == 403


def test_operator_action_without_the_token_is_refused(world: World) -> None:
    page = world.page
    world.at("violation")
    page.evaluate("sessionStorage.removeItem('anunnaki-token')")
    world.use_token("")
    page.click("#plan-queue li[data-tactic=fail-safe] button[data-op=approve]")
    page.wait_for_selector("#operator-status.bad", timeout=WAIT)
    assert "approve refused: missing or wrong token" in page.text_content("#operator-status")
    world.run.step(25.3)
    assert world.run.decisions("approved") == []


def test_operator_action_with_the_token_is_logged_with_its_caller(world: World) -> None:
    page = world.page
    world.at("violation")
    world.use_token(TOKEN)
    page.click("#plan-queue li[data-tactic=fail-safe] button[data-op=approve]")
    page.wait_for_selector("#operator-status.ok", timeout=WAIT)
    world.run.step(25.4)  # Utu applies the call at its next step
    world.passed("approved")
    (approved,) = world.run.decisions("approved")
    assert approved.tactic == "fail-safe"
    assert approved.data["caller"] == CALLER
    row = page.locator("#decision-log tr[data-kind=approved]")
    row.wait_for(timeout=WAIT)
    assert f"caller={CALLER}" in row.locator("td.detail").text_content()


def test_execute_shows_the_postcondition_result(world: World) -> None:
    page = world.page
    world.at("recovered")
    done = page.locator("#executions li[data-tactic=fail-safe][data-result=postcondition_ok]")
    done.wait_for(timeout=WAIT)
    assert "postconditions verified at t=25.50" in done.text_content()
    page.wait_for_selector("#goal-svg [data-node=G3].satisfied", timeout=WAIT)


def test_timeline_marks_the_tactic_at_its_start(world: World) -> None:
    page = world.page
    world.at("recovered")
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
    page.wait_for_function(
        "() => document.getElementById('camera-model').textContent.includes('centernet-fog')",
        timeout=WAIT,
    )
    assert page.text_content("#camera-model") == "active model centernet-fog · domain fog"
    color = page.evaluate(
        "Array.from(document.getElementById('camera').getContext('2d')"
        ".getImageData(120, 90, 1, 1).data.slice(0, 3))"
    )
    assert color == [30, 90, 160]  # the frame's pixels, outside the boxes


def test_screenshot_is_saved(world: World) -> None:
    page = world.page
    world.at("recovered")
    state = world.dash.state
    # Wait until the page shows what the dashboard holds: the whole utility line (the
    # timeline's redraw is throttled), the fail-safe verified, every decision in the log.
    page.wait_for_selector(
        "#executions li[data-tactic=fail-safe][data-result=postcondition_ok]", timeout=WAIT
    )

    def drawn() -> bool:
        snap = state.snapshot()
        shown = page.evaluate(
            "() => [Number(document.querySelector('#timeline path.utility')?.dataset.points),"
            " document.querySelectorAll('#decision-log tbody tr').length]"
        )
        return bool(shown == [len(snap["timeline"]), min(300, len(snap["decisions"]))])

    wait_for(drawn, timeout=WAIT / 1000, what="the page to show the whole run")
    ARTIFACTS.mkdir(exist_ok=True)
    out = ARTIFACTS / "dashboard-rover.png"
    page.screenshot(path=str(out), full_page=True)
    assert out.stat().st_size > 20_000
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_monitor_marks_a_topic_that_stops_publishing_stale(world: World) -> None:
    page = world.page
    ultrasonic = "#monitor tr[data-topic='/rover/ultrasonic'] td.age"
    status = "#monitor tr[data-topic='/rover/status'] td.age"
    world.at("recovered")  # every topic publishing
    # Fresh while the sensor publishes. (Trace time moves on in a burst, and a topic whose
    # messages are still queued can look stale for a moment: wait for them to be in.)
    page.wait_for_selector(f"{ultrasonic}:not(.stale)", timeout=WAIT)
    assert float(page.text_content(f"{ultrasonic}:not(.stale)").removesuffix(" s")) <= 1.0
    world.at("silent")  # the ultrasonic sensor's last message was at t=45, now t=48
    page.wait_for_selector(f"{ultrasonic}.stale", timeout=WAIT)
    assert float(page.text_content(f"{ultrasonic}.stale").removesuffix(" s")) > 1.0
    # The rover's status keeps coming: that row is fresh, and the silent one still stale.
    page.wait_for_selector(f"{status}:not(.stale)", timeout=WAIT)
    assert page.locator(f"{ultrasonic}.stale").count() == 1


def test_goal_model_greys_a_node_whose_agent_is_silent(world: World) -> None:
    page = world.page
    world.at("silent")
    nodes = world.run.manager.analyzer.state_message(world.run.t, [])["nodes"]
    assert nodes["G13"] == [None, "unknown"]  # Utu: A3.range is stale, so unknown
    page.wait_for_selector("#goal-svg [data-node=G13].unknown", timeout=WAIT)
    assert node(page, "G13").get_attribute("class") == "node unknown"
    wait_utility(page, "G13", "u ?")
    pill = page.locator("#knowledge .agent[data-agent=A3] .pill[data-goal=G13]")
    assert pill.get_attribute("class") == "pill unknown"
    assert nodes["G14"] == [1.0, "satisfied"]  # A1 still speaks: its goal stays coloured
    page.wait_for_selector("#goal-svg [data-node=G14].satisfied", timeout=WAIT)


def test_run_stop_asks_for_confirmation_and_is_logged_with_its_caller(world: World) -> None:
    page = world.page
    world.at("silent")
    world.use_token(TOKEN)
    page.evaluate("document.getElementById('operator-status').textContent = ''")
    asked: list[str] = []

    def dismiss(dialog: Any) -> None:
        asked.append(dialog.message)
        dialog.dismiss()

    page.once("dialog", dismiss)
    page.click("#op-runstop")
    assert asked == ["Run-stop: halt adaptation and stop the system?"]
    # Declined: the click handler returned without calling Utu (it would say "run_stop…").
    assert page.text_content("#operator-status") == ""

    def accept(dialog: Any) -> None:
        asked.append(dialog.message)
        dialog.accept()

    page.once("dialog", accept)
    page.click("#op-runstop")
    page.wait_for_selector("#operator-status.ok", timeout=WAIT)
    assert len(asked) == 2
    world.run.step(world.run.t + 0.1)  # Utu applies it at its next step
    (stop,) = world.run.decisions("run_stop")
    assert stop.data["caller"] == CALLER
    assert stop.data["reason"] == "operator run-stop from the dashboard"
    assert world.run.manager.run_stopped
    page.wait_for_selector("#flag-runstop:not(.hidden)", timeout=WAIT)
    row = page.locator("#decision-log tr[data-kind=run_stop]")
    row.wait_for(timeout=WAIT)
    assert f"caller={CALLER}" in row.locator("td.detail").text_content()


# -- the header's time, the live badge and the frame rate, on a run of their own ---------------
def test_header_time_live_badge_and_frame_rate(chromium: Any) -> None:
    """The header shows the latest time any pane shows (the oracle's row is newer than Utu's
    last analysis); the badge is *live* while Utu's liveliness token is held and *ended* once
    it is withdrawn; the camera's fps is frames drawn over their stamps' span (9.6 frames per
    simulated second, however fast they arrive). Frames are published one at a time, each
    once the page has drawn the previous one."""
    from anunnaki.bus import InprocHub, open_bus
    from anunnaki.goals import load_goal_model
    from anunnaki.messages import Clock
    from anunnaki.tactics import load_tactics

    rover = HERE.parents[1] / "examples" / "rover"
    model = load_goal_model(rover / "goals.yaml", rover / "binding.yaml")
    tactics = load_tactics(rover / "tactics.yaml")
    hub = InprocHub()
    with (
        open_bus("inproc", hub=hub, name="sim") as sim,
        Dashboard(model, tactics, bus=sim, clock="sim", port=0, seed=False, idle=3600) as dash,
    ):
        page = chromium.new_page()
        try:
            page.goto(dash.url)
            page.wait_for_selector(CONNECTED, timeout=WAIT)
            assert page.get_attribute("#connection", "data-state") == "waiting"
            token = sim.liveliness_token("/utu_monitor")
            sim.publish("/utu/analyze/state", {"t": 33.8, "nodes": {"G1": [1.0, "satisfied"]}})
            page.wait_for_selector("#connection.on[data-state=live]", timeout=WAIT)
            assert page.text_content("#connection") == "live"

            def clock(t: float) -> None:
                sim.publish("/clock", Clock(time=t))
                wait_for(lambda: dash.state.clock() >= t, what=f"the dashboard's clock at {t}")

            clock(36.1)
            sim.publish(
                "/utu/oracle/output",
                Assessment(category=1, confidence=0.9, model_id="m", assessor="oracle"),
            )
            page.wait_for_function(
                "() => document.getElementById('oracle').textContent.includes('t 36.10')",
                timeout=WAIT,
            )
            page.wait_for_function(
                "() => document.getElementById('utu-time').textContent === 't = 36.10'",
                timeout=WAIT,
            )

            data = png(32, 24, (10, 20, 30))
            for k in range(1, 25):
                clock(round(40.0 + k / 9.6, 6))
                sim.publish(
                    "/rover/camera/image",
                    Image(encoding="png", width=32, height=24, data=data, seq=k),
                )
                page.wait_for_selector(f"#camera[data-seq='{k}']", timeout=WAIT)
            fps = float(page.get_attribute("#camera", "data-fps") or "nan")
            assert fps == pytest.approx(9.6, abs=0.01)
            assert "· 9.6 fps ·" in page.text_content("#camera-info")
            page.wait_for_function(  # the header follows the frames' time too
                "() => document.getElementById('utu-time').textContent === 't = 42.50'",
                timeout=WAIT,
            )

            token.close()  # Utu's node stops: the run has ended
            page.wait_for_selector("#connection.off[data-state=ended]", timeout=WAIT)
            assert page.text_content("#connection") == "ended"
            assert page.get_attribute("#connection", "title") == "Utu's nodes are gone"
            assert page.text_content("#utu-time") == "t = 42.50"
        finally:
            page.close()
