"""``anunnaki oracle train | evaluate``: a model's behavior oracle (docs/enlil.md)."""

from __future__ import annotations

import argparse
import json
from typing import Any

__all__ = ["add_parser"]


def add_parser(sub: Any) -> None:
    """Register ``oracle`` and its sub-commands."""
    p: argparse.ArgumentParser = sub.add_parser(
        "oracle", help="learned behavior oracles (Enlil): train, evaluate", description=__doc__
    )
    osub = p.add_subparsers(dest="oracle_command", metavar="SUBCOMMAND")
    osub.required = True
    t: argparse.ArgumentParser = osub.add_parser(
        "train",
        help="train a model's oracle on archive contexts (or random ones: the MC baseline)",
    )
    t.add_argument("--models", required=True, help="model registry YAML")
    t.add_argument("--model", required=True, help="model id whose behavior is predicted")
    t.add_argument("--data", required=True, help="dataset folder (train and val splits)")
    t.add_argument("--archive", action="append", default=[], help="Enlil archive (repeatable)")
    t.add_argument("--random", type=int, default=0, help="N uniformly random contexts instead")
    t.add_argument("--phenomenon", action="append", default=[], help="with --random")
    t.add_argument("--out", required=True, help="oracle file NAME (.safetensors + .json)")
    t.add_argument("--frames", type=int, default=3000)
    t.add_argument("--val-frames", type=int, default=600)
    t.add_argument("--epochs", type=int, default=12)
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--threads", type=int, default=0)
    t.add_argument(
        "--extra-data",
        action="append",
        default=[],
        metavar="DIR",
        help="another dataset folder whose train/val images join the frames (repeatable), "
        "e.g. one made by make-dataset --no-clutter",
    )
    t.add_argument(
        "--no-lookup",
        dest="lookup",
        action="store_false",
        help="the category head alone: no perceived-context lookup over the archive",
    )
    t.set_defaults(run=run_train)
    _add_evaluate(osub)


def run_train(args: argparse.Namespace) -> int:
    """Train, save, print the oracle's sha256 and val metrics as JSON."""
    from anunnaki.enlil import (
        EnlilError,
        OracleTrainConfig,
        contexts_from_archive,
        fixed_batch,
        random_contexts,
        train_oracle,
    )
    from anunnaki.lec import evaluate_detector, load_registry

    if bool(args.archive) == bool(args.random):
        raise EnlilError("oracle train: give --archive PATH (repeatable) or --random N")
    registry = load_registry(args.models)
    spec = registry.get(args.model)
    digest = registry.verify(spec)
    sets = [contexts_from_archive(a) for a in args.archive]
    if args.random:
        if not args.phenomenon:
            raise EnlilError("oracle train --random N needs --phenomenon P (repeatable)")
        detector = registry.load(spec)
        batch = fixed_batch(args.data, "val", 32, seed=args.seed)
        clean = float(evaluate_detector(detector, batch).f1)
        sets = [
            random_contexts(detector, batch, p, args.random, clean_f1=clean, seed=args.seed)
            for p in args.phenomenon
        ]
    config = OracleTrainConfig(
        frames=args.frames,
        val_frames=args.val_frames,
        epochs=args.epochs,
        seed=args.seed,
        threads=args.threads,
        lookup=args.lookup,
        extra={"extra_data": list(args.extra_data)} if args.extra_data else {},
    )
    oracle = train_oracle(
        _joined(args.data, args.extra_data, "train"),
        _joined(args.data, args.extra_data, "val"),
        sets,
        model_id=spec.id,
        model_sha256=digest,
        config=config,
    )
    sha = oracle.save(args.out)
    print(json.dumps({"file": str(args.out), "sha256": sha, **oracle.card.metrics}, indent=2))
    return 0


def _joined(data: str, extra: list[str], split: str) -> Any:
    """*split* of *data* with the same split of every *extra* folder appended."""
    from anunnaki.datasets import Dataset, load_split
    from anunnaki.enlil import EnlilError

    main = load_split(data, split)
    if not extra:
        return main
    records = list(main.records)
    for folder in extra:
        more = load_split(folder, split)
        if more.classes != main.classes:
            raise EnlilError(
                f"--extra-data {folder}: classes {list(more.classes)} differ from {data}'s "
                f"{list(main.classes)}; render it for the same platform"
            )
        records.extend(more.records)
    return Dataset(main.classes, records, name=f"{data}+{len(extra)} extra ({split})")


