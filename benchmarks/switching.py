"""Does switching earn its complexity? (issue 23, item 5): one model for all domains vs switching.

One mixed stream of clean and adverse camera frames — the rover's three Enki domains (``hsl``,
``raindrop``: one to three drops on the lens, ``fog``), each in its own phase between clean
phases, in a seeded order — goes through the arms:

- ``default``: ``rover-default`` alone;
- ``all_domains``: one model fine-tuned from ``rover-default`` on **all three domains at
  once**, with the budget of ONE shipped domain model (the same train images, epochs, batch
  size, learning rate and optimiser steps as ``rover-hsl``, ``rover-raindrop`` and
  ``rover-fog-enki`` each had; ``--finetune-seeds``); each perturbed training frame gets a
  context of one domain's Enki selection (:class:`anunnaki.enki.MixedContexts` of three
  :class:`~anunnaki.enki.ArchiveContexts`, the selections the shipped chains trained on);
- ``switched``: the per-domain models (``rover-hsl``, ``rover-raindrop``, ``rover-fog-enki``)
  switched by the Enlil oracle of the active model, by the rule of the rover's tactics
  (examples/rover/tactics-lm.yaml, goals-lm.yaml): a degraded report (category >= 1) naming a
  domain swaps that domain's model in (fog at once; hsl and raindrop after the report has
  lasted :attr:`Settings.hold` frames, goal G20); a degraded report in clear weather from a
  domain model restores the default at once; a clear scene for 5 s (G15) restores it too;
  each swap tactic waits out its 10 s cooldown; the oracle averages 3 frames (sim-enlil.yaml);
  a swap is in force from the next frame. A report naming a condition none of the three
  models is for (``brightness``: the tactics' ``rover-low_light``, not an arm here) leaves
  the model as it is;
- ``switched_truth``: the same models switched by the frame's true condition, at once: what
  a perfect oracle would give, the bound of switching.

The stream is rendered by the simulator (:class:`anunnaki.sim.RoverSim`: a scenario with the
rover driving a route through a test layout, pedestrians and deer beside it; its camera at
10 Hz, 128 x 128), every frame's ground truth from the simulator's segmentation. The
phases' phenomena are applied to the clean frame exactly as the platform applies a
scenario's (render, phenomena in order with the platform's per-frame seed, JPEG at quality
90, decoded): the scenario file's timeline keys its events by phenomenon name and so cannot
hold the raindrop domain's three-drop composition. Each adverse phase holds one context,
drawn (seeded) from the contexts where the default model degrades (categories 1 and 2) in
the domain's Enlil search archive that no model was trained on (not in the selection).

Figures, per arm and stream seed: F1 per phase kind (clean, hsl, raindrop, fog) and over the
whole stream (true/false positives and misses summed over the frames, each model at its own
score threshold, the detector's F1 rule), swaps made, frames spent in a wrong model (the
model's domain is not the frame's true condition; the all-domain model has none by
definition); then mean and standard deviation over the stream seeds (the all-domain arm:
over fine-tune seeds x stream seeds), and the differences between arms paired by stream (a
tie unless the mean difference exceeds its standard deviation).

Work (the fine-tunes with per-epoch checkpoints, the rendered streams, every model's per-frame
counts) is kept in ``--work``: a killed run continues where it stopped; other settings are
refused with the setting named. Run it under ``nice -n 10``::

    nice -n 10 .venv/bin/python benchmarks/switching.py --domains runs/domains
    .venv/bin/python benchmarks/switching.py --report   # docs/switching.md + its plot

``--domains DIR`` holds the shipped domain chains' work folders (scripts/train-domains.sh's
``runs/domains``: ``ID/stages/select.json`` and ``ID/search/``); their archives are checked
against the sha256 the shipped models' sidecars record. ``--quick`` is the suite's tiny run.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

sys.path.insert(0, str(Path(__file__).resolve().parent))
from robustify import claim, loadavg, read_json, write_json  # the work folder's helpers

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results" / "switching.json"
DOC = ROOT / "docs" / "switching.md"
IMAGES = ROOT / "docs" / "images"
MODELS = ROOT / "examples" / "models"

#: domain -> (shipped model id, the chain's phenomenon): the model examples/models/rover.yaml
#: serves the domain with (fog: Enki's rover-fog-enki, which replaced the --augment rover-fog)
DOMAINS = {
    "hsl": ("rover-hsl", "hsl"),
    "raindrop": ("rover-raindrop", "raindrop+raindrop+raindrop"),
    "fog": ("rover-fog-enki", "fog"),
}
DEFAULT = "rover-default"
ALL_ID = "rover-all"
ARMS = ("default", "all_domains", "switched", "switched_truth")
LABELS = {
    "default": "rover-default alone",
    "all_domains": "one model, all domains",
    "switched": "per-domain models, switched by the Enlil oracle",
    "switched_truth": "per-domain models, switched by the true condition (bound)",
}
SHORT = {
    "default": "default",
    "all_domains": "all-domain",
    "switched": "switched",
    "switched_truth": "switched (truth)",
}
KINDS = ("clean", *DOMAINS)


@dataclass(frozen=True)
class Settings:
    """What decides the results (recorded in the output and the work folder)."""

    train_images: int = 2000
    val_images: int = 200
    epochs: int = 8
    batch_size: int = 32
    lr: float = 2e-3
    threads: int = 2
    clean: float = 0.3
    finetune_seeds: tuple[int, ...] = (0, 1)
    stream_seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    clean_seconds: float = 6.0
    adverse_seconds: float = 12.0
    rate: float = 10.0
    first_layout: int = 44
    oracle_window: int = 3
    hold: tuple[tuple[str, int], ...] = (("hsl", 11), ("raindrop", 11), ("fog", 1))
    cooldown_s: float = 10.0
    back_after_s: float = 5.0
    data_seed: int = 0

    def budget(self) -> Any:
        """The fine-tune budget (:class:`anunnaki.enki.Budget`)."""
        from anunnaki.enki import Budget

        return Budget(
            epochs=self.epochs, batch_size=self.batch_size, lr=self.lr, threads=self.threads
        )


QUICK = Settings(
    train_images=6,
    val_images=4,
    epochs=1,
    batch_size=3,
    threads=1,
    finetune_seeds=(0,),
    stream_seeds=(0, 1),
    clean_seconds=0.6,
    adverse_seconds=1.0,
    hold=(("hsl", 2), ("raindrop", 2), ("fog", 1)),
    cooldown_s=0.5,
    back_after_s=0.5,
)


# -- the work folder --------------------------------------------------------------------------


def log(quiet: bool, text: str) -> None:
    if not quiet:
        print(text, flush=True)


# -- the domains' inputs: selections (training) and archives (the stream's contexts) ----------


@dataclass(frozen=True)
class DomainInput:
    """One domain's chain outputs: what its model trained on and its search archive."""

    domain: str
    model_id: str
    phenomenon: str
    selection: npt.NDArray[np.float64]  # [n, d] the Enki selection (trained on)
    pool: npt.NDArray[np.float64]  # [m, d] held-out degraded contexts of the default
    archive_sha256: str
    shipped_sha256: str | None


