"""Generate ``trace.jsonl``: the rover's sensors through nominal and violated phases.

Run ``python examples/rover/make_trace.py`` to rebuild the trace (it is deterministic).

Phases (times in seconds):

* 0–10   nominal: autonomous, ultrasonic at 10 Hz, oracle category 0.
* 10–20  the ultrasonic rate sags to 4.8 Hz: the RELAX-ed G6 (0 at 4.5 Hz, 1 at 5 Hz,
         threshold 0.5) stays satisfied with utility 0.6, where a crisp ``rate(A3) >= 5.0``
         would be violated.
* 20–25  a pedestrian comes within 0.8 m and the buzzer sounds: G13 fails, G14 holds, so
         G12 (warn pedestrians) stays satisfied.
* 25–35  light dims: the oracle reports category 1, obstacle O1 holds, G4, G3, G2 and G1
         become unsatisfied.
* 35–45  the rover is in manual mode (what the fail-safe tactic does): G3 is satisfied
         through G11 while A4.category stays 1, and G1 is satisfied again.
* 45–50  the ultrasonic sensor falls silent: its range goes stale (unknown) and its rate
         decays; G12 and G1 become unknown (grey), then G6 unsatisfied.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "src"))

from anunnaki.trace import Phase, Record, write_trace

END = 50.0


def build() -> list[Record | Phase]:
    items: list[Record | Phase] = []

    def at(t: float, topic: str, msg: dict[str, object]) -> None:
        items.append(Record(round(t, 4), topic, msg))

    phases = [
        (0.0, "nominal", "autonomous, ultrasonic at 10 Hz, oracle category 0"),
        (10.0, "ultrasonic-4.8Hz", "the ultrasonic rate sags to 4.8 Hz (RELAX-ed G6 holds)"),
        (20.0, "pedestrian-near", "a pedestrian within 0.8 m; the buzzer sounds"),
        (25.0, "dim-light", "light dims: the oracle reports category 1 (O1 holds)"),
        (35.0, "manual", "the rover is switched to manual mode (the fail-safe)"),
        (45.0, "ultrasonic-silent", "the ultrasonic sensor stops publishing"),
    ]
    for t, name, note in phases:
        items.append(Phase(t, name, note))

    def mode(t: float) -> str:
        return "manual" if t >= 35.0 else "autonomous"

    # A1: controller status at 2 Hz.
    for k in range(int(END * 2)):
        t = k / 2
        warning = 20.0 <= t < 25.5  # the buzzer sounds until the way is clear
        at(
            t,
            "/rover/status",
            {"mode": mode(t), "buzzer": warning, "bumper": False, "lights": True},
        )
    # A2: camera metadata at 5 Hz (pixels never go into a trace).
    for k in range(int(END * 5)):
        at(k / 5, "/rover/camera/info", {"seq": k, "width": 128, "height": 128})
    # A3: ultrasonic at 10 Hz, then 4.8 Hz from t = 10, then silent from t = 45.
    t = 0.0
    while t < 45.0:
        rng = 0.8 if 20.0 <= t < 25.0 else 3.0
        at(t, "/rover/ultrasonic", {"range": rng})
        t += 0.1 if t < 10.0 - 1e-9 else 1 / 4.8
    # A4: oracle at 2 Hz.
    for k in range(int(END * 2)):
        t = k / 2
        category = 1 if t >= 25.0 else 0
        at(t, "/utu/oracle/output", {"category": category, "confidence": 0.9})
    items.sort(key=lambda r: (r.t, isinstance(r, Record)))
    return items


def main() -> None:
    out = Path(__file__).with_name("trace.jsonl")
    header = {
        "name": "rover-phases",
        "description": "the rover through nominal and violated phases",
    }
    write_trace(out, build(), header)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
