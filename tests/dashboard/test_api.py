"""The dashboard without a browser: state, HTTP API, token checks, server-sent events, CLI."""

from __future__ import annotations

import argparse
import http.client
import json
import os
import queue
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.parse
from pathlib import Path
from typing import Any

import dashboard_helpers
import pytest
from dashboard_helpers import (
    HERE,
    PATIENCE,
    REQUIRE_BROWSER,
    ROOT,
    ROVER,
    TOKEN,
    RoverRun,
    Web,
    free_port,
    need_browser,
    png,
    wait_for,
)

from anunnaki.bus import BusConfigError, open_bus
from anunnaki.cli import _dashboard
from anunnaki.dashboard import (
    Dashboard,
    DashboardError,
    DashboardState,
    Frame,
    create_app,
)
from anunnaki.dashboard._server import is_loopback, loopback_names
from anunnaki.dashboard._token import Throttle
from anunnaki.errors import MissingExtraError, ModelFileError
from anunnaki.goals import load_goal_model
from anunnaki.launch import load_launch
from anunnaki.messages import Clock, Detections, Image, body_of
from anunnaki.tactics import load_tactics
from anunnaki.tokens import token_weakness
from anunnaki.topics import DECISIONS as DECISIONS_TOPIC


@pytest.fixture
def state() -> DashboardState:
    model = load_goal_model(ROVER / "goals.yaml", ROVER / "binding.yaml")
    return DashboardState(model, load_tactics(ROVER / "tactics.yaml"), clock=lambda: 10.0)


# -- the state ------------------------------------------------------------------------------
def test_state_takes_analysis_and_sends_only_changed_goals(state: DashboardState) -> None:
    nodes = {g: [1.0, "satisfied"] for g in state.model.goals}
    state.take_analysis({"t": 1.0, "nodes": nodes, "violated": [], "tactics": []})
    seen = state.version
    nodes["G4"] = [0.0, "unsatisfied"]
    state.take_analysis(
        {
            "t": 2.0,
            "nodes": nodes,
            "violated": ["G4"],
            "tactics": ["fail-safe"],
            "queue": [{"tactic": "fail-safe", "priority": 100, "state": "pending"}],
        }
    )
    patch = state.delta(seen, decisions_after=0, timeline_after=0)
    assert patch["goals"] == {"G4": [0.0, "unsatisfied"]}
    assert patch["analysis"]["violated"] == ["G4"]
    assert patch["analysis"]["eligible"] == ["fail-safe"]
    assert patch["analysis"]["queue"][0]["state"] == "pending"
    assert state.snapshot()["goal_source"] == "utu"


def test_state_derives_executions_and_dedupes_decisions(state: DashboardState) -> None:
    rows = [
        {"id": 1, "t": 25.0, "kind": "started", "tactic": "fail-safe", "data": {"deadline": 30}},
        {"id": 2, "t": 25.0, "kind": "action", "tactic": "fail-safe", "data": {"ok": True}},
        {"id": 3, "t": 25.5, "kind": "postcondition_ok", "tactic": "fail-safe", "data": {}},
    ]
    state.take_decisions(rows)
    # The same decisions again, as a knowledge query answers them (without ids): ignored.
    state.take_decisions([{k: v for k, v in r.items() if k != "id"} for r in rows])
    snap = state.snapshot()
    assert [d["kind"] for d in snap["decisions"]] == ["started", "action", "postcondition_ok"]
    (run,) = snap["executions"]
    assert (run["tactic"], run["result"], run["result_t"]) == (
        "fail-safe",
        "postcondition_ok",
        25.5,
    )


def test_state_flags_follow_the_newest_of_analysis_and_operator_decisions(
    state: DashboardState,
) -> None:
    """Utu publishes its analysis only when a goal changes: a pause shows from the log."""
    state.take_analysis({"t": 4.0, "paused": False, "run_stopped": False})
    state.take_decisions([{"t": 5.0, "kind": "paused", "data": {"caller": "x"}}])
    assert state.snapshot()["analysis"]["paused"] is True
    state.take_analysis({"t": 4.5, "paused": False})  # late, and older than the pause
    assert state.snapshot()["analysis"]["paused"] is True
    state.take_decisions([{"t": 5.5, "kind": "run_stop", "data": {"caller": "x"}}])
    assert state.snapshot()["analysis"]["run_stopped"] is True
    state.take_decisions([{"t": 6.0, "kind": "resumed_adaptation", "data": {"caller": "x"}}])
    analysis = state.snapshot()["analysis"]
    assert (analysis["paused"], analysis["run_stopped"]) == (False, False)
    state.take_analysis({"t": 7.0, "paused": True, "run_stopped": False})  # newer: it holds
    state.take_decisions([{"t": 3.0, "kind": "resumed_adaptation"}])  # older: history only
    assert state.snapshot()["analysis"]["paused"] is True