def domain_inputs(domains: Path, models: Path) -> dict[str, DomainInput]:
    """Read every domain's selection and archive from the chains' work folders."""
    from anunnaki.enki import archive_sha256
    from anunnaki.enlil import read_archive

    out = {}
    for domain, (model_id, phen) in DOMAINS.items():
        folder = domains / model_id
        sel_file, search = folder / "stages" / "select.json", folder / "search"
        if not sel_file.is_file() or not search.is_dir():
            raise SystemExit(
                f"{folder}: no stages/select.json and search/ archive there; give --domains "
                "the folder of scripts/train-domains.sh's chains (runs/domains)"
            )
        sel = json.loads(sel_file.read_text(encoding="utf-8"))
        archive = read_archive(search)
        if archive.phenomenon != phen or sel["phenomenon"] != phen:
            raise SystemExit(
                f"{folder}: its archive is of {archive.phenomenon!r} and its selection of "
                f"{sel['phenomenon']!r}; the {domain} domain is {phen!r}"
            )
        rows = set(int(r) for r in sel["rows"])
        held = [i for i in range(len(archive)) if int(archive.categories[i]) >= 1 and i not in rows]
        if not held:
            raise SystemExit(f"{folder}: the archive holds no degraded context outside training")
        card = read_json(models / f"{model_id}.json") or {}
        shipped = card.get("training", {}).get("enki", {}).get("archive", {}).get("sha256")
        out[domain] = DomainInput(
            domain,
            model_id,
            phen,
            np.asarray(sel["params"], np.float64),
            np.asarray(archive.params, np.float64)[held],
            archive_sha256(search),
            shipped,
        )
    return out


# -- the all-domain model ---------------------------------------------------------------------


def splits(data: Path, s: Settings) -> tuple[Any, Any]:
    """Train and val (seeded subsets when smaller than the split; the whole split else)."""
    from anunnaki.datasets import load_split

    out = []
    for i, (split, n) in enumerate((("train", s.train_images), ("val", s.val_images))):
        full = load_split(data, split, cache=True)
        if n < len(full):
            rng = np.random.default_rng(s.data_seed + i)
            full = full.subset(np.sort(rng.choice(len(full), size=n, replace=False)))
        out.append(full)
    return out[0], out[1]


def all_domains_source(inputs: dict[str, DomainInput], s: Settings) -> Any:
    """Each perturbed frame: a context of one domain's selection, domains equally likely."""
    from anunnaki.enki import ArchiveContexts, MixedContexts

    return MixedContexts(
        [ArchiveContexts(d.phenomenon, d.selection) for d in inputs.values()], clean=s.clean
    )


def train_all(
    seed: int, inputs: dict[str, DomainInput], data: Path, work: Path, s: Settings, quiet: bool
) -> dict[str, Any]:
    """Fine-tune (or reuse) the all-domain model of *seed*; its file and record."""
    from anunnaki.enki import finetune
    from anunnaki.lec import save_detector

    folder = work / f"all-s{seed}"
    done = read_json(folder / "result.json")
    if done is not None:
        return dict(done)
    train, val = splits(data, s)
    budget = s.budget()
    log(
        quiet,
        f"fine-tune {ALL_ID} seed {seed}: {budget.steps(len(train))} steps (load {loadavg()})",
    )
    start = time.monotonic()
    load0 = loadavg()

    def on_epoch(info: dict[str, float]) -> None:
        log(
            quiet,
            f"  epoch {int(info['epoch'])}: loss {info['loss']:.3f}, val F1 {info['val_f1']:.3f}",
        )

    result = finetune(
        MODELS / f"{DEFAULT}.safetensors", train, val, all_domains_source(inputs, s),
        budget=budget, seed=seed, model_id=ALL_ID, domain="all",
        checkpoints=folder / "finetune", on_epoch=on_epoch,
    )  # fmt: skip
    det = result.detector
    det.training["switching"] = {"domains": list(DOMAINS), "seed": seed}
    file = folder / f"{ALL_ID}.safetensors"
    sha = save_detector(det, file)
    record = {
        "seed": seed,
        "file": str(file.relative_to(work)),
        "sha256": sha,
        "threshold": round(float(result.threshold), 5),
        "steps": int(det.training["steps"]),
        "images": len(train),
        "val_f1": round(float(result.val.f1), 5),
        "train_seconds": round(result.seconds, 1),
        "wall_seconds": round(time.monotonic() - start, 1),
        "load": [load0, loadavg()],
        "source": det.training["source"],
    }
    write_json(folder / "result.json", record)
    return record