def _add_evaluate(osub: Any) -> None:
    e: argparse.ArgumentParser = osub.add_parser(
        "evaluate",
        help="accuracy, macro-F1, ECE … of a model's oracle (and baselines) on held-out frames",
        description=(
            "Draw contexts of a phenomenon on a split (random:N uniform, balanced:N about N/3 "
            "per category), measure each one's true category on a fixed batch of the split, "
            "perturb --frames-per-context other frames of the split with it and compare the "
            "oracle's per-frame prediction, and its mean over windows of --window frames. "
            "--baseline atc|max-score|box-stability scores the detector's own outputs on the "
            "same frames, fitted on the val split. Every context is measured again on a "
            "disjoint batch of as many images: the labels' own agreement (Cohen's kappa, "
            "macro-F1) is the ceiling every figure is reported against; a balanced set is "
            "also drawn from each category's interior (docs/enlil.md)."
        ),
    )
    e.add_argument("--models", required=True, help="model registry YAML")
    e.add_argument("--model", required=True, help="model id whose behavior is predicted")
    e.add_argument("--data", required=True, help="dataset folder (the split; val for baselines)")
    e.add_argument("--split", default="test", help="split the figures come from (test)")
    e.add_argument("--phenomenon", "-p", required=True, help="e.g. fog, raindrop, hsl")
    e.add_argument(
        "--contexts",
        default="random:60",
        help="random:N, balanced:N or interior:N (random:60)",
    )
    e.add_argument(
        "--oracle",
        action="append",
        default=[],
        metavar="[NAME=]FILE",
        help="oracle file(s) to score (repeatable; default: the one the registry names)",
    )
    e.add_argument(
        "--baseline",
        action="append",
        default=[],
        choices=("atc", "max-score", "box-stability"),
        help="also score a detector-output baseline (repeatable)",
    )
    e.add_argument(
        "--no-ceiling",
        dest="ceiling",
        action="store_false",
        help="skip measuring the contexts again (no ceiling, no interior set)",
    )
    e.add_argument(
        "--no-interior",
        dest="interior",
        action="store_false",
        help="with balanced:N, skip the second set drawn from each category's interior",
    )
    e.add_argument(
        "--fit-contexts",
        help="val contexts the baselines' category thresholds are fitted on "
        "(default: balanced:N with --contexts' N)",
    )
    e.add_argument("--frames-per-context", type=int, default=10, help="frames per context (10)")
    e.add_argument("--window", type=int, default=5, help="frames per window (5)")
    e.add_argument("--batch-images", type=int, default=32, help="fixed batch size (32)")
    e.add_argument(
        "--thresholds", type=float, nargs=2, default=[0.05, 0.10], metavar=("DEG", "COMP")
    )
    e.add_argument("--seed", type=int, default=0)
    e.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's default)")
    e.add_argument("--json", action="store_true", help="print one JSON object")
    e.set_defaults(run=run_evaluate)


def _oracles(args: argparse.Namespace, spec: Any) -> dict[str, Any]:
    """Name → loaded oracle: ``--oracle [NAME=]FILE`` or the registry's."""
    from anunnaki.enlil import EnlilError, load_oracle

    if not args.oracle:
        if spec.oracle is None:
            if args.baseline:
                return {}
            raise EnlilError(
                f"{args.models}: model {spec.id!r} names no oracle; give --oracle FILE "
                "(or add oracle: {file, sha256} to its entry), or only --baseline"
            )
        return {"oracle": load_oracle(spec.oracle.file, sha256=spec.oracle.sha256)}
    out: dict[str, Any] = {}
    for i, text in enumerate(args.oracle):
        name, sep, path = text.partition("=")
        name, path = (name, path) if sep else (f"oracle{i}" if i else "oracle", text)
        oracle = load_oracle(path)
        if oracle.model_id != spec.id:
            raise EnlilError(
                f"--oracle {path}: it assesses model {oracle.model_id!r}, not {spec.id!r}"
            )
        out[name] = oracle
    return out