def test_state_evaluates_on_its_own_until_utu_speaks(state: DashboardState) -> None:
    state.take_input("/utu/oracle/output", {"category": 1, "confidence": 0.9}, 10.0)
    out = state.explain("O1")
    assert out is not None
    assert out["source"] == "dashboard"
    assert "A4.category = 1" in out["text"]
    assert state.snapshot()["goals"]["O1"] == [1.0, "satisfied"]  # the obstacle holds


# -- the HTTP API ---------------------------------------------------------------------------
def test_snapshot_explain_frame_and_page(state: DashboardState) -> None:
    state.take_input("/utu/oracle/output", {"category": 1, "confidence": 0.9}, 10.0)
    client = Web.serve(create_app(state))
    snap = client.get("/api/snapshot").json()
    assert snap["structure"]["root"] == "G1"
    assert {a["id"] for a in snap["structure"]["agents"]} == {"A1", "A2", "A3", "A4"}
    assert snap["structure"]["tactics"][0]["name"] == "fail-safe"
    explained = client.get("/api/explain/G4").json()
    assert "A4.category" in explained["text"]
    assert client.get("/api/explain/G99").status_code == 404
    assert client.get("/api/frame/latest").status_code == 404
    page = client.get("/")
    assert page.status_code == 200
    assert "script-src 'self'" in page.headers["content-security-policy"]
    assert "/static/dashboard.js" in page.text
    assert "https://" not in page.text  # nothing from a CDN
    assert client.get("/static/dashboard.js").status_code == 200


def test_operator_refused_read_only_and_without_token(state: DashboardState) -> None:
    read_only = Web.serve(create_app(state))
    r = read_only.post("/api/operator/pause", json={})
    assert r.status_code == 403
    assert "--token" in r.json()["detail"]
    guarded = Web.serve(create_app(state, token=TOKEN))
    assert guarded.post("/api/operator/pause", json={}).status_code == 401
    wrong = guarded.post("/api/operator/pause", headers={"Authorization": "Bearer nope"})
    assert wrong.status_code == 401
    assert wrong.headers["www-authenticate"] == "Bearer"


@pytest.mark.parametrize(
    ("token", "why"),
    [
        ("", "empty"),
        ("screenshot", "bits"),
        ("a" * 64, "distinct characters"),
        ("correcthorsebattery", "bits"),  # 19 lower-case letters: about 89 bits
    ],
)
def test_a_weak_operator_token_is_refused(state: DashboardState, token: str, why: str) -> None:
    with pytest.raises(ValueError, match=why):
        create_app(state, token=token)
    assert token_weakness(secrets.token_urlsafe(16)) is None  # what the error suggests


def test_failed_token_guesses_are_rate_limited(state: DashboardState) -> None:
    guarded = Web.serve(create_app(state, token=TOKEN))
    codes = [
        guarded.post(
            "/api/operator/pause", headers={"Authorization": f"Bearer guess-{i}"}
        ).status_code
        for i in range(8)
    ]
    assert codes == [401] * 5 + [429] * 3  # five guesses a minute, then a lock-out
    locked = guarded.post("/api/operator/pause", headers={"Authorization": f"Bearer {TOKEN}"})
    assert locked.status_code == 429  # even the right token waits: no oracle for guesses
    assert int(locked.headers["retry-after"]) > 0


def test_the_throttle_also_counts_guesses_across_clients() -> None:
    throttle = Throttle(limit=2, window=60.0, lockout=30.0)
    for i in range(8):  # one guess each from eight addresses: none is locked by its own
        assert throttle.wait(f"10.0.0.{i}") == 0
        throttle.failed(f"10.0.0.{i}")
    assert throttle.wait("10.0.0.99") > 0  # 8 = 2 x 4 failures from anywhere lock everyone


def test_operator_with_token_is_logged_by_utu_with_its_caller(rover_run: RoverRun) -> None:
    rover_run.run_to(3.0)
    with Dashboard(rover_run.model, rover_run.tactics, bus=rover_run.bus, port=0, token=TOKEN):
        pass  # a dashboard starts and stops cleanly around a live bus
    dash = Dashboard(
        rover_run.model, rover_run.tactics, bus=rover_run.bus, port=0, token=TOKEN, **PATIENCE
    )
    dash.start()
    client = Web(dash.url)
    try:
        r = client.post(
            "/api/operator/pause",
            json={"operator": "alice"},
            headers={"Authorization": f"Bearer {TOKEN}"},
        )
        assert r.status_code == 200, r.text
        assert r.json()["caller"] == "dashboard:alice@127.0.0.1"
        bad = client.post(
            "/api/operator/approve", json={}, headers={"Authorization": f"Bearer {TOKEN}"}
        )
        assert bad.status_code == 502
        assert "pending tactic" in bad.json()["detail"]
        rover_run.step(3.1)
        (paused,) = rover_run.decisions("paused")
        assert paused.data["caller"] == "dashboard:alice@127.0.0.1"
    finally:
        dash.close()