# -- the stream -------------------------------------------------------------------------------


def phase_plan(seed: int, s: Settings) -> list[str]:
    """Clean, then the three domains in a seeded order, each followed by a clean phase."""
    order = list(DOMAINS)
    np.random.default_rng(1000 + seed).shuffle(order)
    plan = ["clean"]
    for d in order:
        plan += [d, "clean"]
    return plan


def scenario_for(seed: int, s: Settings, duration: float) -> dict[str, Any]:
    """The scenario the stream is rendered from: a test layout, objects beside the route.

    Pedestrians and deer every 2.5-4.5 m, 1.3-3.5 m to either side of the route, walking
    slowly without crossing it: the rover drives on at its cruise speed (no detector stops
    it here), so every arm sees the same frames and none of the objects is run into.
    """
    rng = np.random.default_rng(2000 + seed)
    speed = 0.8
    length = speed * duration + 12.0
    objects = []
    x = 4.0
    while x < length:
        side = 1.0 if rng.random() < 0.5 else -1.0
        objects.append({
            "kind": "pedestrian" if rng.random() < 0.6 else "deer",
            "x": round(x, 2), "y": round(side * float(rng.uniform(1.3, 3.5)), 2),
            "walk_to": [round(x + float(rng.uniform(-1.5, 1.5)), 2),
                        round(side * float(rng.uniform(1.3, 4.0)), 2)],
            "speed": round(float(rng.uniform(0.3, 0.7)), 2),
        })  # fmt: skip
        x += float(rng.uniform(2.5, 4.5))
    return {
        "anunnaki": "scenario/1",
        "platform": "rover",
        "name": f"switching-{seed}",
        "layout": s.first_layout + seed,
        "background": True,
        "seed": seed,
        "duration": duration + 1.0,
        "camera": {"rate": s.rate, "width": 128, "height": 128, "encoding": "jpeg", "quality": 90},
        "route": [[0.0, 0.0], [round(length, 1), 0.0]],
        "cruise_speed": speed,
        "objects": objects,
    }


def render_stream(
    seed: int, inputs: dict[str, DomainInput], s: Settings, work: Path, quiet: bool
) -> dict[str, Any]:
    """Render (or reuse) stream *seed*: frames, ground truth, the true condition per frame."""
    folder = work / "streams" / f"s{seed}"
    meta = read_json(folder / "stream.json")
    if meta is not None:
        meta["images"] = np.load(folder / "images.npy")
        return dict(meta)
    from anunnaki.bus import open_bus
    from anunnaki.enlil import resolve_phenomenon, to_phenomenon_vector
    from anunnaki.messages import Image
    from anunnaki.sim import RoverSim, parse_scenario

    start = time.monotonic()
    plan = phase_plan(seed, s)
    lengths = [s.clean_seconds if p == "clean" else s.adverse_seconds for p in plan]
    per_frame = 1.0 / s.rate
    counts = [round(x * s.rate) for x in lengths]
    n = sum(counts)
    rng = np.random.default_rng(3000 + seed)
    contexts: list[Any] = []
    for p in plan:
        if p == "clean":
            contexts.append(None)
        else:
            pool = inputs[p].pool
            contexts.append(pool[int(rng.integers(len(pool)))].tolist())
    condition = [p for p, c in zip(plan, counts, strict=True) for _ in range(c)]
    phase = [i for i, c in enumerate(counts) for _ in range(c)]
    scenario = parse_scenario(scenario_for(seed, s, n * per_frame))
    clean: list[Any] = []
    with open_bus("inproc") as bus, RoverSim(
        bus, scenario, frame_hook=lambda sim, frame, image: clean.append(frame),
        publish_ground_truth=False,
    ) as sim:  # fmt: skip
        while len(clean) < n:
            sim.step(per_frame)
    images, truths = [], []
    phens = {d: resolve_phenomenon(inp.phenomenon) for d, inp in inputs.items()}
    for i, frame in enumerate(clean[:n]):
        image = frame.image
        p = plan[phase[i]]
        if p != "clean":
            ph = phens[p]
            params = ph.from_vector(to_phenomenon_vector(ph, np.asarray(contexts[phase[i]])))
            image = ph.apply(image, params, seed=(seed * 1_000_003 + i * 31) % (2**31))
        image = Image.from_array(image, encoding="jpeg", quality=90).to_array()
        images.append(image)
        truths.append({
            "boxes": np.asarray(frame.boxes).reshape(-1, 4).round(2).tolist(),
            "labels": np.asarray(frame.labels).reshape(-1).tolist(),
            "ignore": np.asarray(frame.ignore).reshape(-1, 4).round(2).tolist(),
        })  # fmt: skip
    meta = {
        "seed": seed,
        "layout": scenario.layout,
        "plan": plan,
        "frames_per_phase": counts,
        "contexts": contexts,
        "condition": condition,
        "phase": phase,
        "truths": truths,
        "objects": len(scenario.objects),
        "render_seconds": round(time.monotonic() - start, 1),
    }
    folder.mkdir(parents=True, exist_ok=True)
    np.save(folder / "images.npy", np.stack(images))
    write_json(folder / "stream.json", meta)
    log(quiet, f"stream {seed}: {n} frames, phases {plan}")
    meta["images"] = np.stack(images)
    return meta


