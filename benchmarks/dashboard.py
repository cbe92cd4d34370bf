"""The dashboard under load: 300 goals at 10 Hz and 10 Hz camera frames, in headless Chromium.

What runs (one Python process, plus Chromium):
    * a generated goal model of 300 goals (root G1, AND of 20 sub-goals of 14 leaves each);
    * a publisher on its own in-process bus session (the same hub as the dashboard's),
      publishing at 10 Hz a ``/utu/analyze/state`` with all 300 utilities changing, a
      320×240 PNG camera frame (``Image``, ~190 KB: incompressible noise) and its
      ``Detections`` (3 boxes);
    * the dashboard (``anunnaki.dashboard.Dashboard``: observer, FastAPI, uvicorn) serving
      one page in Debian's headless Chromium through Playwright.

Measured, for ``--seconds`` (default 60):
    * the interval between ``requestAnimationFrame`` callbacks on the page (p50/p95/p99/max):
      how smooth the page stays while it applies the patches, redraws the tree, the panes,
      the timeline and the camera;
    * how many distinct camera frames the page drew per second (a frame is painted again
      when its detections arrive after it);
    * the latency from a violation published on the bus (G1 unsatisfied in the next
      analysis, published at once) to G1 turning red on the page: the page stamps the class
      change with ``performance.timeOrigin + performance.now()`` (a MutationObserver), this
      process stamps the publication with ``time.time()``: one machine, one wall clock.
      A violation every 5 s, held for 2 s;
    * with the assurance case pane (on unless ``--no-case``): the case of the same 300-goal
      model (``anunnaki.assurance.case_from_model``: every leaf undeveloped, no evidence to
      read) evaluated live by a ``CaseMonitor`` on its own bus session, as ``anunnaki run``
      does, and drawn in the page's case pane; the latency from the same violation on the bus
      to the claim G1 drawn red there (the monitor evaluates the analysis, publishes
      ``/utu/assurance/state``, the dashboard patches the page, the page recolours
      ``g#gsn-G1``: stamped as above).

Results go to benchmarks/results/dashboard.json.

    python benchmarks/dashboard.py [--seconds 60] [--no-case] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import platform
import random
import statistics
import struct
import tempfile
import threading
import time
import zlib
from pathlib import Path
from typing import Any

from playwright.sync_api import sync_playwright

from anunnaki.assurance import CaseMonitor, LiveCase, case_from_model, propagate, render_svg
from anunnaki.bus import InprocHub, open_bus
from anunnaki.dashboard import Dashboard
from anunnaki.goals import parse_goal_model
from anunnaki.messages import Detections, Image
from anunnaki.tactics import TacticSet

ROOT = Path(__file__).resolve().parent.parent
CHROMIUM = os.environ.get("ANUNNAKI_CHROMIUM", "/usr/bin/chromium")
GROUPS, LEAVES = 20, 14  # G1, 20 sub-goals, 279 leaves (14 per sub-goal, 13 in the last): 300


def model_text() -> str:
    lines = [
        "anunnaki: goal-model/1",
        "name: bench-300",
        "root: G1",
        "agents:",
        "  - id: A1",
        "    topics:",
        "      - topic: /bench/status",
        "        attributes: [v]",
        "goals:",
    ]
    groups = [f"G{2 + g}" for g in range(GROUPS)]
    lines += ["  - id: G1", "    refinement: and", f"    children: [{', '.join(groups)}]"]
    n = 2 + GROUPS
    count = 1 + GROUPS
    for g in groups:
        kids = []
        for _ in range(LEAVES):
            if count >= 300:
                break
            kids.append(f"G{n}")
            n += 1
            count += 1
        lines += [f"  - id: {g}", "    refinement: and", f"    children: [{', '.join(kids)}]"]
        for k in kids:
            lines += [f"  - id: {k}", "    utility: A1.v >= 0", "    agents: [A1]"]
    return "\n".join(lines) + "\n"


def noise_png(width: int, height: int, rng: random.Random) -> bytes:
    raw = b"".join(b"\x00" + rng.randbytes(width * 3) for _ in range(height))

    def chunk(kind: bytes, data: bytes) -> bytes:
        crc = zlib.crc32(kind + data) & 0xFFFFFFFF
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(raw, 1))
        + chunk(b"IEND", b"")
    )


def pct(values: list[float], q: float) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, max(0, round(q / 100 * (len(s) - 1))))]


def summary(values: list[float]) -> dict[str, float]:
    return {
        "n": len(values),
        "p50": round(pct(values, 50), 2),
        "p95": round(pct(values, 95), 2),
        "p99": round(pct(values, 99), 2),
        "max": round(max(values), 2),
        "mean": round(statistics.fmean(values), 2),
    }


RECORDER = """
() => {
  window.__raf = [];
  (function tick(t) { window.__raf.push(t); requestAnimationFrame(tick); })(performance.now());
  window.__red = [];
  window.__frames = new Set();
  const g1 = document.querySelector('#goal-svg [data-node=G1]');
  let red = false;
  new MutationObserver(() => {
    const now = g1.classList.contains('unsatisfied');
    if (now && !red) window.__red.push(performance.timeOrigin + performance.now());
    red = now;
  }).observe(g1, {attributes: true, attributeFilter: ['class']});
  window.__caseRed = [];
  const claim = document.querySelector('#case-drawing g#gsn-G1');
  if (claim) {
    let was = false;
    new MutationObserver(() => {
      const now = claim.dataset.status === 'violated';
      if (now && !was) window.__caseRed.push(performance.timeOrigin + performance.now());
      was = now;
    }).observe(claim, {attributes: true, attributeFilter: ['data-status']});
  }
  const cam = document.getElementById('camera');
  new MutationObserver(() => { window.__frames.add(cam.dataset.seq); })
    .observe(cam, {attributes: true, attributeFilter: ['data-seq']});
}
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "dashboard.json"))
    ap.add_argument("--no-case", action="store_true", help="without the assurance case pane")
    args = ap.parse_args()
    model = parse_goal_model(model_text(), source="<bench-300>")
    goals = list(model.goals)
    assert len(goals) == 300, len(goals)
    rng = random.Random(7)
    frames = [noise_png(320, 240, rng) for _ in range(4)]
    hub = InprocHub()
    dash_bus = open_bus("inproc", hub=hub, name="dashboard")
    pub_bus = open_bus("inproc", hub=hub, name="bench")
    dash = Dashboard(model, TacticSet(tactics=[]), bus=dash_bus, port=0, seed=False)
    monitor = None
    case_bus = None
    if not args.no_case:
        case = case_from_model(model, name="bench-300")
        propagate(case)
        case_bus = open_bus("inproc", hub=hub, name="case")
        monitor = CaseMonitor(LiveCase(case), case_bus)
        dash.state.set_case_drawing(render_svg(case))
    dash.start()
    stop = threading.Event()
    violate = threading.Event()
    published_red: list[float] = []
    lock = threading.Lock()
    sent = {"states": 0, "frames": 0}

    def state(t: float, red: bool) -> dict[str, Any]:
        nodes: dict[str, list[Any]] = {
            g: [round(0.5 + 0.5 * rng.random(), 3), "satisfied"] for g in goals
        }
        if red:
            nodes["G1"] = [0.0, "unsatisfied"]
            nodes["G2"] = [0.0, "unsatisfied"]
        return {
            "t": t,
            "root": "G1",
            "nodes": nodes,
            "violated": ["G1", "G2"] if red else [],
            "tactics": [],
            "queue": [],
        }

    def publish() -> None:
        t0 = time.monotonic()
        seq = 0
        red = False
        next_tick = t0
        while not stop.is_set():
            now = time.monotonic()
            want_red = violate.is_set()
            if want_red != red or now >= next_tick:
                if want_red and not red:
                    with lock:
                        published_red.append(time.time() * 1000.0)
                red = want_red
                pub_bus.publish("/utu/analyze/state", state(now - t0, red))
                sent["states"] += 1
            if now >= next_tick:
                data = frames[seq % len(frames)]
                pub_bus.publish(
                    "/bench/camera/image",
                    Image(encoding="png", width=320, height=240, data=data, seq=seq),
                )
                pub_bus.publish(
                    "/lec/detector/detections",
                    Detections(
                        frame_seq=seq,
                        model_id="bench",
                        width=320,
                        height=240,
                        boxes=[[20.0 + i * 80, 40.0, 80.0 + i * 80, 200.0] for i in range(3)],
                        labels=["person"] * 3,
                        scores=[0.9, 0.8, 0.7],
                    ),
                )
                sent["frames"] += 1
                seq += 1
                next_tick += 0.1
            stop.wait(max(0.0, min(next_tick - time.monotonic(), 0.005)))

    result: dict[str, Any] = {}
    with sync_playwright() as pw, tempfile.TemporaryDirectory() as profile:
        ctx = pw.chromium.launch_persistent_context(
            profile,
            executable_path=CHROMIUM,
            headless=True,
            args=["--no-sandbox", "--disable-gpu", "--disable-background-networking"],
            viewport={"width": 1440, "height": 1100},
        )
        page = ctx.new_page()
        page.goto(dash.url)
        page.wait_for_selector(  # the stream is up (the run may not be fed yet)
            "#connection[data-state]:not([data-state=reconnecting])", timeout=30_000
        )
        worker = threading.Thread(target=publish, daemon=True)
        worker.start()
        page.wait_for_selector("#goal-svg [data-node=G1].satisfied", timeout=30_000)
        if monitor is not None:
            page.wait_for_selector("#case-drawing g#gsn-G1[data-status]", timeout=30_000)
        page.evaluate(RECORDER)
        start = time.monotonic()
        while time.monotonic() - start < args.seconds:
            elapsed = time.monotonic() - start
            phase = elapsed % 5.0
            if 2.0 <= phase < 4.0:
                violate.set()
            else:
                violate.clear()
            time.sleep(0.01)
        violate.clear()
        time.sleep(1.0)
        raf = page.evaluate("window.__raf")
        red = page.evaluate("window.__red")
        case_red = page.evaluate("window.__caseRed")
        drawn = page.evaluate("window.__frames.size")
        ctx.close()
    stop.set()
    worker.join(5)
    dash.close()
    if monitor is not None and case_bus is not None:
        monitor.close()
        case_bus.close()
    pub_bus.close()
    dash_bus.close()
    intervals = [b - a for a, b in itertools.pairwise(raf[1:])]
    latencies = _latencies(published_red, red)
    case_latencies = _latencies(published_red, case_red)
    result = {
        "benchmark": "dashboard",
        "setup": {
            "goals": len(goals),
            "state_rate_hz": 10,
            "camera_rate_hz": 10,
            "frame": f"320x240 PNG of noise, {len(frames[0])} bytes",
            "detections_per_frame": 3,
            "seconds": args.seconds,
            "violations": len(published_red),
            "browser": "Debian chromium headless via Playwright (executable_path)",
            "server_max_rate_hz": 15,
            "python": platform.python_version(),
            "cpus": os.cpu_count(),
            "load_average_at_end": os.getloadavg()[0],
        },
        "raf_interval_ms": summary(intervals),
        "raf_aim_p95_ms": 50,
        "camera_frames_drawn_per_s": round(drawn / args.seconds, 2),
        "published": {k: round(v / args.seconds, 2) for k, v in sent.items()},
        "violation_to_red_ms": summary(latencies) if latencies else None,
        "case": None
        if monitor is None
        else {
            "nodes": len(case.nodes),
            "svg_bytes": len(render_svg(case)),
            "violation_to_claim_red_ms": summary(case_latencies) if case_latencies else None,
            "aim_p95_ms": 100,
        },
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    print(json.dumps(result, indent=2))


def _latencies(published: list[float], seen: list[float]) -> list[float]:
    """For each violation published, the first time the page showed it (ms)."""
    out = []
    for p in published:
        after = [r for r in seen if r >= p - 5]
        if after:
            out.append(min(after) - p)
    return out


if __name__ == "__main__":
    main()