def test_operator_reject_resume_and_run_stop_are_applied_and_logged(
    rover_run: RoverRun,
) -> None:
    """Each action reaches Utu, changes its state at its next step, and is recorded by Utu and
    shown in the dashboard's decision log with the caller the dashboard named."""
    rover_run.run_to(25.2)  # fail-safe and report-degradation pending approval
    auth = {"Authorization": f"Bearer {TOKEN}"}
    caller = "dashboard:bob@127.0.0.1"
    manager = rover_run.manager
    with Dashboard(
        rover_run.model,
        rover_run.tactics,
        bus=rover_run.bus,
        clock="sim",
        port=0,
        token=TOKEN,
        **PATIENCE,
    ) as dash:
        client = Web(dash.url)

        def act(action: str, t: float, **body: str) -> None:
            r = client.post(
                f"/api/operator/{action}", json={"operator": "bob", **body}, headers=auth
            )
            assert r.status_code == 200, r.text
            assert r.json()["caller"] == caller
            rover_run.step(t)  # Utu applies the call at its next step

        def logged(kind: str) -> dict:
            rows = [d for d in dash.state.snapshot()["decisions"] if d["kind"] == kind]
            return rows[-1] if rows else {}

        act("reject", 25.3, tactic="report-degradation")
        (rejected,) = rover_run.decisions("rejected")
        assert (rejected.tactic, rejected.data["caller"]) == ("report-degradation", caller)
        queue = {row["tactic"]: row["state"] for row in manager.planner.queue()}
        assert queue == {"fail-safe": "pending", "report-degradation": "rejected"}
        row = wait_for(lambda: logged("rejected"), what="the rejection in the decision log")
        assert (row["tactic"], row["data"]["caller"]) == ("report-degradation", caller)

        act("pause", 25.4)
        assert manager.paused
        wait_for(lambda: dash.state.snapshot()["analysis"]["paused"], what="paused flag")
        act("resume", 25.5)
        assert not manager.paused
        (resumed,) = rover_run.decisions("resumed_adaptation")
        assert resumed.data["caller"] == caller
        assert wait_for(lambda: logged("resumed_adaptation"))["data"]["caller"] == caller
        # the decision and Utu's next analysis come on two threads: wait for both
        wait_for(lambda: dash.state.snapshot()["analysis"]["paused"] is False, what="resumed")

        act("run_stop", 25.6, reason="cliff ahead")
        assert manager.run_stopped
        (stop,) = rover_run.decisions("run_stop")
        assert (stop.data["caller"], stop.data["reason"]) == (caller, "cliff ahead")
        assert stop.data["service"] == "/rover/stop"
        assert rover_run.rover.overrides.get("stopped") is True  # Utu called /rover/stop
        row = wait_for(lambda: logged("run_stop"), what="the run-stop in the decision log")
        assert (row["data"]["caller"], row["data"]["reason"]) == (caller, "cliff ahead")
        analysis = dash.state.snapshot()["analysis"]
        assert (analysis["run_stopped"], analysis["paused"]) == (True, True)

        assert client.post("/api/operator/reboot", json={}, headers=auth).status_code == 404
        no_tactic = client.post("/api/operator/reject", json={}, headers=auth)
        assert no_tactic.status_code == 502
        assert "reject needs the name of a pending tactic" in no_tactic.json()["detail"]


# -- the server and its event stream --------------------------------------------------------
def test_events_stream_snapshot_then_patches(rover_run: RoverRun) -> None:
    rover_run.run_to(1.0)
    with Dashboard(
        rover_run.model, rover_run.tactics, bus=rover_run.bus, port=0, clock="sim"
    ) as dash:
        assert dash.url.startswith("http://127.0.0.1:")
        with Web(dash.url).stream("/api/events") as response:
            assert response.headers["content-type"].startswith("text/event-stream")
            events: list[tuple[str, dict]] = []
            kind = ""
            g4 = category = None
            for raw in response:
                line = raw.decode().rstrip("\n")
                if line.startswith("event: "):
                    kind = line[7:]
                elif line.startswith("data: "):
                    body = json.loads(line[6:])
                    events.append((kind, body))
                    if kind == "snapshot":
                        rover_run.run_to(26.0)  # the oracle reports category 1 at t=25
                    g4 = body.get("goals", {}).get("G4", g4)
                    for o in body.get("oracle", []):
                        category = o["category"]
                    if g4 == [0.0, "unsatisfied"] and category == 1:
                        break
        assert events[0][0] == "snapshot"
        assert events[0][1]["structure"]["root"] == "G1"
        patches = [e for k, e in events if k == "patch"]
        assert patches
        assert all(p["version"] > events[0][1]["version"] for p in patches)
        assert g4 == [0.0, "unsatisfied"]
        # Each patch carries only what changed, not the model again.
        assert all("structure" not in p for p in patches)