def frame_counts(
    model: Path, model_key: str, stream: dict[str, Any], work: Path
) -> npt.NDArray[np.int64]:
    """``[n, 3]`` true positives, false positives, misses of *model* on every frame (cached)."""
    from anunnaki.lec import load_detector
    from anunnaki.lec._metrics import match_image

    file = work / "streams" / f"s{stream['seed']}" / f"counts-{model_key}.npy"
    if file.is_file():
        return np.asarray(np.load(file), np.int64)
    det = load_detector(model)
    out = np.zeros((len(stream["truths"]), 3), np.int64)
    images = stream["images"]
    for start in range(0, len(images), 32):
        preds = det.detect(list(images[start : start + 32]))
        for k, pred in enumerate(preds):
            t = stream["truths"][start + k]
            _, is_tp, n_truth = match_image(
                pred, t["boxes"], t["labels"], iou=0.5, ignore=t["ignore"]
            )
            hits = int(is_tp.sum())
            out[start + k] = (hits, len(is_tp) - hits, n_truth - hits)
    np.save(file, out)
    return out


# -- switching --------------------------------------------------------------------------------


def domain_of(context: str) -> str | None:
    """The domain an oracle's context names (``raindrop+raindrop+raindrop`` is raindrop)."""
    if context == "clear":
        return "default"
    head = context.split("+", 1)[0].split(".", 1)[0]
    return head if head in DOMAINS else None


def switch_by_oracle(stream: dict[str, Any], s: Settings, oracles: Any) -> dict[str, Any]:
    """The tactics' rule, frame by frame, with the active model's Enlil oracle.

    Returns the active domain per frame (``default`` or a domain), the swaps and the
    oracle's reports.
    """
    hold = dict(s.hold)
    cooldown = round(s.cooldown_s * s.rate)
    back = round(s.back_after_s * s.rate)
    ids = {"default": DEFAULT} | {d: DOMAINS[d][0] for d in DOMAINS}
    active = "default"
    degraded = 0  # consecutive frames reported degraded (category >= 1): goal G20
    last_adverse = 0  # frame of the last adverse report (category >= 1 or not clear)
    last_fired: dict[str, int] = {}
    actives, swaps, reports = [], [], []
    for i, image in enumerate(stream["images"]):
        actives.append(active)
        a = oracles.assess(image, seq=i, model_id=ids[active])
        cat = int(a.category)
        context = str(a.context.get("phenomenon", "clear"))
        reports.append([cat, context])
        named = domain_of(context)
        degraded = degraded + 1 if cat >= 1 else 0
        if cat >= 1 or context != "clear":
            last_adverse = i
        target, tactic = None, None
        if (
            cat >= 1
            and named not in (None, "default")
            and named != active
            and degraded >= hold[str(named)]
        ):
            target, tactic = named, f"swap-to-{named}"
        elif cat >= 1 and named == "default" and active != "default":
            target, tactic = "default", "default-in-clear-weather"
        elif active != "default" and cat == 0 and context == "clear" and i - last_adverse >= back:
            target, tactic = "default", "back-to-default"
        if target is not None and tactic is not None:
            fired = last_fired.get(tactic)
            if fired is None or i - fired >= cooldown or tactic == "back-to-default":
                last_fired[tactic] = i
                swaps.append({"frame": i, "from": active, "to": target, "tactic": tactic})
                active = target  # in force from the next frame
    return {"active": actives, "swaps": swaps, "reports": reports}


def runs_of(values: Sequence[str]) -> list[list[Any]]:
    """Run-length code: ``[[value, first frame, frames], ...]``."""
    out: list[list[Any]] = []
    for i, v in enumerate(values):
        if out and out[-1][0] == v:
            out[-1][2] += 1
        else:
            out.append([v, i, 1])
    return out


def expand(runs: Sequence[Sequence[Any]]) -> list[Any]:
    """Inverse of :func:`runs_of`."""
    return [v for v, _, n in runs for _ in range(int(n))]


def per_frame(keep: bool, counts: npt.NDArray[np.int64]) -> dict[str, Any]:
    """The per-frame counts, kept for the plotted stream only."""
    return {"counts": counts.tolist()} if keep else {}


def switch_by_truth(stream: dict[str, Any]) -> dict[str, Any]:
    """The bound: the true condition's model, on every frame (a swap per phase change)."""
    active = ["default" if c == "clean" else c for c in stream["condition"]]
    swaps = [
        {"frame": i, "from": active[i - 1], "to": active[i], "tactic": "truth"}
        for i in range(1, len(active))
        if active[i] != active[i - 1]
    ]
    return {"active": active, "swaps": swaps}


# -- figures ----------------------------------------------------------------------------------


def f1_of(c: npt.NDArray[np.int64]) -> float | None:
    """Pooled F1; ``None`` without a ground-truth object (``anunnaki.sim.f1_score``'s rule)."""
    tp, fp, fn = (int(x) for x in c.sum(axis=0))
    if tp + fn == 0:
        return None
    return round(2 * tp / (2 * tp + fp + fn), 5)


def score(
    counts: npt.NDArray[np.int64], stream: dict[str, Any], active: Sequence[str] | None
) -> dict[str, Any]:
    """F1 per phase kind and overall; frames in a wrong model (``None``: one model for all)."""
    cond = np.asarray(stream["condition"])
    out: dict[str, Any] = {"f1": {}}
    for kind in KINDS:
        mask = cond == kind
        out["f1"][kind] = f1_of(counts[mask]) if mask.any() else None
    out["f1"]["overall"] = f1_of(counts)
    out["f1"]["adverse"] = f1_of(counts[cond != "clean"])
    truth = np.where(cond == "clean", "default", cond)
    if active is None:
        out["wrong_frames"] = None
    else:
        act = np.asarray(active)
        wrong = act != truth
        out["wrong_frames"] = int(wrong.sum())
        out["wrong_detail"] = {
            "adverse_in_default": int((wrong & (act == "default")).sum()),
            "clean_in_domain_model": int((wrong & (truth == "default")).sum()),
            "adverse_in_other_domain_model": int(
                (wrong & (act != "default") & (truth != "default")).sum()
            ),
        }
    return out


