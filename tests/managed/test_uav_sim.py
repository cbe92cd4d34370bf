"""The UAV demo under Utu (examples/uav/sim.yaml, issue #24 item 2), on a shortened scenario.

The launch file as shipped (goals, binding, tactics, the learned ``enlil`` oracle as A4, the
ground-truth oracle as its live scorer, the shipped uav-default/uav-fog models) flies a
short delivery from the ground: a fast climb, one waypoint, rain under changed light
(rain+brightness) from t = 3 s to 6 s, dense fog from t = 7 s, and a battery that starts
draining fast at t = 10 s. The UAV takes off (no tactic keeps it on the ground: G3 applies
only while it cruises), Utu swaps in the Enki rain+brightness model, then, named by that
model's own oracle, the fog model (G6 holds again after each). In the dense fog at cruise
uav-fog itself loses over 10 % F1 through the camera's JPEG: its oracle (trained through
the same encoding, issue 34 item 8) calls it compromised, as the live scorer does, and
Failsafe F-1 hovers the UAV. The draining battery then makes it return home: the battery
forecast at home after the rest of the mission (A3.after_mission, from the drain of the last
5 s) falls below the 5 % reserve, G15 fails long before obstacle O2 (20 %), and G8 then holds
only through G10.
"""

from __future__ import annotations

import io
import json
import threading
import urllib.request
from pathlib import Path
from typing import Any

import pytest
import yaml

from anunnaki import topics
from anunnaki.cli._dashboard import dashboard_for_launch
from anunnaki.launch import load_launch, run_launch
from anunnaki.managed import SimKind
from anunnaki.messages import Assessment, body_of

ROOT = Path(__file__).parents[2]
UAV = ROOT / "examples" / "uav"

#: 16 s from the ground: climb at 10 m/s to 30 m (3 s), one waypoint, the demo's
#: rain+brightness (examples/uav/demo-scenario.yaml) from 3 s to 6 s, fog from 7 s (dense by
#: 8 s: uav-default's F1 falls far, uav-fog copes), a 45 % battery draining 4 %/s more from
#: 10 s (below 30 % about 3 s later, below O2's 20 % about 2 s after that).
#: The demo's rain+brightness context (a category-1 context of uav-default's search).
RAIN = next(
    p["params"]
    for p in yaml.safe_load((UAV / "demo-scenario.yaml").read_text())["phenomena"]
    if p["phenomenon"] == "rain+brightness"
)
SHORT: dict[str, Any] = {
    "anunnaki": "scenario/1",
    "platform": "uav",
    "name": "short-delivery",
    "layout": 0,
    "seed": 0,
    "duration": 16,
    "camera": {"rate": 10, "width": 320, "height": 240, "encoding": "jpeg"},
    "mission": {
        "home": [0, 0],
        "waypoints": [[-20, 10], [10, 25]],
        "delivery": [25, -15],
        "cruise_altitude": 30,
        "speed": 8,
        "climb_rate": 10,
        "battery": 45,
    },
    "phenomena": [
        {"at": 3, "phenomenon": "rain+brightness", "params": RAIN, "ramp": 0.5, "until": 6},
        {"at": 7, "phenomenon": "fog", "strength": 0.7, "ramp": 1},
    ],
    "faults": [{"at": 10, "fault": "battery_drain", "rate": 4}],
}


def run_short(tmp: Path, scenario: dict[str, Any]) -> dict[str, Any]:
    """examples/uav/sim.yaml on *scenario* at 1000× (one thread): result, log, UAV statuses."""
    (tmp / "scenario.yaml").write_text(yaml.safe_dump(scenario))
    launch = load_launch(UAV / "sim.yaml")
    assert isinstance(launch.managed, SimKind)
    launch.managed.options = launch.managed.options.model_copy(
        update={"scenario": str(tmp / "scenario.yaml")}
    )
    statuses: list[dict[str, Any]] = []
    scored: list[Assessment] = []
    said: list[Assessment] = []
    clean: list[int] = []
    lock = threading.Lock()

    def keep(sample: Any) -> None:
        with lock:
            statuses.append(body_of(sample.message))

    def keep_score(sample: Any) -> None:
        with lock:
            scored.append(sample.message)

    def keep_said(sample: Any) -> None:
        with lock:
            said.append(sample.message)

    def keep_clean(sample: Any) -> None:
        with lock:
            clean.append(sample.message.seq)

    # the dashboard, as `anunnaki run examples/uav/sim.yaml --dashboard` attaches it
    dashboard = dashboard_for_launch(launch, port=0)
    dashboard.start()

    def attach(bus: Any) -> None:
        dashboard.attach(bus)
        bus.subscribe("/uav/status", keep, queue=1024)
        bus.subscribe(topics.SCORER, keep_score, queue=1024)
        bus.subscribe(topics.ORACLE_OUTPUT, keep_said, queue=1024)
        bus.subscribe(topics.CLEAN_FRAMES, keep_clean, queue=1024)

    out = io.StringIO()
    try:
        result = run_launch(launch, speed=1000, out=out, handle_signals=False, on_bus=attach)
        with urllib.request.urlopen(dashboard.url.rstrip("/") + "/api/snapshot") as reply:
            snapshot = json.loads(reply.read())
    finally:
        dashboard.close()
    with lock:
        seen, scores, renders, oracle = list(statuses), list(scored), list(clean), list(said)
    return {
        "result": result,
        "log": out.getvalue(),
        "statuses": seen,
        "snapshot": snapshot,
        "scorer": scores,
        "oracle": oracle,
        "clean": renders,
    }