def test_camera_frames_and_detections_from_the_bus(rover_run: RoverRun) -> None:
    with (
        Dashboard(rover_run.model, rover_run.tactics, bus=rover_run.bus, port=0) as dash,
        open_bus("inproc", hub=rover_run.hub, name="camera") as cam,
    ):
        data = png(64, 48, (200, 40, 40))
        cam.publish(
            "/rover/camera/image", Image(encoding="png", width=64, height=48, data=data, seq=7)
        )
        cam.publish(
            "/lec/detector/detections",
            Detections(
                frame_seq=7,
                model_id="centernet-fog",
                domain="fog",
                width=64,
                height=48,
                boxes=[[4.0, 4.0, 20.0, 30.0]],
                labels=["person"],
                scores=[0.8],
            ),
        )
        # frames and detections come on two subscriptions (two threads): wait for both
        wait_for(
            lambda: (
                (c := dash.state.snapshot()["camera"]).get("detections")
                and c.get("frame", {}).get("seq") == 7
            ),
            what="the frame and its detections",
        )
        r = Web(dash.url).get("/api/frame/7")
        assert r.status_code == 200
        assert r.headers["content-type"] == "image/png"
        assert r.content == data
        camera = dash.state.snapshot()["camera"]
        assert camera["frame"]["seq"] == 7
        assert camera["detections"]["labels"] == ["person"]
        assert camera["active"]["model"] == "centernet-fog"


# -- the header's time, the live badge, the frame rate ----------------------------------------
def test_header_time_is_the_latest_time_any_pane_shows(state: DashboardState) -> None:
    assert state.snapshot()["latest_t"] is None  # nothing shown yet: the page shows `now`
    state.take_analysis({"t": 33.8, "nodes": {"G1": [1.0, "satisfied"]}})
    seen = state.version
    state.take_assessment("/utu/oracle/output", {"category": 0, "confidence": 0.9}, 36.1)
    assert state.snapshot()["latest_t"] == 36.1  # the oracle pane's row is newer than Utu's t
    assert state.snapshot()["utu_t"] == 33.8
    assert state.delta(seen, decisions_after=0, timeline_after=0)["latest_t"] == 36.1
    state.take_analysis({"t": 34.0, "nodes": {"G1": [1.0, "satisfied"]}})
    state.take_decisions([{"t": 35.0, "kind": "started", "tactic": "fail-safe", "data": {}}])
    assert state.latest_t == 36.1  # never back
    state.take_input("/rover/status", {"mode": "manual"}, 36.5)
    assert state.latest_t == 36.5
    # unchanged version: the heartbeat patch still carries it
    assert state.delta(state.version, decisions_after=9, timeline_after=9)["latest_t"] == 36.5


def test_the_run_is_live_while_fed_and_ended_after_idle_or_when_utu_leaves() -> None:
    model = load_goal_model(ROVER / "goals.yaml", ROVER / "binding.yaml")
    wall = [100.0]
    state = DashboardState(
        model,
        load_tactics(ROVER / "tactics.yaml"),
        clock=lambda: 1.0,
        idle=5.0,
        wall=lambda: wall[0],
    )
    assert state.run() == {"live": False, "state": "waiting", "reason": "no message yet"}
    state.take_input("/rover/status", {"mode": "autonomous"}, 1.0)
    assert state.run()["live"] is True
    wall[0] += 5.0
    assert state.run()["live"] is True  # at the limit: still live
    wall[0] += 2.0
    assert state.run() == {"live": False, "state": "ended", "reason": "no message for 7 s"}
    assert state.delta(state.version, decisions_after=0, timeline_after=0)["run"]["live"] is False
    state.heard()  # a /clock: fed again
    assert state.run()["state"] == "live"
    state.utu_node("/utu_monitor", True)
    state.utu_node("/utu_analyze", True)
    state.utu_node("/utu_monitor", False)
    assert state.run()["live"] is True  # one of Utu's nodes still runs
    state.utu_node("/utu_analyze", False)
    assert state.run() == {"live": False, "state": "ended", "reason": "Utu's nodes are gone"}
    state.take_input("/rover/status", {"mode": "autonomous"}, 2.0)
    assert state.run()["state"] == "ended"  # Utu gone: late messages do not revive the run
    state.utu_node("/utu_monitor", True)  # Utu restarted
    assert state.run()["state"] == "live"
    state.end("the run has ended")  # its launch says so: ended for good, whatever follows
    state.heard()
    state.utu_node("/utu_plan", True)
    assert state.run() == {"live": False, "state": "ended", "reason": "the run has ended"}


def test_the_badge_follows_utus_liveliness_token_on_the_bus(rover_run: RoverRun) -> None:
    with (
        Dashboard(rover_run.model, rover_run.tactics, bus=rover_run.bus, port=0, idle=3600) as dash,
        open_bus("inproc", hub=rover_run.hub, name="utu-node") as node,
    ):
        node.publish("/rover/status", {"mode": "autonomous"})
        token = node.liveliness_token("/utu_monitor")
        node.liveliness_token("/camera_driver")  # not Utu's: ignored
        wait_for(lambda: dash.state.snapshot()["run"]["live"], what="the run live")
        token.close()
        run = wait_for(
            lambda: (r := dash.state.snapshot()["run"])["state"] == "ended" and r,
            what="the run ended once Utu's token is gone",
        )
        assert run == {"live": False, "state": "ended", "reason": "Utu's nodes are gone"}