def mean_std(values: Sequence[float | None]) -> dict[str, Any]:
    vals = [float(v) for v in values if v is not None]
    if not vals:
        return {"mean": None, "std": None, "n": 0}
    return {
        "mean": round(statistics.fmean(vals), 5),
        "std": round(statistics.stdev(vals), 5) if len(vals) > 1 else 0.0,
        "n": len(vals),
    }


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Mean and standard deviation over an arm's runs."""
    out: dict[str, Any] = {"f1": {}}
    for key in (*KINDS, "adverse", "overall"):
        out["f1"][key] = mean_std([r["f1"][key] for r in runs])
    out["swaps"] = mean_std([r["swaps"] for r in runs])
    wrong = [r["wrong_frames"] for r in runs]
    out["wrong_frames"] = None if any(w is None for w in wrong) else mean_std(wrong)
    return out


#: The comparisons, each paired by stream (both arms saw the same frames): a minus b.
PAIRS = (
    ("switched", "all_domains"),
    ("switched", "default"),
    ("all_domains", "default"),
    ("switched_truth", "switched"),
)


def paired(runs: dict[str, list[dict[str, Any]]], a: str, b: str, key: str) -> dict[str, Any]:
    """F1 of arm *a* minus arm *b* on the same streams: mean, sd, and the verdict.

    A **tie** unless the mean difference exceeds the standard deviation of the per-stream
    differences (the issue's rule: a difference inside the seeds' spread is a tie).
    """
    diffs = [
        ra["f1"][key] - rb["f1"][key]
        for ra in runs[a]
        for rb in runs[b]
        if ra["stream_seed"] == rb["stream_seed"]
        and ra["f1"][key] is not None
        and rb["f1"][key] is not None
    ]
    out = mean_std(diffs)
    if out["mean"] is None or out["n"] < 2 or abs(out["mean"]) <= out["std"]:
        out["verdict"] = "tie"
    else:
        out["verdict"] = "win" if out["mean"] > 0 else "loss"
    return out


# -- the run ----------------------------------------------------------------------------------


