"""The way back to the default model: how long the rover's scene must stay clear first.

Issue #34, item 4. After an adverse phase the rover's tactics keep the robust model until
goal G15 fails: the default model is not active and no adverse condition was reported
for ``hold`` seconds (G17: RELAX *eventually within* ``hold``), and only then
``swap-back-to-default`` runs. A long hold keeps a robust model on clear frames it was not
made for (the clear phase after hsl scored F1 0.77 under Utu against 0.89 with no manager);
a short one may swap back while the condition lingers and swap out again: flapping.

Each *variant* is the rover demo (examples/rover/demo.yaml) with its goal model edited in
a copy of the folder, run under Utu on the seeds of ``benchmarks/case_studies.py`` (the
scenario's ``vary:`` draws phase timing, placement and strength), flat out in simulated
time. Variants:

* ``hold-H``: G17's ``within`` set to H seconds (the shipped file says 5);
* ``shadow-H``: the default model's own learned oracle assesses every frame in the shadow
  of the active model's (``managed.shadow``; Utu's agent A7), G17 holds while *it*
  reported the default model degraded within the last H seconds, and the swap back needs
  it to find the default nominal now (instead of the active model's oracle finding the
  scene clear): the default's oracle tells directly whether the default model would cope.

Per run, beside the measures of ``case_studies.run_once`` (``degraded_frames`` among them):

* ``swaps``: swaps of the detector's model (actions of type ``swap_model``);
* ``flaps``: swaps undone within :data:`FLAP_S` seconds (a swap back to the domain the
  previous swap left);
* ``clear_f1``: F1 over the frames of the clear stretches after the first adverse phase,
  pooled (TP, FP, FN summed);
* ``clear_robust_frames``: frames of those stretches a robust (non-default) model handled;
* ``back_s``: per clear stretch after an adverse phase, seconds from its start to the
  first frame of the default model (``null`` when it never came back in the stretch).

Writes ``benchmarks/results/hysteresis.json`` after every run (resumable: a run already in
the file is not run again) and prints the table::

    .venv/bin/python benchmarks/hysteresis.py                       # hold 0.5 1 2 3 5, 10 seeds
    .venv/bin/python benchmarks/hysteresis.py --variants hold-1,shadow-1 --seeds 3
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).parent))
from case_studies import CASES, Case, _spread, run_once

from anunnaki.sim import Timeline, f1_score

ROOT = Path(__file__).parents[1]
RESULTS = Path(__file__).parent / "results" / "hysteresis.json"
#: A swap undone within this many simulated seconds is a flap.
FLAP_S = 2.0
HOLDS = (0.5, 1.0, 2.0, 3.0, 5.0)
DEFAULT_VARIANTS = tuple(f"hold-{h:g}" for h in HOLDS)
MEASURES = (
    "degraded_frames",
    "clear_robust_frames",
    "clear_f1",
    "swaps",
    "flaps",
    "pedestrian_misses",
    "false_alarms",
)


def _set_within(goals: Path, goal: str, within: float) -> None:
    """Set goal ``goal``'s RELAX ``within`` in the goal model file ``goals`` (one edit)."""
    text = goals.read_text(encoding="utf-8")
    block = re.compile(rf"(  - id: {goal}\n(?:    .*\n)*?    relax: \{{[^}}]*within: )([0-9.]+)")
    new, n = block.subn(lambda m: f"{m.group(1)}{within:g}", text)
    if n != 1:
        raise SystemExit(f"{goals}: found {n} relax 'within' of goal {goal}, expected 1")
    goals.write_text(new, encoding="utf-8")


#: The shadow variant's agent: the default model's oracle on every frame.
SHADOW_AGENT = """  A7:
    node: /shadow_enlil
    topics:
      - topic: /utu/oracle/shadow
        attributes: {category: category, context: context.phenomenon}
"""


