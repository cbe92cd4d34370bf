"""Generate ``trace.jsonl``: the UAV's delivery mission through nominal and violated phases.

Run ``python examples/uav/make_trace.py`` to rebuild the trace (it is deterministic).

Phases (times in seconds):

* 0-20   nominal cruise at 30 m, GPS at 10 Hz, camera at 10 Hz, oracle category 0.
* 20-30  gusts push the UAV to 36 m, then 34 m. The RELAX-ed altitude goal G3 (30 m
         +- 10 m, threshold 0.5) gives 1 - 6/10 = 0.4 at 36 m, a violation, but
         1 - 4/10 = 0.6 at 34 m, which still counts as satisfied (a crisp "altitude == 30"
         would have failed throughout).
* 30-40  fog: the oracle reports category 1 with context "fog"; O1 holds and G6 fails,
         until the fog-robust model is active (A6.domain = fog from t = 33): resolution
         goal G9 is satisfied and G6 holds again.
* 40-50  dense fog: category 2; G9 no longer resolves O1, G6 and G5 fail, G1 is violated.
* 50-60  Failsafe F-1: the UAV hovers; G5 is satisfied through G7.
* 60-70  the battery sags below 20 %: O2 holds, and the battery forecast at home (A3.after_mission,
         from the drain of the last 5 s over the 100 m still to fly at 6 m/s) falls far below
         the 5 % reserve: G15 and G8 fail.
* 70-80  the UAV returns home: G8 is satisfied through G10 (and G7 still holds).
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "src"))

from anunnaki.trace import Phase, Record, write_trace

END = 80.0


def mode(t: float) -> str:
    return "return_home" if t >= 70 else "hover" if t >= 50 else "auto"


def phase(mode: str) -> str:
    """The simulated UAV's ``phase`` in that mode: cruising on the leg to the target."""
    return {"auto": "to delivery", "hover": "hover", "return_home": "return"}[mode]


def altitude(t: float) -> float:
    if 20 <= t < 25:
        return 36.0
    if 25 <= t < 30:
        return 34.0
    return 30.0


def route_m(t: float) -> float:
    """Metres at cruise speed still to fly: 400 at take-off, 6 m/s off while flying on."""
    return 400.0 - 6.0 * min(t, 50.0)


def oracle(t: float) -> tuple[int, str]:
    """The oracle's category and context at ``t``: fog from 30 s, dense from 40 s."""
    if 30 <= t < 40:
        return 1, "fog"
    if t >= 40:
        return 2, "fog"
    return 0, "clear"


def build() -> list[Record | Phase]:
    items: list[Record | Phase] = []

    def at(t: float, topic: str, msg: dict[str, object]) -> None:
        items.append(Record(round(t, 4), topic, msg))

    for t, name, note in [
        (0.0, "nominal", "cruise at 30 m, GPS and camera at 10 Hz, category 0"),
        (20.0, "gusts", "gusts push the UAV to 36 m, then 34 m (RELAX-ed G3)"),
        (30.0, "fog", "fog: category 1, context fog; the fog-robust model is active at 33 s"),
        (40.0, "dense-fog", "dense fog: category 2, the robust model no longer suffices"),
        (50.0, "failsafe-f1", "the UAV hovers (Failsafe F-1)"),
        (60.0, "low-battery", "the battery falls below 20 %"),
        (70.0, "return-home", "the UAV returns home"),
    ]:
        items.append(Phase(t, name, note))

    for k in range(int(END * 2)):  # A1 status at 2 Hz
        t = k / 2
        status = {"mode": mode(t), "altitude": altitude(t), "delivered": False}
        status |= {"route_m": route_m(t), "home_m": 150.0, "cruise_speed": 6.0}
        at(t, "/uav/status", {**status, "phase": phase(mode(t))})
    for k in range(int(END * 10)):  # A2 camera metadata and A5 GPS at 10 Hz
        t = k / 10
        at(t, "/uav/camera/info", {"seq": k, "width": 320, "height": 240})
        at(t, "/uav/gps", {"lat": 42.7 + t * 1e-5, "lon": -84.48 + t * 1e-5})
    for k in range(int(END)):  # A3 battery at 1 Hz
        t = float(k)
        level = 15.0 if t >= 60 else 80.0 - 0.5 * t
        at(t, "/uav/battery", {"level": level})
    for k in range(int(END * 2)):  # A4 oracle at 2 Hz
        t = k / 2
        category, context = oracle(t)
        at(
            t,
            "/utu/oracle/output",
            {"category": category, "confidence": 0.8, "context": {"phenomenon": context}},
        )
    for k in range(int(END / 2)):  # A6 active model every 2 s
        t = k * 2.0
        domain = "fog" if t >= 33 else "default"
        at(t, "/lm_manager/active", {"model": f"detector-{domain}", "domain": domain})
    at(33.0, "/lm_manager/active", {"model": "detector-fog", "domain": "fog"})
    for k in range(int(END)):  # A7 link heartbeat at 1 Hz
        at(float(k), "/uav/link", {"connected": True})
    items.sort(key=lambda r: (r.t, isinstance(r, Record)))
    return items


def main() -> None:
    out = Path(__file__).with_name("trace.jsonl")
    header = {"name": "uav-delivery", "description": "the UAV mission through adverse phases"}
    write_trace(out, build(), header)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