def run(args: argparse.Namespace, s: Settings) -> dict[str, Any]:
    from anunnaki.enlil import EnlilOracle
    from anunnaki.lec import load_registry

    work: Path = args.work
    quiet = bool(args.quiet)
    inputs = domain_inputs(args.domains, MODELS)
    # the seeds choose which runs are made, not what one is: more seeds join the same work
    fixed = {k: v for k, v in asdict(s).items() if k not in ("finetune_seeds", "stream_seeds")}
    claim(work, {"settings": fixed, "data": str(args.data.resolve()),
                 "archives": {d: i.archive_sha256 for d, i in inputs.items()}})  # fmt: skip
    t0 = time.monotonic()
    seeds = () if args.streams_only else s.finetune_seeds
    trained = [train_all(seed, inputs, args.data, work, s, quiet) for seed in seeds]
    if args.finetune_only:
        return {"finetunes": trained}
    registry = load_registry(MODELS / "rover.yaml")
    models = {"default": MODELS / f"{DEFAULT}.safetensors"} | {
        d: MODELS / f"{DOMAINS[d][0]}.safetensors" for d in DOMAINS
    }
    runs: dict[str, list[dict[str, Any]]] = {arm: [] for arm in ARMS}
    streams = []
    first = s.stream_seeds[0]
    for seed in s.stream_seeds:
        stream = render_stream(seed, inputs, s, work, quiet)
        render_s = stream.get("render_seconds")
        counts = {key: frame_counts(path, key, stream, work) for key, path in models.items()}
        if args.streams_only:
            streams.append({"seed": seed, "plan": stream["plan"], "render_seconds": render_s})
            continue
        # per-frame series only for the first stream (the plot); run-length codes for the rest
        keep = seed == first
        for rec in trained:
            counts[f"all-s{rec['seed']}"] = frame_counts(
                work / rec["file"], f"all-s{rec['seed']}", stream, work
            )
        base = {"stream_seed": seed}
        r = score(counts["default"], stream, ["default"] * len(stream["condition"]))
        runs["default"].append(base | r | {"swaps": 0} | per_frame(keep, counts["default"]))
        for rec in trained:
            c = counts[f"all-s{rec['seed']}"]
            r = score(c, stream, None)
            runs["all_domains"].append(
                base | {"finetune_seed": rec["seed"]} | r | {"swaps": 0} | per_frame(keep, c)
            )
        oracles = EnlilOracle(registry, window=s.oracle_window)
        for arm, switched in (
            ("switched", switch_by_oracle(stream, s, oracles)),
            ("switched_truth", switch_by_truth(stream)),
        ):
            active = switched["active"]
            picked = np.stack([counts[a][i] for i, a in enumerate(active)])
            r = score(picked, stream, active)
            runs[arm].append(
                base | r | {"swaps": len(switched["swaps"]), "swap_list": switched["swaps"],
                            "active": runs_of(active)} | per_frame(keep, picked)
            )  # fmt: skip
            if arm == "switched":
                runs[arm][-1]["reports"] = runs_of([f"{c} {x}" for c, x in switched["reports"]])
        streams.append({
            "seed": seed, "layout": stream["layout"], "plan": stream["plan"],
            "frames_per_phase": stream["frames_per_phase"], "contexts": stream["contexts"],
            "frames": len(stream["condition"]), "objects": stream["objects"],
            "truth_boxes": int(sum(len(t["boxes"]) for t in stream["truths"])),
            "render_seconds": render_s,
        })  # fmt: skip
        log(quiet, f"stream {seed}: " + ", ".join(
            f"{arm} {runs[arm][-1]['f1']['overall']}" for arm in ARMS))  # fmt: skip
    if args.streams_only:
        return {"streams": streams}
    return {
        "benchmark": "switching",
        "quick": bool(args.quick),
        "settings": asdict(s),
        "domains": {
            d: {
                "model": i.model_id,
                "phenomenon": i.phenomenon,
                "selection": len(i.selection),
                "held_out_pool": len(i.pool),
                "archive_sha256": i.archive_sha256,
                "archive_is_the_shipped_models": i.archive_sha256 == i.shipped_sha256,
            }
            for d, i in inputs.items()
        },
        "budget": {
            "all_domains_steps": sorted({t["steps"] for t in trained}),
            "shipped_steps": {
                d: (read_json(MODELS / f"{m}.json") or {})
                .get("training", {})
                .get("enki", {})
                .get("budget", {})
                .get("steps")
                for d, (m, _) in DOMAINS.items()
            },
            "epochs": s.epochs,
            "batch_size": s.batch_size,
            "lr": s.lr,
            "clean": s.clean,
            "train_images": trained[0]["images"],
        },
        "finetunes": trained,
        "streams": streams,
        "runs": runs,
        "summary": {arm: summarise(runs[arm]) for arm in ARMS},
        "paired": {
            f"{a}-{b}": {k: paired(runs, a, b, k) for k in (*KINDS, "adverse", "overall")}
            for a, b in PAIRS
        },
        "wall_seconds": round(time.monotonic() - t0, 1),
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "load_end": loadavg(),
        },
        "date": time.strftime("%Y-%m-%d", time.gmtime()),
    }


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", type=Path, default=ROOT / "data" / "rover")
    p.add_argument("--domains", type=Path, default=ROOT / "runs" / "domains")
    p.add_argument("--work", type=Path, default=ROOT / "runs" / "switching-benchmark")
    p.add_argument("--output", type=Path, default=OUT)
    p.add_argument("--doc", type=Path, default=DOC, help="--report: the page written")
    p.add_argument("--images", type=Path, default=IMAGES, help="--report: the plot's folder")
    p.add_argument("--quick", action="store_true", help="tiny sizes (the test suite's run)")
    p.add_argument("--finetune-seeds", help="comma list (default 0,1)")
    p.add_argument("--stream-seeds", help="comma list (default 0,1,2,3,4)")
    p.add_argument("--finetune-only", action="store_true", help="train the all-domain model(s)")
    p.add_argument(
        "--streams-only", action="store_true",
        help="render the streams and measure the shipped models (while a fine-tune runs)",
    )  # fmt: skip
    p.add_argument("--report", action="store_true", help="write --doc from --output, no run")
    p.add_argument("--nice", type=int, default=0, help="add this to the process's niceness")
    p.add_argument("--quiet", action="store_true")
    args = p.parse_args(argv)
    if args.report:
        doc = json.loads(args.output.read_text(encoding="utf-8"))
        write_report(doc, args.doc, args.images)
        return 0
    if args.nice:
        os.nice(args.nice)
    s = QUICK if args.quick else Settings()
    if args.finetune_seeds:
        s = replace(s, finetune_seeds=tuple(int(x) for x in args.finetune_seeds.split(",")))
    if args.stream_seeds:
        s = replace(s, stream_seeds=tuple(int(x) for x in args.stream_seeds.split(",")))
    doc = run(args, s)
    if args.finetune_only or args.streams_only:
        print(json.dumps(doc.get("finetunes", doc.get("streams")), indent=1)[:2000])
        return 0
    write_json(args.output, doc)
    log(args.quiet, f"wrote {args.output}")
    return 0


# -- the report -------------------------------------------------------------------------------


def pct(x: float | None) -> str:
    return "—" if x is None else f"{100 * x:.1f}"


def ms(entry: dict[str, Any] | None, *, scale: float = 100.0, digits: int = 1) -> str:
    """``mean ± sd`` of a summary entry (F1 in points by default)."""
    if entry is None or entry.get("mean") is None:
        return "—"
    m, sd = entry["mean"] * scale, entry["std"] * scale
    return f"{m:.{digits}f} ± {sd:.{digits}f}"