def _replace_once(path: Path, old: str, new: str) -> None:
    text = path.read_text(encoding="utf-8")
    if text.count(old) != 1:
        raise SystemExit(f"{path}: expected {old.strip()!r} once")
    path.write_text(text.replace(old, new), encoding="utf-8")


def _shadow(folder: Path, hold: float) -> None:
    """The shadow variant: the launch runs the default model's oracle as A7, G17 reads it."""
    launch = folder / "demo.yaml"
    _replace_once(launch, "binding: binding-enlil.yaml", "binding: binding-shadow.yaml")
    launch.write_text(
        launch.read_text(encoding="utf-8")
        + "    shadow: {name: enlil, window: 3, domain: default}\n",
        encoding="utf-8",
    )
    binding = (folder / "binding-enlil.yaml").read_text(encoding="utf-8")
    (folder / "binding-shadow.yaml").write_text(
        binding.replace("  A6:\n", SHADOW_AGENT + "  A6:\n", 1), encoding="utf-8"
    )
    goals = folder / "goals-lm.yaml"
    _replace_once(
        goals,
        "  - {id: A6,",
        "  - {id: A7, description: The default model's oracle (shadow), kind: software}\n"
        "  - {id: A6,",
    )
    _replace_once(
        goals,
        "    utility: A4.category >= 1 or A4.context != 'clear'\n",
        "    utility: A7.category >= 1\n",
    )
    _replace_once(goals, "    agents: [A4]\n\nobstacles:", "    agents: [A7]\n\nobstacles:")
    _set_within(goals, "G17", hold)
    _replace_once(
        folder / "tactics-lm.yaml",
        "      - expression: A4.category == 0 and A4.context == 'clear'\n",
        "      - expression: A7.category == 0\n",
    )


def prepare(variant: str, folder: Path) -> Path:
    """A copy of examples/rover in ``folder`` edited for ``variant``; its launch file."""
    kind, _, value = variant.partition("-")
    try:
        hold = float(value)
    except ValueError:
        raise SystemExit(
            f"unknown variant {variant!r}: give hold-SECONDS or shadow-SECONDS"
        ) from None
    rover = folder / "rover"
    shutil.copytree(ROOT / "examples" / "rover", rover)
    (folder / "models").symlink_to(ROOT / "examples" / "models")
    if kind == "hold":
        _set_within(rover / "goals-lm.yaml", "G17", hold)
    elif kind == "shadow":
        _shadow(rover, hold)
    else:
        raise SystemExit(f"unknown variant {variant!r}: give hold-SECONDS or shadow-SECONDS")
    return rover / "demo.yaml"


def measure(report: dict[str, Any], scenario: Any, result: Any) -> dict[str, Any]:
    """The hysteresis measures of one run (see the module's docstring)."""
    timeline = Timeline(scenario)
    frames = report["frames"]
    default = frames[0]["model"] if frames else ""
    first = min((e.at for e in scenario.phenomena), default=float("inf"))
    clear = [f for f in frames if f["t"] >= first and not timeline.phenomena(f["t"])]
    # the clear stretches after an adverse phase: (start, end)
    stretches: list[tuple[float, float]] = []
    for f in clear:
        if stretches and abs(f["t"] - stretches[-1][1]) < 0.15:
            stretches[-1] = (stretches[-1][0], f["t"])
        else:
            stretches.append((f["t"], f["t"]))
    back: list[float | None] = []
    for start, end in stretches:
        hit = next(
            (f["t"] for f in clear if start <= f["t"] <= end and f["model"] == default), None
        )
        back.append(None if hit is None else round(hit - start, 3))
    swaps = [
        (d.t, d.data.get("domain") or d.data.get("model"))
        for d in result.decisions
        if d.kind == "action" and d.data.get("type") == "swap_model"
    ]
    left = ["default", *(to for _, to in swaps)]  # left[k]: the domain swap k left
    flaps = sum(  # swap k undoes swap k - 1: back, within FLAP_S, to what k - 1 left
        1
        for k in range(1, len(swaps))
        if swaps[k][0] - swaps[k - 1][0] <= FLAP_S and swaps[k][1] == left[k - 1]
    )
    f1 = f1_score(*(sum(f[n] for f in clear) for n in ("tp", "fp", "fn")))
    return {
        "swaps": len(swaps),
        "flaps": flaps,
        "clear_frames": len(clear),
        "clear_f1": None if f1 is None else round(f1, 4),
        "clear_robust_frames": sum(1 for f in clear if f["model"] != default),
        "back_s": back,
    }


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Mean and spread per measure over a variant's seeds; ``back_s`` pooled over stretches."""
    out: dict[str, Any] = {
        m: _spread([float(r[m]) for r in runs if r.get(m) is not None]) for m in MEASURES
    }
    back = [b for r in runs for b in r["back_s"]]
    out["back_s"] = _spread([float(b) for b in back if b is not None])
    out["never_back"] = sum(1 for b in back if b is None)
    out["seeds"] = len(runs)
    return out