def test_frame_rate_is_measured_on_the_frames_stamps_not_their_arrivals(
    state: DashboardState,
) -> None:
    data = png(8, 8, (0, 0, 0))
    assert state.frame_rate() is None
    for k in range(40):  # 9.6 frames/s of stamps, delivered in one burst
        state.take_frame(Frame("/rover/camera/image", k, "png", 8, 8, data, 20.0 + k / 9.6))
    assert state.frame_rate() == pytest.approx(9.6)
    assert state.snapshot()["camera"]["fps"] == pytest.approx(9.6)
    state.take_frame(Frame("/rover/camera/image", 99, "png", 8, 8, data, 0.0))  # a new run
    assert state.frame_rate() is None


def test_camera_frames_are_stamped_with_their_simulated_instant(rover_run: RoverRun) -> None:
    with (
        Dashboard(rover_run.model, rover_run.tactics, bus=rover_run.bus, port=0, clock="sim") as d,
        open_bus("inproc", hub=rover_run.hub, name="sim") as sim,
    ):
        data = png(8, 8, (0, 0, 0))
        for k in range(25):
            t = round(30.0 + k / 9.6, 6)
            sim.publish("/clock", Clock(time=t))
            wait_for(lambda t=t: d.state.clock() >= t, what=f"the clock at {t}")
            sim.publish(
                "/rover/camera/image", Image(encoding="png", width=8, height=8, data=data, seq=k)
            )
            wait_for(lambda k=k: d.state.snapshot()["camera"].get("frame", {}).get("seq") == k)
            assert d.state.snapshot()["camera"]["frame"]["t"] == t
        assert d.state.snapshot()["camera"]["fps"] == pytest.approx(9.6)
        assert d.state.latest_t == pytest.approx(30.0 + 24 / 9.6)


def test_port_in_use_is_a_clear_error(state: DashboardState) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        with pytest.raises(
            DashboardError, match=f"port {port} on 127.0.0.1 is in use.*--dashboard-port N"
        ):
            Dashboard(state.model, state.tactics, port=port)


def test_missing_extra_names_the_pip_command(
    state: DashboardState, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "uvicorn", None)
    with pytest.raises(MissingExtraError, match=r"pip install 'anunnaki\[dashboard\]'"):
        Dashboard(state.model, state.tactics, port=0)


