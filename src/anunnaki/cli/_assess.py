"""``anunnaki assess MODEL --data DATA --phenomenon P --budget N``: Enlil's search.

Searches the phenomenon's parameter space for where MODEL degrades, one evaluation being
the F1 drop and category of one context on a fixed batch of the val split; every round is
appended to a Parquet archive (``--out``), which a rerun with the same settings resumes.
See docs/enlil.md.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
from rich.table import Table

from anunnaki.cli._detector import add_model_options, classes_line

_CATEGORY = {0: "unaffected", 1: "degraded", 2: "compromised"}


def add_parser(sub: Any) -> None:
    """Register ``assess``."""
    p: argparse.ArgumentParser = sub.add_parser(
        "assess",
        help="search a phenomenon's parameter space for where a model degrades (Enlil)",
        description=(
            "Run a search (enlil, or the random/sobol baselines) of BUDGET evaluations; each "
            "measures MODEL's F1 on a fixed batch of the val split under one context and maps "
            "the drop to a behaviour category. Results go to a Parquet archive in --out; "
            "rerunning the same command resumes it (after Ctrl-C or kill -9)."
        ),
    )
    p.add_argument(
        "model",
        help="model file (NAME.safetensors), or a model registry (REG.yaml: its default model, "
        "or --model ID; any loader plugin its entries name)",
    )
    add_model_options(p)
    p.add_argument("--data", "-d", required=True, help="dataset folder")
    p.add_argument("--phenomenon", "-p", required=True, help="e.g. fog, hsl, rain+brightness")
    p.add_argument("--budget", "-n", type=int, required=True, help="evaluations")
    p.add_argument("--search", default="enlil", help="enlil, random or sobol (enlil)")
    p.add_argument(
        "--out", "-o", help="archive folder (default: assess/MODEL-P-SEARCH-sSEED, MODEL the id)"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the search and batch (0)")
    p.add_argument("--split", default="val", help="split of the fixed batch (val)")
    p.add_argument("--batch-images", type=int, default=32, help="images per evaluation (32)")
    p.add_argument("--round", type=int, default=16, help="contexts per search round (16)")
    p.add_argument(
        "--encoding",
        default="",
        metavar="jpeg:Q|none",
        help="the camera's encoding every frame goes through after the phenomenon, the clean "
        "batch's too: jpeg:90 for a camera that sends JPEG at quality 90, as the scenarios' "
        "(none: the frames as stored; the archive records it, oracle train follows it)",
    )
    p.add_argument("--workers", type=int, default=2, help="local processes (2)")
    p.add_argument("--dask", help="Dask scheduler address, e.g. tcp://HOST:8786")
    p.add_argument(
        "--thresholds",
        nargs=2,
        type=float,
        default=(0.05, 0.10),
        metavar=("DEGRADED", "COMPROMISED"),
        help="relative F1 drops for categories 1 and 2 (0.05 0.10)",
    )
    p.add_argument("--plot", metavar="DIR", help="write PNG plots of the archive into DIR")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(run=_run_assess)


def _out(args: argparse.Namespace, model: Any) -> Path:
    """``--out``, or ``assess/MODEL-P-SEARCH-sSEED`` (a name: it must follow the rule)."""
    from anunnaki._names import check_name

    if args.out:
        return Path(args.out)
    stem = model.model_id if model.spec is not None else Path(args.model).stem
    name = f"{stem}-{args.phenomenon.replace('+', '_')}-{args.search}-s{args.seed}"
    check_name(name, what="the archive folder's name", fix="give the folder with --out DIR")
    return Path("assess") / name


def _run_assess(args: argparse.Namespace) -> int:
    from anunnaki.enlil import EnlilError, Job, run_search
    from anunnaki.lec import resolve_model

    if args.budget < 1:
        raise EnlilError(f"--budget must be a positive number of evaluations, got {args.budget}")
    model = resolve_model(args.model, args.model_id)  # a bad registry or id fails here
    job = Job(
        model=str(args.model),
        data=str(args.data),
        phenomenon=args.phenomenon,
        split=args.split,
        batch_images=args.batch_images,
        seed=args.seed,
        thresholds=(float(args.thresholds[0]), float(args.thresholds[1])),
        model_id=args.model_id,
        shared_classes=args.shared_classes,
        encoding=args.encoding,
    )
    counted = _counted(args, model)
    out = _out(args, model)
    console = Console(stderr=True)
    columns = (
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
    )
    with Progress(*columns, console=console, disable=args.json) as bar:
        task = bar.add_task(f"{args.search} · {args.phenomenon}", total=args.budget)
        outcome = run_search(
            job,
            out,
            search=args.search,
            budget=args.budget,
            seed=args.seed,
            batch=args.round,
            workers=args.workers,
            dask=args.dask,
            progress=lambda done, total: bar.update(task, completed=done),
            meta_extra={"classes": counted} if args.shared_classes else None,
        )
    summary = {**outcome.summary, "archive": str(out), "resumed": outcome.resumed}
    summary["encoding"] = job.encoding or "none"
    summary |= {"model_id": model.model_id, "model_file": str(model.file),
                "model_sha256": model.sha256, **counted}  # fmt: skip
    if args.plot:
        from anunnaki.enlil import plot_archive

        summary["plots"] = [str(p) for p in plot_archive(outcome.archive, Path(args.plot))]
    if args.json:
        print(json.dumps(summary, indent=2, sort_keys=True))
        return 0
    table = Table(
        title=f"{summary['search']} on {summary['phenomenon']}: "
        f"{summary['evaluations']} evaluations"
    )
    for col in ("category", "evaluations", "occupied cells", "fraction"):
        table.add_column(col, justify="right")
    for c in (0, 1, 2):
        table.add_row(
            f"{c} {_CATEGORY[c]}",
            str(summary["counts"][c]),
            str(summary["cells"][c]),
            f"{summary['fraction'][c]:.3f}",
        )
    Console().print(table)
    print(f"archive: {out} (clean F1 {summary['clean_f1']:.3f}; resumed {outcome.resumed})")
    print(classes_line(counted))
    return 0


def _counted(args: argparse.Namespace, model: Any) -> dict[str, list[str]]:
    """Which classes the search counts; differing class lists fail here, before any worker."""
    from anunnaki.cli._detector import classes_counted, shared_view
    from anunnaki.datasets import load_split
    from anunnaki.lec import DetectorError, class_map

    det = model.load()
    data = load_split(args.data, args.split)
    try:
        view, kept = shared_view(args, det, data)
        class_map(view, kept)
    except DetectorError as exc:
        raise DetectorError(f"{args.model}: model {model.model_id!r}: {exc}") from None
    return classes_counted(det, data)
