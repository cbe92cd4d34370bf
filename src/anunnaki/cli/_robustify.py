"""``anunnaki robustify MODEL --data DATA --phenomenon P --domain NAME``: Enki's chain.

Search (or ``--archive``) → select contexts → fine-tune a copy of MODEL → measure → assess the
new model → its oracle → ``--register``. Work goes to ``--out``; rerunning the same command
continues it after Ctrl-C or kill -9. See docs/robustify.md.
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

from anunnaki.cli._detector import add_model_options
from anunnaki.cli._text import plain

__all__ = ["add_parser"]


def add_parser(sub: Any) -> None:
    """Register ``robustify``."""
    p: argparse.ArgumentParser = sub.add_parser(
        "robustify",
        help="a robustified model for a domain, from the contexts where MODEL fails (Enki)",
        description=plain(__doc__),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("model", help="model file (NAME.safetensors) or registry (REG.yaml)")
    add_model_options(p)
    p.add_argument("--data", "-d", required=True, help="dataset folder (train, val, test)")
    p.add_argument("--phenomenon", "-p", required=True, help="e.g. hsl, raindrop, fog")
    p.add_argument("--domain", required=True, help="the new model's domain, e.g. hsl")
    p.add_argument("--out", "-o", help="work folder (default: robustify/ID)")
    p.add_argument("--id", dest="new_id", help="the new model's id (default: rover-DOMAIN "
                   "for rover-default, else MODEL_ID-DOMAIN)")  # fmt: skip
    p.add_argument("--archive", help="reuse this Enlil archive of MODEL and P (no search)")
    p.add_argument("--register", metavar="REG.yaml", help="add the model and its oracle here")
    g = p.add_argument_group("search (as anunnaki assess)")
    g.add_argument("--budget", "-n", type=int, default=400, help="evaluations per search (400)")
    g.add_argument("--search", default="enlil", help="enlil, random or sobol (enlil)")
    g.add_argument("--batch-images", type=int, default=32, help="images per evaluation (32)")
    g.add_argument("--round", type=int, default=16, help="contexts per search round (16)")
    g.add_argument("--workers", type=int, default=2, help="local processes (2)")
    g.add_argument("--thresholds", nargs=2, type=float, default=(0.05, 0.10),
                   metavar=("DEGRADED", "COMPROMISED"), help="(0.05 0.10)")  # fmt: skip
    s = p.add_argument_group("selection (docs/robustify.md)")
    s.add_argument("--contexts", type=int, default=64, help="training contexts (64)")
    s.add_argument(
        "--weights",
        nargs=3,
        type=float,
        default=(1.0, 3.0, 3.0),
        metavar=("W0", "W1", "W2"),
        help="weights of categories 0 1 2 (1 3 3)",
    )
    s.add_argument("--second-opinion", metavar="MODEL",
                   help="a second model (file or registry id) for the learnability cap: a "
                   "context is left out only if it too scores F1 below the floor there "
                   "(without one, nothing is left out)")  # fmt: skip
    f = p.add_argument_group("fine-tune")
    f.add_argument("--clean", type=float, default=0.3, help="share of clean frames (0.3)")
    f.add_argument("--epochs", type=int, default=8, help="(8)")
    f.add_argument("--batch-size", type=int, default=32, help="(32)")
    f.add_argument("--lr", type=float, default=2e-3, help="peak learning rate (2e-3)")
    f.add_argument("--threads", type=int, default=2, help="torch threads (2)")
    f.add_argument("--seed", type=int, default=0, help="the one seed of every stage (0)")
    f.add_argument("--ema", type=float, default=0.0, metavar="DECAY",
                   help="save a moving average of the weights with this decay, e.g. 0.99 "
                   "(0: off, the last weights)")  # fmt: skip
    r = p.add_argument_group("training recipe (docs/robustify.md#recipe; the default is B, "
                             "the selected contexts)")  # fmt: skip
    r.add_argument("--source", default="archive", metavar="NAME",
                   help="what perturbs the training frames: archive (the selected contexts), "
                   "archive_mix (jittered selected contexts mixed with uniform ones), uniform, "
                   "corruption_mix, or a plugin's name (archive)")  # fmt: skip
    r.add_argument("--k", type=int, default=1,
                   help="candidates per perturbed frame; above 1, worst-of-k keeps the one "
                   "with the highest loss under the network being trained (1: off)")  # fmt: skip
    r.add_argument("--select", choices=("hardest", "random"), default="hardest",
                   help="worst-of-k's pick; random renders as many candidates and picks one "
                   "at random (the control) (hardest)")  # fmt: skip
    r.add_argument("--share", type=float, default=0.5,
                   help="archive_mix: share of perturbed frames from the selected contexts, "
                   "the rest uniform (0.5)")  # fmt: skip
    r.add_argument("--jitter", type=float, default=0.1,
                   help="archive_mix: standard deviation of the selected contexts' Gaussian "
                   "jitter in the normalised space (0.1)")  # fmt: skip
    r.add_argument("--consistency", type=float, default=0.0, metavar="LAMBDA",
                   help="weight of the consistency loss between the heat maps of each "
                   "perturbed frame and its clean view (0: off)")  # fmt: skip
    o = p.add_argument_group("measurement and oracle")
    o.add_argument("--measure-contexts", type=int, default=32,
                   help="archive contexts both models are measured on (32)")  # fmt: skip
    o.add_argument("--oracle-frames", type=int, help="(oracle train's default)")
    o.add_argument("--oracle-val-frames", type=int, help="(oracle train's default)")
    o.add_argument("--oracle-epochs", type=int, help="(oracle train's default)")
    o.add_argument("--oracle-threads", type=int, help="(oracle train's default)")
    o.add_argument(
        "--oracle-architecture",
        metavar="NAME",
        help="the oracle's network, e.g. small_cnn or patch_cnn (default: the measured choice, "
        "as scripts/train-oracles.sh makes it; anunnaki oracle architecture P --model ID "
        "prints it)",
    )
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(run=run_robustify)


def _config(args: argparse.Namespace) -> Any:
    from anunnaki.enki import Budget, RobustifyConfig, SelectionRule

    oracle = {k: v for k, v in (("frames", args.oracle_frames),
              ("val_frames", args.oracle_val_frames), ("epochs", args.oracle_epochs),
              ("threads", args.oracle_threads)) if v is not None}  # fmt: skip
    return RobustifyConfig(
        phenomenon=args.phenomenon,
        domain=args.domain,
        archive=args.archive,
        model_id=args.new_id,
        budget=args.budget,
        search=args.search,
        batch_images=args.batch_images,
        search_round=args.round,
        workers=args.workers,
        thresholds=(float(args.thresholds[0]), float(args.thresholds[1])),
        rule=SelectionRule(contexts=args.contexts, weights=tuple(args.weights)),
        clean=args.clean,
        finetune=Budget(
            epochs=args.epochs,
            batch_size=args.batch_size,
            lr=args.lr,
            threads=args.threads,
            ema=args.ema,
        ),
        seed=args.seed,
        measure_contexts=args.measure_contexts,
        oracle=oracle,
        oracle_architecture=args.oracle_architecture,
        source=args.source,
        k=args.k,
        select=args.select,
        share=args.share,
        jitter=args.jitter,
        consistency=args.consistency,
        second_opinion=args.second_opinion,
    )


def run_robustify(args: argparse.Namespace) -> int:
    """Run (or continue) the chain; print the summary table (or JSON)."""
    from pathlib import Path

    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from anunnaki.enki import EnkiError, new_model_id, robustify
    from anunnaki.lec import resolve_model

    if args.budget < 1:
        raise EnkiError(f"--budget must be a positive number of evaluations, got {args.budget}")
    config = _config(args)
    out = args.out
    if out is None:
        model = resolve_model(args.model, args.model_id)
        out = str(Path("robustify") / (args.new_id or new_model_id(model.model_id, args.domain)))
    console = Console(stderr=True, highlight=False)
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn())
    eta = TimeRemainingColumn()  # the current stage's time left
    with Progress(*columns, TimeElapsedColumn(), eta, console=console, disable=args.json) as bar:
        task = bar.add_task("robustify", total=None)
        last: dict[str, Any] = {"stage": "", "done": 0, "total": 0, "start": time.monotonic()}

        def progress(stage: str, done: int, total: int) -> None:
            if done < last["done"] or total != last["total"]:  # a new count: a new ETA
                bar.reset(task, total=total or None, completed=done, description=stage)
                last["start"] = time.monotonic()
            bar.update(task, description=stage, completed=done, total=total or None)
            if not console.is_terminal and not args.json and stage != last["stage"]:
                console.print(stage + _eta(done, total, time.monotonic() - last["start"]))
            last.update(stage=stage, done=done, total=total)

        summary = robustify(
            args.model, args.data, out, config, model_in_id=args.model_id,
            register=args.register, progress=progress,
        )  # fmt: skip
    if args.json:
        print(json.dumps(summary, indent=2, sort_keys=True))
        return 0
    _print(summary)
    return 0


def _spent(finetune: dict[str, Any]) -> str:
    """The forward passes beside the steps, and the recipe when it is not the default."""
    recipe = finetune.get("recipe", {})
    parts = []
    if recipe.get("source", "archive") != "archive" or recipe.get("k", 1) > 1:
        parts.append(f"source {recipe['source']}" + (
            f", worst-of-{recipe['k']} ({recipe['select']})" if recipe.get("k", 1) > 1 else ""
        ))  # fmt: skip
    if finetune.get("select_forwards"):
        parts.append(f"{finetune['select_forwards']} scoring forward passes")
    if finetune.get("consistency_forwards"):
        parts.append(
            f"{finetune['consistency_forwards']} clean views (consistency "
            f"{recipe.get('consistency')})"
        )
    if recipe.get("ema"):
        parts.append(f"EMA {recipe['ema']}")
    return f"; {', '.join(parts)}" if parts else ""


def _eta(done: int, total: int, seconds: float) -> str:
    """`` (about N s left)`` at the rate so far, for a log's line (a terminal has the bar's)."""
    if done <= 0 or total <= done or seconds <= 0:
        return ""
    return f" (about {seconds / done * (total - done):.0f} s left in this stage)"


def _print(summary: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    m, model = summary["metrics"], summary["model"]
    table = Table(title=f"{model['model_id']} ({model['domain']}) from "
                  f"{summary['input']['model_id']}, {summary['phenomenon']}")  # fmt: skip
    for col in ("F1", summary["input"]["model_id"], model["model_id"]):
        table.add_column(col, justify="left" if col == "F1" else "right")
    clean, on = m["clean"], m["archive_contexts"]
    table.add_row(f"clean ({clean['split']})", f"{clean['input']:.3f}", f"{clean['new']:.3f}")
    table.add_row(
        f"{on['contexts']} archive contexts (val batch)",
        f"{on['input']['f1']:.3f}",
        f"{on['new']['f1']:.3f}",
    )
    table.add_row(
        "  categories 0/1/2",
        "/".join(map(str, on["input"]["categories"])),
        "/".join(map(str, on["new"]["categories"])),
    )
    console = Console(highlight=False)
    console.print(table)
    a, t, sel = summary["archive"], summary["finetune"], summary["selection"]
    lines = [
        f"archive: {a['path']} ({a['evaluations']} contexts, categories "
        f"{'/'.join(map(str, a['counts']))}{', reused' if a['reused'] else ''})",
        f"selection: {sum(sel['counts'])} contexts, categories {'/'.join(map(str, sel['counts']))}",
        f"fine-tune: {t['epochs']} epochs, {t['steps']} optimizer steps on {t['images']} "
        f"images, seed {summary['seed']}" + _spent(t),
        f"model: {model['file']} (sha256 {model['sha256'][:16]}…)",
        f"oracle: {summary['oracle']['file']} ({summary['oracle'].get('architecture', '?')}, "
        f"sha256 {summary['oracle']['sha256'][:16]}…)",
        f"assessment: {summary['assessment']['path']} (categories "
        f"{'/'.join(map(str, summary['assessment']['counts']))})",
    ]
    if summary.get("reused_stages"):
        lines.append(f"continued: {', '.join(summary['reused_stages'])} done before")
    if summary.get("rerun_stages"):
        lines.append(f"run again (their options changed): {', '.join(summary['rerun_stages'])}")
    if "registered" in summary:
        r = summary["registered"]
        lines.append(f"registered {r['model_id']} ({r['domain']}) in {r['registry']}")
    for line in lines:
        console.print(line, soft_wrap=True)