def test_core_imports_no_web_framework() -> None:
    code = (
        "import sys, anunnaki, anunnaki.dashboard, anunnaki.cli._dashboard, anunnaki.cli._run;"
        "print(sorted(m for m in ('fastapi', 'uvicorn', 'starlette') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


# -- the command line -----------------------------------------------------------------------
def _dashboard_args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    _dashboard.add_parser(parser.add_subparsers())
    return parser.parse_args(["dashboard", *argv])


def test_cli_refuses_an_inproc_bus_naming_file_and_line() -> None:
    with pytest.raises(ModelFileError) as exc:
        _dashboard.run(_dashboard_args(str(ROVER / "utu.yaml"), "--port", "0"))
    message = str(exc.value)
    assert f"{ROVER / 'utu.yaml'}:" in message
    assert "inproc" in message
    assert "anunnaki run CONFIG --dashboard" in message


def test_cli_joins_the_launch_of_utu_processes_without_taking_its_port() -> None:
    """The documented ways to join ``examples/rover/utu-processes.yaml`` (which listens on
    tcp/127.0.0.1:7447) never listen on 7447 themselves, and ``--mode client`` is accepted."""
    config = str(ROVER / "utu-processes.yaml")

    def bus(*argv: str) -> Any:
        args = _dashboard_args(config, *argv)
        return _dashboard.joining_bus(load_launch(args.config, read_records=False), args)

    for joined in (bus(), bus("--connect", "tcp/127.0.0.1:7447")):
        assert (joined.kind, joined.mode) == ("zenoh", "peer")
        assert joined.connect == ["tcp/127.0.0.1:7447"]
        assert joined.listen == []  # a peer then listens on a free loopback port
        assert joined.effective_listen(free_port=4321) == ["tcp/127.0.0.1:4321"]
    client = bus("--mode", "client")
    assert (client.mode, client.connect, client.listen) == ("client", ["tcp/127.0.0.1:7447"], [])
    assert bus("--mode", "client", "--connect", "tcp/10.0.0.5:7447").connect == [
        "tcp/10.0.0.5:7447"
    ]
    assert bus("--listen", "tcp/127.0.0.1:7999").listen == ["tcp/127.0.0.1:7999"]
    with pytest.raises(BusConfigError, match="a client does not listen"):
        bus("--mode", "client", "--listen", "tcp/127.0.0.1:7999")


def _launch_on(tmp_path: Path, port: int) -> Path:
    """``utu-processes.yaml`` listening on ``port`` (next to a copy of its files)."""
    rover = tmp_path / "rover"
    shutil.copytree(ROVER, rover)
    launch = rover / "utu-processes.yaml"
    launch.write_text(launch.read_text().replace(":7447", f":{port}"))
    return launch


@pytest.mark.parametrize(
    "argv", [(), ("--connect", "tcp/127.0.0.1:{port}"), ("--mode", "client")], ids=str
)
def test_the_joining_session_meets_the_launch_session_on_loopback(
    tmp_path: Path, argv: tuple[str, ...]
) -> None:
    """Two zenoh sessions on loopback (multicast scouting off): the launch's, listening on
    its port, and the dashboard's, opened as ``anunnaki dashboard`` opens it, while the
    launch's holds the port. A message each way arrives."""
    pytest.importorskip("zenoh")
    port = free_port()
    config = _launch_on(tmp_path, port)
    args = _dashboard_args(str(config), *(a.format(port=port) for a in argv))
    launch = load_launch(args.config, read_records=False)
    joined = _dashboard.joining_bus(launch, args)
    assert not joined.multicast_scouting
    got: queue.Queue[tuple[str, Any]] = queue.Queue()
    with open_bus(launch.bus, name="launch") as utu, open_bus(joined, name="dashboard") as dash:
        subs = [
            dash.subscribe("/utu/analyze/state", lambda s: got.put(("dash", s.message))),
            utu.subscribe("/utu/knowledge/query_probe", lambda s: got.put(("utu", s.message))),
        ]

        def heard(who: str, topic: str) -> bool:
            (utu if who == "dash" else dash).publish(topic, {"t": 1.0})  # until the link is up
            try:
                return got.get(timeout=0.2)[0] == who
            except queue.Empty:
                return False

        wait_for(lambda: heard("dash", "/utu/analyze/state"), timeout=60, what="utu -> dashboard")
        wait_for(lambda: heard("utu", "/utu/knowledge/query_probe"), timeout=60, what="dash -> utu")
        for sub in subs:
            sub.close()


def test_cli_bad_config_names_file_and_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        "anunnaki: launch/1\n"
        f"utu: {ROVER / 'utu.yaml'}\n"
        "bus: {kind: zenoh}\n"
        "nodes: [monitor, planner]\n",
        encoding="utf-8",
    )
    with pytest.raises(ModelFileError) as exc:
        _dashboard.run(_dashboard_args(str(bad), "--port", "0"))
    assert f"{bad}:4: nodes" in str(exc.value)


def test_run_with_dashboard_serves_the_rover_run(tmp_path: Path) -> None:
    """``anunnaki run examples/rover/utu.yaml --dashboard``: URL printed, the run's decisions
    on the page, the page kept up after the run until SIGINT (exit 0)."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "anunnaki.cli.main",
            "run",
            str(ROVER / "utu.yaml"),
            "--speed",
            "20",
            "--dashboard",
            "--dashboard-port",
            "0",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
        cwd=tmp_path,
    )
    lines: list[str] = []
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line)
            if "the run has ended" in line:
                break
        url = next(x.split()[1] for x in lines if x.startswith("dashboard: http"))
        client = Web(url)
        want = {("fail-safe", "postcondition_ok"), ("warn-pedestrians", "postcondition_ok")}

        def shown() -> dict | None:
            # The run's last messages reach the dashboard's subscribers after the launcher
            # says the run ended (on a loaded machine, noticeably later): wait for them.
            snap = client.get("/api/snapshot").json()
            runs = {(e["tactic"], e["result"]) for e in snap["executions"]}
            return snap if want <= runs and snap["oracle"] else None

        snap = wait_for(shown, what="both tactics verified on the page")
        assert snap["oracle"][0]["category"] == 1
        # The launch closed the page's observer before Utu's nodes stopped: the badge says
        # the run is over (it once waited for tokens whose withdrawal it could not hear).
        assert snap["run"] == {"live": False, "state": "ended", "reason": "the run has ended"}
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=30) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        if proc.stdout is not None:
            lines.extend(proc.stdout)
            proc.stdout.close()
    assert any("stopped (trace ended): 9 decisions" in x for x in lines), "".join(lines)


def test_setup_browser_script_is_idempotent() -> None:
    need_browser()
    out = subprocess.run(
        ["bash", str(ROOT / "scripts" / "setup-browser.sh")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert out.returncode == 0
    assert out.stdout == ""  # already there: nothing installed, nothing said


def test_example_files_stay_in_sync() -> None:
    # The approval variant keeps the example's tactics (names, priorities) besides its own.
    example = {t.name: t.priority for t in load_tactics(ROVER / "tactics.yaml").tactics}
    variant = {
        t.name: t.priority for t in load_tactics(HERE / "data" / "tactics-approval.yaml").tactics
    }
    assert {k: variant[k] for k in example} == example


# -- the test set-up: the browser tests cannot pass unnoticed --------------------------------
def test_missing_browser_skips_saying_how_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(dashboard_helpers, "CHROMIUM", "/nonexistent/chromium")
    monkeypatch.delenv(REQUIRE_BROWSER, raising=False)
    with pytest.raises(pytest.skip.Exception) as skipped:
        need_browser()
    assert "Chromium is not installed at /nonexistent/chromium" in str(skipped.value)
    assert "scripts/setup-browser.sh" in str(skipped.value)


def test_missing_browser_fails_when_required(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(dashboard_helpers, "CHROMIUM", "/nonexistent/chromium")
    monkeypatch.setenv(REQUIRE_BROWSER, "1")
    with pytest.raises(pytest.fail.Exception) as failed:
        need_browser()
    assert f"{REQUIRE_BROWSER}=1 requires the browser tests" in str(failed.value)
    assert "scripts/setup-browser.sh" in str(failed.value)


def test_required_browser_turns_the_browser_tests_red(tmp_path: Path) -> None:
    """End to end: CI's setting makes a browser test an error, not a skip (exit code 1)."""
    env = {**os.environ, "ANUNNAKI_CHROMIUM": str(tmp_path / "no-chromium")}
    env[REQUIRE_BROWSER] = "1"
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-q",
            "-p",
            "no:cacheprovider",
            "-k",
            "screenshot",
            str(HERE / "test_browser.py"),
        ],
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=120,
        check=False,
    )
    assert out.returncode == 1, out.stdout + out.stderr
    assert "1 error" in out.stdout
    assert "skipped" not in out.stdout
    assert f"{REQUIRE_BROWSER}=1 requires the browser tests" in out.stdout


