"""The dashboard without a browser: state, HTTP API, token checks, server-sent events, CLI."""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from dashboard_helpers import HERE, ROOT, ROVER, TOKEN, RoverRun, Web, png

from anunnaki.bus import Detections, Image, open_bus
from anunnaki.cli import _dashboard
from anunnaki.dashboard import (
    Dashboard,
    DashboardError,
    DashboardState,
    create_app,
)
from anunnaki.errors import MissingExtraError, ModelFileError
from anunnaki.goals import load_goal_model
from anunnaki.tactics import load_tactics


def wait_for(predicate, timeout: float = 30.0, what: str = "condition"):
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.02)


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


def test_operator_with_token_is_logged_by_utu_with_its_caller(rover_run: RoverRun) -> None:
    rover_run.run_to(3.0)
    with Dashboard(rover_run.model, rover_run.tactics, bus=rover_run.bus, port=0, token=TOKEN):
        pass  # a dashboard starts and stops cleanly around a live bus
    dash = Dashboard(rover_run.model, rover_run.tactics, bus=rover_run.bus, port=0, token=TOKEN)
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
        wait_for(lambda: dash.state.snapshot()["camera"].get("detections"), what="detections")
        r = Web(dash.url).get("/api/frame/7")
        assert r.status_code == 200
        assert r.headers["content-type"] == "image/png"
        assert r.content == data
        camera = dash.state.snapshot()["camera"]
        assert camera["frame"]["seq"] == 7
        assert camera["detections"]["labels"] == ["person"]
        assert camera["active"]["model"] == "centernet-fog"


def test_port_in_use_is_a_clear_error(state: DashboardState) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        with pytest.raises(DashboardError, match=f"port {port} on 127.0.0.1 is in use"):
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
        snap = Web(url).get("/api/snapshot").json()
        runs = {(e["tactic"], e["result"]) for e in snap["executions"]}
        assert ("fail-safe", "postcondition_ok") in runs
        assert ("warn-pedestrians", "postcondition_ok") in runs
        assert snap["oracle"][0]["category"] == 1
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
    if not Path("/usr/bin/chromium").exists():
        pytest.skip("Chromium is not installed")
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
