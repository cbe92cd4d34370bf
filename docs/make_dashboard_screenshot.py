"""Make docs/images/dashboard.png: the dashboard on a rover run, in headless Chromium.

Runs a launch file — by default ``examples/rover/sim.yaml``, the simulated rover with its
detector, the ground-truth oracle and Utu on the in-process bus — with the dashboard attached
to the launch's bus (what ``anunnaki run LAUNCH --dashboard`` does) until simulated time
``--until`` (default 14 s: fog has come, the fog model has been swapped in), opens the page,
clicks a goal (``--node``, default G4) for its explanation and saves a screenshot.

    python docs/make_dashboard_screenshot.py [--out docs/images/dashboard.png] [--until 14]
    python docs/make_dashboard_screenshot.py --launch examples/rover/utu.yaml --until 30

Needs the dashboard extra, playwright and Chromium (scripts/setup-browser.sh).
"""

from __future__ import annotations

import argparse
import io
import os
import secrets
import tempfile
import threading
from pathlib import Path

from playwright.sync_api import sync_playwright

from anunnaki.cli._dashboard import dashboard_for_launch
from anunnaki.launch import load_launch, run_launch

ROOT = Path(__file__).resolve().parent.parent
CHROMIUM = os.environ.get("ANUNNAKI_CHROMIUM", "/usr/bin/chromium")


def main() -> None:
    """Run the rover with the dashboard, open the page, save the screenshot."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "images" / "dashboard.png"))
    ap.add_argument("--launch", default=str(ROOT / "examples" / "rover" / "sim.yaml"))
    ap.add_argument("--until", type=float, default=14.0, help="run time to stop at (s)")
    ap.add_argument("--speed", type=float, default=10.0)
    ap.add_argument("--node", default="G4", help="the goal whose explanation is shown")
    args = ap.parse_args()
    launch = load_launch(args.launch)
    dash = dashboard_for_launch(launch, port=0, token=secrets.token_urlsafe(16))
    dash.start()
    done = threading.Event()

    def run() -> None:
        try:
            run_launch(
                launch,
                speed=args.speed,
                until=args.until,
                on_bus=dash.attach,
                handle_signals=False,
                out=io.StringIO(),
            )
        finally:
            done.set()

    threading.Thread(target=run, daemon=True).start()
    try:
        with sync_playwright() as pw, tempfile.TemporaryDirectory() as profile:
            ctx = pw.chromium.launch_persistent_context(
                profile,
                executable_path=CHROMIUM,
                headless=True,
                args=["--no-sandbox", "--disable-gpu", "--disable-background-networking"],
                viewport={"width": 1440, "height": 1180},
            )
            page = ctx.new_page()
            page.goto(dash.url)
            if not done.wait(300):
                raise SystemExit("the rover run did not end within 300 s")
            page.wait_for_selector("#executions li", timeout=30_000)
            page.click(f"[data-node={args.node}]")
            page.wait_for_selector("#explanation-text", timeout=10_000)
            page.wait_for_timeout(600)  # the timeline redraws at most 4 times a second
            page.screenshot(path=args.out, full_page=True)
            ctx.close()
    finally:
        dash.close()
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