# -- security -------------------------------------------------------------------------------
def _get_with_host(url: str, host: str | None, path: str = "/api/health") -> tuple[int, bytes]:
    """GET ``path`` from the server at ``url`` with this ``Host`` header (``None``: none)."""
    parts = urllib.parse.urlsplit(url)
    conn = http.client.HTTPConnection(parts.hostname or "", parts.port, timeout=30)
    try:
        conn.putrequest("GET", path, skip_host=True)
        if host is not None:
            conn.putheader("Host", host)
        conn.endheaders()
        r = conn.getresponse()
        return r.status, r.read()
    finally:
        conn.close()


def test_loopback_server_refuses_foreign_host_headers(state: DashboardState) -> None:
    """DNS rebinding: a page of evil.example whose name resolves to 127.0.0.1 gets 400."""
    client = Web.serve(create_app(state))
    port = urllib.parse.urlsplit(client.url).port
    for host in ("evil.example", f"evil.example:{port}", f"127.0.0.1.evil.example:{port}", ""):
        status, body = _get_with_host(client.url, host)
        assert status == 400, host
        assert b"invalid host header" in body.lower()
    for path in ("/", "/api/snapshot", "/api/events", "/static/dashboard.js"):
        assert _get_with_host(client.url, f"evil.example:{port}", path)[0] == 400, path
    assert _get_with_host(client.url, None)[0] == 400
    for host in (f"127.0.0.1:{port}", f"localhost:{port}", "LOCALHOST", f"[::1]:{port}"):
        status, body = _get_with_host(client.url, host)
        assert status == 200, host
        assert json.loads(body)["ok"] is True


def test_server_on_all_interfaces_accepts_any_host_and_the_cli_warns(
    capsys: pytest.CaptureFixture[str],
) -> None:
    launch = load_launch(ROVER / "utu.yaml", read_records=False)
    quiet = _dashboard.dashboard_for_launch(launch, port=0)
    try:
        assert quiet.server.loopback
        assert capsys.readouterr().err == ""
    finally:
        quiet.close()
    exposed = _dashboard.dashboard_for_launch(launch, host="0.0.0.0", port=0)
    try:
        err = capsys.readouterr().err
        assert "dashboard: warning: serving on 0.0.0.0, not only on this machine" in err
        assert f"anyone who can reach port {exposed.server.port} can watch the run" in err
        assert "give it a --token" in err
        exposed.start()
        local = f"http://127.0.0.1:{exposed.server.port}/"
        assert _get_with_host(local, "dashboard.example.org")[0] == 200  # no name to check
    finally:
        exposed.close()
    assert not is_loopback("0.0.0.0")
    assert not is_loopback("10.1.2.3")
    assert not is_loopback("rover.local")
    assert is_loopback("127.0.0.1")
    assert is_loopback("127.0.0.2")
    assert is_loopback("::1")
    assert is_loopback("localhost")
    assert loopback_names("127.0.0.2") == ["127.0.0.1", "127.0.0.2", "[::1]", "localhost"]
    assert loopback_names("::1") == ["127.0.0.1", "[::1]", "localhost"]