def render_report(doc: dict[str, Any]) -> str:
    """docs/switching.md from the benchmark's JSON alone."""
    s, summ, runs = doc["settings"], doc["summary"], doc["runs"]
    b = doc["budget"]
    lines = [
        "# Does switching earn its complexity?",
        "",
        "<!-- Generated by `python benchmarks/switching.py --report` from "
        "benchmarks/results/switching.json; do not edit (a test checks it regenerates). -->",
        "",
        "Issue 23, item 5. One mixed stream of clean and adverse frames of the rover, rendered by "
        "the simulator, goes through three arms (and a bound); which does best, and what does "
        "switching cost? How the stream and the arms are made: the docstring of "
        "`benchmarks/switching.py`.",
        "",
    ]
    if doc.get("quick"):
        lines += ["**This is a `--quick` run (tiny sizes): its figures measure nothing.**", ""]
    seeds = s["stream_seeds"]
    lines += [
        "## The set-up",
        "",
        f"- **Stream** ({len(seeds)} stream seeds: {', '.join(map(str, seeds))}): the rover "
        f"drives a route through a test layout (never in a training split) with pedestrians and "
        f"deer beside it; camera at {s['rate']:g} Hz, 128 x 128, JPEG quality 90. Phases: "
        f"clean {s['clean_seconds']:g} s, then hsl, raindrop and fog ({s['adverse_seconds']:g} s "
        f"each) in a seeded order, each followed by a clean phase; every adverse phase holds "
        "one context the default model degrades on (categories 1-2 of its Enlil search "
        "archive) and no model trained on.",
        f"- **One model, all domains** (`{ALL_ID}`): fine-tuned from `{DEFAULT}` with the "
        f"budget of one shipped domain model: {b['train_images']} train images, {s['epochs']} "
        f"epochs, batch {s['batch_size']}, lr {s['lr']:g}, clean share {s['clean']:g}: "
        f"{', '.join(map(str, b['all_domains_steps']))} optimiser steps (the shipped models': "
        + ", ".join(f"{d} {v}" for d, v in b["shipped_steps"].items())
        + "); each perturbed frame a context of one domain's Enki selection "
        f"({', '.join(str(v['selection']) for v in doc['domains'].values())} contexts), domains "
        f"equally likely. Fine-tune seeds: {', '.join(map(str, s['finetune_seeds']))}.",
        "- **Switched**: `rover-default`, `rover-hsl`, `rover-raindrop`, `rover-fog-enki`; the "
        "active model's Enlil oracle (window "
        f"{s['oracle_window']} frames) drives the tactics' rule: a degraded report naming a "
        "domain swaps its model in ("
        + ", ".join(f"{d} after {h} frame{'s' if h > 1 else ''}" for d, h in s["hold"])
        + f"), a degraded report in clear weather restores the default, so does a clear scene "
        f"for {s['back_after_s']:g} s; each swap tactic waits {s['cooldown_s']:g} s before it "
        "fires again; a swap is in force from the next frame.",
        "- **Switched by the true condition**: the same models, the right one on every frame: "
        "the bound a perfect oracle would reach.",
        "",
        "## Results",
        "",
        "F1 in points, mean ± standard deviation over the stream seeds (the all-domain model: "
        "over fine-tune seeds x stream seeds); each phase kind's frames pooled; **wrong-model "
        "frames**: frames whose active model's domain is not the frame's true condition (of "
        f"{doc['streams'][0]['frames']} frames per stream; one model for all has none by "
        "definition).",
        "",
        "| arm | clean | hsl | raindrop | fog | adverse | overall | swaps | wrong-model frames |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for arm in ARMS:
        e = summ[arm]
        f = e["f1"]
        wrong = "—" if e["wrong_frames"] is None else ms(e["wrong_frames"], scale=1.0)
        lines.append(
            f"| {LABELS[arm]} | {ms(f['clean'])} | {ms(f['hsl'])} | {ms(f['raindrop'])} | "
            f"{ms(f['fog'])} | {ms(f['adverse'])} | **{ms(f['overall'])}** | "
            f"{ms(e['swaps'], scale=1.0)} | {wrong} |"
        )
    lines += [
        "",
        "Differences, paired by stream (every arm saw the same frames): arm a minus arm b, F1 "
        "points, mean ± sd over the streams; a **tie** unless the mean exceeds the sd.",
        "",
        "| a − b | clean | hsl | raindrop | fog | adverse | overall |",
        "|---|---|---|---|---|---|---|",
    ]
    for a, b in PAIRS:
        p = doc["paired"][f"{a}-{b}"]
        cells = [
            f"{ms(p[k])} ({p[k]['verdict']})" if p[k]["mean"] is not None else "—"
            for k in (*KINDS, "adverse", "overall")
        ]
        lines.append(f"| {SHORT[a]} − {SHORT[b]} | " + " | ".join(cells) + " |")
    lines += ["", "Where the switched arm's wrong-model frames went (mean per stream):", ""]
    details = [r["wrong_detail"] for r in runs["switched"]]
    for key, text in (
        ("adverse_in_default", "adverse frames still in the default model (before a swap)"),
        ("clean_in_domain_model", "clean frames in a domain model (before the swap back)"),
        ("adverse_in_other_domain_model", "adverse frames in another domain's model"),
    ):
        lines.append(f"- {text}: {statistics.fmean(d[key] for d in details):.1f}")
    lines += ["", "## Per stream", "", "| seed | phases | " + " | ".join(LABELS[a] for a in ARMS)
              + " | swaps (oracle) |", "|---|---|" + "---|" * len(ARMS) + "---|"]  # fmt: skip
    for i, st in enumerate(doc["streams"]):
        cells = []
        for arm in ARMS:
            vals = [r["f1"]["overall"] for r in runs[arm] if r["stream_seed"] == st["seed"]]
            cells.append(" / ".join(pct(v) for v in vals))
        lines.append(
            f"| {st['seed']} | {' → '.join(st['plan'])} | "
            + " | ".join(cells)
            + f" | {runs['switched'][i]['swaps']} |"
        )
    lines += [
        "",
        "![The first stream: true condition, the active model and the F1 over 2 s, per arm]"
        "(images/switching-stream.png)",
        "",
        "## Cost",
        "",
    ]
    for t in doc["finetunes"]:
        lines.append(
            f"- fine-tune of `{ALL_ID}` seed {t['seed']}: {t['steps']} steps, "
            f"{t['train_seconds']:.0f} s of training, {t['wall_seconds']:.0f} s wall (load "
            f"{t['load'][0][0]:g} at start); val F1 {pct(t['val_f1'])}"
        )
    renders = [st["render_seconds"] for st in doc["streams"] if st["render_seconds"]]
    lines += [
        f"- rendering a stream ({doc['streams'][0]['frames']} frames, the phenomena applied): "
        f"{statistics.fmean(renders):.0f} s mean; the last run (fine-tunes and streams made "
        f"before, reused from the work folder) {doc['wall_seconds']:.0f} s on "
        f"{doc['machine']['cpus']} CPUs shared with other work "
        f"({doc['date']}).",
        "- switching ships and keeps four models and four oracles (each assessed by Enlil) "
        "where one model for all needs one model and one oracle; the swap itself is the model "
        "manager's (docs/model-manager.md).",
        "",
        "## What it says",
        "",
    ]
    lines += _conclusion(doc)
    return "\n".join(lines) + "\n"


def _conclusion(doc: dict[str, Any]) -> list[str]:
    summ, pair = doc["summary"], doc["paired"]
    sw, al = summ["switched"]["f1"], summ["all_domains"]["f1"]
    v = pair["switched-all_domains"]["overall"]
    word = {"win": "beats", "loss": "loses to", "tie": "ties with"}[v["verdict"]]
    kinds = ", ".join(
        f"{k} {ms(pair['switched-all_domains'][k])} ({pair['switched-all_domains'][k]['verdict']})"
        for k in ("clean", *DOMAINS, "adverse")
    )
    g = pair["switched_truth-switched"]["overall"]
    detail = {
        k: statistics.fmean(r["wrong_detail"][k] for r in doc["runs"]["switched"])
        for k in ("clean_in_domain_model", "adverse_in_default")
    }
    d = pair["all_domains-default"]["overall"]
    return [
        f"Over the whole stream, switching the per-domain models by the Enlil oracle {word} "
        f"one model fine-tuned on all domains at once with one domain model's budget "
        f"({ms(sw['overall'])} against {ms(al['overall'])} F1 points; paired difference "
        f"{ms(v)}). Per phase, switched minus all-domain: {kinds}. Both beat `rover-default` "
        f"alone (all-domain − default: {ms(d)} points overall, {d['verdict']}).",
        "",
        f"A perfect oracle would change switching by {ms(g)} points overall ({g['verdict']}): "
        f"what the oracle's late or missed reports cost "
        f"({ms(summ['switched']['wrong_frames'], scale=1.0)} wrong-model frames per stream: "
        f"{detail['clean_in_domain_model']:.0f} clean frames in a domain model, mostly the "
        f"rule's {doc['settings']['back_after_s']:g} s wait before the swap back, and "
        f"{detail['adverse_in_default']:.0f} adverse frames still in the default model, the "
        "hold before a swap and conditions its oracle did not flag).",
    ]


def write_plot(doc: dict[str, Any], images: Path) -> Path | None:
    """The first stream: true condition, active model and windowed F1 per arm."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # pragma: no cover - the plot extra
        return None
    st = doc["streams"][0]
    rate = doc["settings"]["rate"]
    n = st["frames"]
    condition = [
        p for p, k in zip(st["plan"], st["frames_per_phase"], strict=True) for _ in range(k)
    ]
    t = np.arange(n) / rate
    fig, (ax0, ax1) = plt.subplots(2, 1, figsize=(9, 4.6), sharex=True,
                                   gridspec_kw={"height_ratios": [1, 2]})  # fmt: skip
    levels = {"default": 0, "clean": 0, **{d: i + 1 for i, d in enumerate(DOMAINS)}}
    ax0.step(t, [levels[c] for c in condition], where="post", color="k", lw=2,
             label="true condition")  # fmt: skip
    for arm, color in (("switched", "tab:red"), ("switched_truth", "tab:gray")):
        r = next(r for r in doc["runs"][arm] if r["stream_seed"] == st["seed"])
        off = 0.08 if arm == "switched" else -0.08
        ax0.step(t, [levels[a] + off for a in expand(r["active"])], where="post", color=color,
                 lw=1.2, label=f"active model: {LABELS[arm].split(', ')[1]}")  # fmt: skip
    ax0.set_yticks(range(len(DOMAINS) + 1), ["default/clean", *DOMAINS])
    ax0.legend(fontsize=7, loc="upper right")
    window = max(1, int(2 * rate))
    colors = {"default": "tab:blue", "all_domains": "tab:green", "switched": "tab:red",
              "switched_truth": "tab:gray"}  # fmt: skip
    for arm in ARMS:
        r = next(r for r in doc["runs"][arm] if r["stream_seed"] == st["seed"])
        c = np.asarray(r["counts"], np.float64)
        k = np.ones(window)
        tp, fp, fn = (np.convolve(c[:, j], k, mode="same") for j in range(3))
        den = 2 * tp + fp + fn
        f1 = np.divide(2 * tp, den, out=np.full(n, np.nan), where=tp + fn > 0)  # gap: no object
        ax1.plot(t, f1, color=colors[arm], lw=1.2, label=LABELS[arm])
    ax1.set_ylabel(f"F1 over {window / rate:g} s")
    ax1.set_xlabel("time (s)")
    ax1.set_ylim(0, 1.02)
    ax1.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    images.mkdir(parents=True, exist_ok=True)
    path = images / "switching-stream.png"
    fig.savefig(path, dpi=110, metadata={"Software": None})
    plt.close(fig)
    return path


def write_report(doc: dict[str, Any], page: Path, images: Path) -> None:
    """Write docs/switching.md and its plot from the JSON."""
    write_plot(doc, images)
    page.parent.mkdir(parents=True, exist_ok=True)
    page.write_text(render_report(doc), encoding="utf-8")


if __name__ == "__main__":
    sys.exit(main())