@pytest.fixture(scope="module")
def short_run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    return run_short(tmp_path_factory.mktemp("uav"), SHORT)


def started(run: dict[str, Any]) -> list[tuple[float, str]]:
    return [(d.t, d.tactic) for d in run["result"].decisions if d.kind == "started"]


@pytest.mark.timeout(600)  # 160 frames at 320x240: about 40 s on a quiet machine
def test_the_uav_takes_off_with_utu_in_the_loop(short_run: dict[str, Any]) -> None:
    result, log = short_run["result"], short_run["log"]
    assert result.exit_code == 0, log
    statuses = short_run["statuses"]
    assert statuses[0]["altitude"] == 0.0 and statuses[0]["phase"] == "takeoff"
    top = max(s["altitude"] for s in statuses)
    assert top == pytest.approx(30.0, abs=0.5), top  # it climbed to cruise altitude
    # G3 applies while cruising: nothing answered the climb with a hover.
    assert all(tactic != "hold-route" for _, tactic in started(short_run)), started(short_run)
    assert "waypoint 1" in {s["phase"] for s in statuses}


def swaps(run: dict[str, Any], tactic: str) -> list[tuple[float, dict[str, Any]]]:
    return [
        (d.t, d.data) for d in run["result"].decisions if d.kind == "action" and d.tactic == tactic
    ]


@pytest.mark.timeout(600)
def test_rain_brightness_on_the_way_swaps_in_its_model(short_run: dict[str, Any]) -> None:
    result, log = short_run["result"], short_run["log"]
    rain = swaps(short_run, "swap-to-rain_brightness-model")
    assert len(rain) == 1 and 3.0 <= rain[0][0] < 6.0, rain  # uav-default's oracle names it
    assert rain[0][1]["ok"] is True and rain[0][1]["domain"] == "rain_brightness"
    verified = [d.tactic for d in result.decisions if d.kind == "postcondition_ok"]
    assert "swap-to-rain_brightness-model" in verified, log  # G6 holds with its model
    assert "uav-rain_brightness" in log  # the per-phase table names the models that ran


@pytest.mark.timeout(600)
def test_fog_near_the_target_swaps_in_uav_fog(short_run: dict[str, Any]) -> None:
    result, log = short_run["result"], short_run["log"]
    fog = swaps(short_run, "swap-to-robust-model")
    # after rain+brightness, uav-rain_brightness is active: its own oracle names the fog
    rain = swaps(short_run, "swap-to-rain_brightness-model")
    assert len(fog) == 1 and 7.0 <= fog[0][0] < 11.0 and rain[0][0] < fog[0][0], (fog, rain)
    assert fog[0][1]["ok"] is True and fog[0][1]["domain"] == "fog"
    verified = [d.tactic for d in result.decisions if d.kind == "postcondition_ok"]
    assert "swap-to-robust-model" in verified, log  # G6 holds again: G9 resolves O1
    assert "uav-fog" in log
    # but uav-fog's own oracle then calls the dense fog compromised (the scorer agrees, below):
    # G5 fails and Failsafe F-1 hovers the UAV, once, soon after the swap
    failsafe = [t for t, tactic in started(short_run) if tactic == "failsafe-f1"]
    assert len(failsafe) == 1 and fog[0][0] < failsafe[0] < fog[0][0] + 3.0, log
    hover = [s["t"] for s in short_run["statuses"] if s["mode"] == "hover"]
    assert hover and failsafe[0] <= hover[0] < failsafe[0] + 0.5, log