def test_cli_serves_on_loopback_by_default() -> None:
    assert _dashboard_args(str(ROVER / "utu.yaml")).host == "127.0.0.1"
    parser = argparse.ArgumentParser()
    _dashboard.add_run_options(parser)
    assert parser.parse_args([]).dashboard_host == "127.0.0.1"


# -- anunnaki dashboard on zenoh --------------------------------------------------------------
def _lines(stream: Any) -> queue.Queue[str | None]:
    """The lines of a subprocess's output as they come (``None`` at the end)."""
    out: queue.Queue[str | None] = queue.Queue()

    def pump() -> None:
        for line in stream:
            out.put(line)
        out.put(None)

    threading.Thread(target=pump, daemon=True).start()
    return out


def _next_line(lines: queue.Queue[str | None], prefix: str, seen: list[str]) -> str:
    deadline = time.monotonic() + 60
    while (left := deadline - time.monotonic()) > 0:
        try:
            line = lines.get(timeout=left)
        except queue.Empty:
            break
        if line is None:
            break
        seen.append(line)
        if line.startswith(prefix):
            return line
    raise AssertionError(f"no line starting {prefix!r} in:\n{''.join(seen)}")


@pytest.mark.slow
def test_cli_dashboard_serves_what_a_zenoh_bus_carries(tmp_path: Path) -> None:
    """``anunnaki dashboard utu-processes.yaml --mode client`` in its own process joins the
    launch's zenoh session (loopback TCP, no multicast scouting), held by a stand-in for Utu
    that listens on the launch's port and publishes; its page's snapshot shows it."""
    pytest.importorskip("zenoh")
    port = free_port()
    config = _launch_on(tmp_path, port)
    model = load_goal_model(ROVER / "goals.yaml", ROVER / "binding.yaml")
    nodes = {n: [1.0, "satisfied"] for n in [*model.goals, *model.obstacles]}
    for n in ("G1", "G2", "G3", "G4"):
        nodes[n] = [0.0, "unsatisfied"]
    analysis = {
        "t": 25.2,
        "root": "G1",
        "nodes": nodes,
        "violated": ["G1", "G2", "G3", "G4"],
        "tactics": ["fail-safe"],
        "queue": [{"tactic": "fail-safe", "priority": 100, "state": "pending", "deadline": None}],
        "paused": False,
        "run_stopped": False,
    }
    decision = {"id": 7, "t": 25.2, "kind": "pending_approval", "tactic": "fail-safe", "data": {}}
    forged = {"id": 8, "t": 25.3, "kind": "run_stop", "tactic": None, "data": {}}

    def query(message: Any) -> dict[str, Any]:  # Utu's knowledge service: the real log
        after = body_of(message).get("after") or 0
        return {"ok": True, "decisions": [decision] if after < decision["id"] else []}

    with open_bus(
        "zenoh", listen=[f"tcp/127.0.0.1:{port}"], multicast_scouting=False, name="utu"
    ) as utu:
        utu.service("/utu/knowledge/query", query)
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "anunnaki.cli.main",
                "dashboard",
                str(config),
                "--mode",
                "client",
                "--port",
                "0",
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        seen: list[str] = []
        assert proc.stdout is not None
        lines = _lines(proc.stdout)
        try:
            url = _next_line(lines, "dashboard: http", seen).split()[1]
            assert url.startswith("http://127.0.0.1:")  # the default host
            _next_line(lines, "dashboard: observing rover on bus", seen)
            client = Web(url)

            def shown() -> dict | None:
                utu.publish("/utu/analyze/state", analysis)  # until the link is up
                # Any client may publish on the decisions topic: the page shows only what
                # Utu's knowledge service holds (issue #12), never the forged run-stop.
                utu.publish(DECISIONS_TOPIC, {"decisions": [decision, forged]})
                snap = client.get("/api/snapshot").json()
                ok = snap["goal_source"] == "utu" and snap["decisions"]
                return snap if ok and snap["goals"]["G1"] == [0.0, "unsatisfied"] else None

            snap = wait_for(shown, timeout=60, what="the bus's analysis on the page")
            assert snap["analysis"]["violated"] == ["G1", "G2", "G3", "G4"]
            assert snap["analysis"]["eligible"] == ["fail-safe"]
            assert snap["analysis"]["queue"][0]["tactic"] == "fail-safe"
            assert snap["analysis"]["t"] == 25.2
            assert snap["goals"]["O1"] == [1.0, "satisfied"]
            # Published again and again, the decision is shown once.
            assert [d["kind"] for d in snap["decisions"]] == ["pending_approval"]
            assert client.get("/api/health").json()["operator"] is False  # no token: read-only
            proc.send_signal(signal.SIGINT)
            assert proc.wait(timeout=30) == 0
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            while (line := lines.get(timeout=30)) is not None:  # the output to its end
                seen.append(line)
            proc.stdout.close()
        assert "dashboard: stopped\n" in seen, "".join(seen)