def run_evaluate(args: argparse.Namespace) -> int:
    """Score the oracle(s) and baselines; print the figures (JSON with --json)."""
    from anunnaki.datasets import load_split
    from anunnaki.enlil import EnlilError, evaluate_oracles, parse_contexts
    from anunnaki.lec import load_registry

    spec_contexts = parse_contexts(args.contexts, ("random", "balanced", "interior"))
    low, high = args.thresholds
    if not 0.0 <= low < high <= 1.0:
        raise EnlilError(f"--thresholds {low} {high}: need 0 <= DEG < COMP <= 1")
    if args.threads:
        import torch

        torch.set_num_threads(args.threads)
    registry = load_registry(args.models)
    spec = registry.get(args.model)
    registry.verify(spec)
    oracles = _oracles(args, spec)
    detector = registry.load(spec)
    report = evaluate_oracles(
        detector,
        load_split(args.data, args.split),
        args.phenomenon,
        spec_contexts,
        oracles=oracles,
        baselines=tuple(args.baseline),
        val=load_split(args.data, "val") if args.baseline else None,
        fit_spec=parse_contexts(args.fit_contexts) if args.fit_contexts else None,
        per_context=args.frames_per_context,
        window=args.window,
        batch_images=args.batch_images,
        thresholds=(low, high),
        seed=args.seed,
        ceiling=args.ceiling,
        interior=args.interior,
    )
    report = {
        "model_id": spec.id,
        "data": str(args.data),
        "split": args.split,
        "seed": args.seed,
        "thresholds": [low, high],
        **report,
    }
    first = next(iter(report["predictors"].values()))
    report.update({k: v for k, v in first.items() if k not in report})
    if args.json:
        print(json.dumps(report))
        return 0
    _print_table(report)
    return 0


def _print_table(report: dict[str, Any]) -> None:
    from rich.console import Console

    console = Console(highlight=False)
    if not console.is_terminal:  # a pipe or a file: room for every column
        console = Console(highlight=False, width=132)
    console.print(_table(report, report["test"], report["split"], report["model_id"]))
    if "interior" in report:
        inner = report["interior"]
        title = f"interior (drops over {inner['margin']:.3f} from a band edge)"
        console.print(_table(inner | {"phenomenon": report["phenomenon"]}, inner["test"],
                             report["split"], title))  # fmt: skip


def _table(part: dict[str, Any], info: dict[str, Any], split: str, who: str) -> Any:
    from rich.table import Table

    table = Table(
        title=f"{who} under {part['phenomenon']}: {info['contexts']} contexts "
        f"({info['spec']}, categories {info['category_counts']}), {info['frames']} "
        f"{split} frames"
    )
    cols = ("predictor", "accuracy", "macro-F1", "kappa", "F1/ceiling", "ECE", "drop RMSE",
            "drop rho", "context err", "win acc", "win F1")  # fmt: skip
    for col in cols:
        table.add_column(col, justify="left" if col == "predictor" else "right")

    def fmt(v: Any) -> str:
        return "-" if v is None else f"{v:.3f}"

    ceiling = part.get("ceiling")
    if ceiling is not None:
        table.add_row(
            f"labels again ({ceiling['batch_images']} images)", fmt(ceiling["accuracy"]),
            fmt(ceiling["macro_f1"]), fmt(ceiling["kappa"]), "1.000", "-",
            fmt(ceiling["drop"]["rmse"]), fmt(ceiling["drop"]["spearman"]), "-", "-", "-",
        )  # fmt: skip
    for name, f in part["predictors"].items():
        w, drop = f["window"], f.get("drop") or {}
        table.add_row(
            name, fmt(f["accuracy"]), fmt(f["macro_f1"]), fmt(f.get("kappa")),
            fmt((f.get("of_ceiling") or {}).get("macro_f1")), fmt(f["ece"]),
            fmt(drop.get("rmse")), fmt(drop.get("spearman")),
            fmt(f["context_error"]), fmt(w["accuracy"]), fmt(w["macro_f1"]),
        )  # fmt: skip
    return table