@pytest.mark.timeout(600)
def test_the_live_scorer_compares_uav_fog_with_the_frames_without_fog(
    short_run: dict[str, Any],
) -> None:
    """The launch's scorer (``reference: paired``, ``sparse: withhold``; issue 34 item 8):
    uav-fog's F1 over its last 30 frames against its F1 on the same frames as rendered
    without the fog. In the dense fog at cruise (about 10.5-13.5 s here) uav-fog scores
    over 10 % below that: compromised, 32 frames in a row. Against its registry F1 (its test
    split's, 0.894, lower than on these frames) the scorer called one of them compromised,
    the others degraded or unaffected. Nothing is said for a window of fewer than 20
    objects (on the ground at the start, nobody is in view)."""
    renders = short_run["clean"]
    assert renders and len(renders) == len(set(renders))  # one clean render per frame
    fog = [a for a in short_run["scorer"] if a.model_id == "uav-fog"]
    assert len(fog) >= 30, short_run["scorer"]
    compromised = [a.frame_seq for a in fog if a.category == 2]
    assert len(compromised) >= 20, [(a.frame_seq, a.category) for a in fog]
    assert all(a.confidence >= 20 / 30 for a in short_run["scorer"])  # min_frames / window


@pytest.mark.timeout(600)
def test_uav_fog_s_oracle_agrees_with_the_scorer_in_the_dense_fog(
    short_run: dict[str, Any],
) -> None:
    """Issue 34 item 8: uav-fog's oracle said "degraded" (a 4 % drop) where its live scorer
    said compromised: its contexts had been measured, and it had been trained, on frames
    that never went through the camera's JPEG, which takes more from a fogged frame than
    the fog alone. Trained through the camera's encoding, it agrees with the scorer on the
    frames both assessed while uav-fog flew in the dense fog at cruise altitude (in the
    landing's descent at home, where the battery forecast's return brings the UAV before the
    run ends, the scene below changes with the altitude: the scorer says degraded there
    where the oracle still says compromised)."""
    statuses = short_run["statuses"]

    def landing(seq: int) -> bool:  # the frame's time: seq / the camera's rate
        before = [st for st in statuses if st["t"] <= seq / SHORT["camera"]["rate"] + 1e-9]
        return bool(before) and before[-1]["phase"] == "landing"

    scorer = {a.frame_seq: a.category for a in short_run["scorer"] if a.model_id == "uav-fog"}
    oracle = {a.frame_seq: a.category for a in short_run["oracle"] if a.model_id == "uav-fog"}
    both = sorted(s for s in set(scorer) & set(oracle) if not landing(s))
    assert len(both) >= 30, (scorer, oracle)
    agree = sum(scorer[s] == oracle[s] for s in both)
    assert agree >= 0.9 * len(both), [(s, scorer[s], oracle[s]) for s in both]


@pytest.mark.timeout(600)
def test_low_battery_sends_the_uav_home(short_run: dict[str, Any]) -> None:
    result, statuses = short_run["result"], short_run["statuses"]
    home = [t for t, tactic in started(short_run) if tactic == "return-home"]
    assert len(home) == 1 and home[0] >= 10.0, started(short_run)
    action = next(d for d in result.decisions if d.kind == "action" and d.tactic == "return-home")
    assert action.data["ok"] is True and action.data["mode"] == "return_home", action.data
    assert "return-home" in [d.tactic for d in result.decisions if d.kind == "postcondition_ok"]
    after = [s for s in statuses if s["t"] > home[0] + 0.5]
    assert after and all(s["mode"] == "return_home" for s in after)  # it flies home
    # the forecast turned it, not the level: the battery still read above O2's 20 %
    assert min(s["battery"] for s in statuses if s["t"] <= home[0]) > 20.0
    # the mission's outcome, printed under the per-phase table
    assert (
        "mission: took off at t = 0.0 s; package not delivered; still airborne" in short_run["log"]
    )


@pytest.mark.timeout(600)
def test_the_dashboard_shows_the_uav_run(short_run: dict[str, Any]) -> None:
    """The page's snapshot at the end of the run: the UAV's goal model with G13/G14, its
    camera feed with the detector's boxes, the fog model active, the enlil oracle, the swap."""
    snap = short_run["snapshot"]
    assert snap["structure"]["root"] == "G1"
    assert {"G13", "G14", "O1", "O2"} <= set(snap["goals"])
    camera = snap["camera"]
    assert camera["frame"]["topic"] == "/uav/camera/image"
    assert (camera["frame"]["width"], camera["frame"]["height"]) == (320, 240)
    assert camera["active"]["model"] == "uav-fog" and camera["detections"]["model_id"] == "uav-fog"
    assert {o["assessor"] for o in snap["oracle"]} == {"enlil"}
    tactics = [e["tactic"] for e in snap["executions"]]
    assert "swap-to-robust-model" in tactics and "return-home" in tactics