def table(summary: dict[str, dict[str, Any]]) -> str:
    """The variants side by side (mean ± std)."""

    def cell(s: dict[str, Any]) -> str:
        return "–" if s["mean"] is None else f"{s['mean']:.2f} ± {s['std']:.2f}"

    rows = [f"{'measure':<20} " + " ".join(f"{v:<16}" for v in summary)]
    for m in (*MEASURES, "back_s"):
        rows.append(f"{m:<20} " + " ".join(f"{cell(s[m]):<16}" for s in summary.values()))
    rows.append(
        f"{'never back':<20} " + " ".join(f"{s['never_back']:<16}" for s in summary.values())
    )
    return "\n".join(rows)


def _load(path: Path) -> dict[str, Any]:
    if path.is_file():
        doc: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
        return doc
    return {"benchmark": "hysteresis", "variants": {}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variants", default=",".join(DEFAULT_VARIANTS), help="comma-separated")
    ap.add_argument("--seeds", type=int, default=10, help="seeds per variant (10)")
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--output", type=Path, default=RESULTS)
    args = ap.parse_args()
    variants = [v for v in args.variants.split(",") if v]
    doc = _load(args.output)
    rover: Case = CASES["rover"]
    for seed in range(args.first_seed, args.first_seed + args.seeds):  # seed-major: balanced
        for variant in variants:  # when interrupted
            entry = doc["variants"].setdefault(variant, {"runs": []})
            if any(r["seed"] == seed for r in entry["runs"]):
                continue
            with tempfile.TemporaryDirectory(prefix="hysteresis-") as tmp:
                case = Case(prepare(variant, Path(tmp)))
                t0 = time.perf_counter()
                run = run_once(case, "utu", seed, None, measure=measure)
            keep = {k: run[k] for k in ("seed", *MEASURES, "back_s", "tactics", "wall_s")}
            entry["runs"].append(keep)
            entry["runs"].sort(key=lambda r: r["seed"])
            entry["summary"] = summarise(entry["runs"])
            doc["settings"] = {
                "case": str(rover.launch.relative_to(ROOT)),
                "flap_s": FLAP_S,
                "machine": platform.machine(),
                "load_avg": os.getloadavg(),
                "date": time.strftime("%Y-%m-%d"),
            }
            args.output.parent.mkdir(parents=True, exist_ok=True)
            args.output.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
            print(
                f"{variant} seed {seed}: degraded {run['degraded_frames']}, swaps {run['swaps']},"
                f" flaps {run['flaps']}, clear F1 {run['clear_f1']}, back {run['back_s']}"
                f" ({time.perf_counter() - t0:.0f} s)",
                flush=True,
            )
    print(
        table(
            {v: doc["variants"][v]["summary"] for v in variants if "summary" in doc["variants"][v]}
        )
    )


if __name__ == "__main__":
    main()
