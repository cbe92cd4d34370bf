"""``anunnaki oracle train | evaluate | architecture``: a model's oracle (docs/enlil.md)."""

from __future__ import annotations

import argparse
import json
import math
from typing import Any

from anunnaki._blas import torch_threads
from anunnaki.cli._detector import add_model_options, classes_counted, classes_line, shared_view
from anunnaki.cli._text import plain

__all__ = ["add_parser"]


def add_parser(sub: Any) -> None:
    """Register ``oracle`` and its sub-commands."""
    p: argparse.ArgumentParser = sub.add_parser(
        "oracle",
        help="learned behavior oracles (Enlil): train, evaluate, architecture",
        description=plain(__doc__),
    )
    osub = p.add_subparsers(dest="oracle_command", metavar="SUBCOMMAND")
    osub.required = True
    t: argparse.ArgumentParser = osub.add_parser(
        "train",
        help="train a model's oracle on archive contexts (or random ones: the MC baseline)",
    )
    t.add_argument(
        "--models",
        required=True,
        help="model registry YAML (any loader plugin its entries name), or a model file",
    )
    add_model_options(t, dest="model")
    t.add_argument("--data", required=True, help="dataset folder (train and val splits)")
    t.add_argument("--archive", action="append", default=[], help="Enlil archive (repeatable)")
    t.add_argument("--random", type=int, default=0, help="N uniformly random contexts instead")
    t.add_argument(
        "--phenomenon", "-p", action="append", default=[], help="with --random (repeatable)"
    )
    t.add_argument("--out", required=True, help="oracle file NAME (.safetensors + .json)")
    t.add_argument("--frames", type=int, default=3000)
    t.add_argument("--val-frames", type=int, default=600)
    t.add_argument("--epochs", type=int, default=12)
    t.add_argument("--seed", type=int, default=0, help="the seed (the first one, with --seeds N)")
    t.add_argument(
        "--seeds",
        metavar="N|S,S,…",
        help="train one oracle per seed: N seeds from --seed on, or the seeds listed "
        "(comma-separated); writes NAME.seedS per seed and reports each one's val figures "
        "with their mean, SD and spread (max - min)",
    )
    t.add_argument(
        "--architecture",
        default="small_cnn",
        metavar="NAME",
        help="the oracle network: a registered oracle architecture, e.g. small_cnn (default) "
        "or patch_cnn (pools over patches: local phenomena such as a raindrop)",
    )
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
        "--encoding",
        metavar="jpeg:Q|none",
        help="the camera encoding every frame goes through after its phenomenon, clean ones "
        "too (default: the one the archives were assessed through, assess --encoding; with "
        "--random, none)",
    )
    t.add_argument(
        "--no-lookup",
        dest="lookup",
        action="store_false",
        help="the category head alone: no perceived-context lookup over the archive",
    )
    t.add_argument("--json", action="store_true", help="print the result as one JSON object")
    t.set_defaults(run=run_train)
    _add_evaluate(osub)
    _add_architecture(osub)


def run_train(args: argparse.Namespace) -> int:
    """Train and save the oracle(s); print their val figures (a table, or JSON with ``--json``)."""
    from anunnaki.enlil import (
        EnlilError,
        OracleTrainConfig,
        contexts_from_archive,
        train_oracle_seeds,
    )
    from anunnaki.lec import resolve_model

    if bool(args.archive) == bool(args.random):
        raise EnlilError("oracle train: give --archive PATH (repeatable) or --random N")
    if args.random and not args.phenomenon:
        raise EnlilError("oracle train --random N needs --phenomenon P (repeatable)")
    seeds = _seeds(args.seeds, args.seed)
    _check_architecture(args.architecture)
    model = resolve_model(args.models, args.model)
    console = _console()
    sets = [contexts_from_archive(a) for a in args.archive]
    encoding = _encoding(args.encoding, sets)
    counted = None
    if args.random:
        sets, counted = _random_sets(args, model, console, encoding)
    for warning in _no_degraded(sets):
        console.print(warning, style="yellow", soft_wrap=True)
    config = OracleTrainConfig(
        frames=args.frames,
        val_frames=args.val_frames,
        epochs=args.epochs,
        seed=args.seed,
        threads=args.threads,
        lookup=args.lookup,
        architecture=args.architecture,
        encoding=encoding,
        extra={"extra_data": list(args.extra_data)} if args.extra_data else {},
    )
    with _bar(console) as bar:
        task = bar.add_task("frames", total=None)

        def progress(seed: int, stage: str, done: int, total: int) -> None:
            label = f"seed {seed}: {stage}" if len(seeds) > 1 else stage
            bar.update(task, description=label, completed=done, total=total)
            if not console.is_terminal and (stage == "epochs" or done == total):
                console.print(f"{label} {done}/{total}")  # a log gets a line per step

        oracles, spread = train_oracle_seeds(
            _joined(args.data, args.extra_data, "train"),
            _joined(args.data, args.extra_data, "val"),
            sets,
            seeds,
            model_id=model.model_id,
            model_sha256=model.sha256,
            config=config,
            progress=progress,
        )
    report: dict[str, Any] = {
        "model_id": model.model_id,
        "model_file": str(model.file),
        "model_sha256": model.sha256,
        "architecture": args.architecture,
    }
    report["contexts"] = oracles[0].card.training["contexts"]
    if len(seeds) == 1:
        sha = oracles[0].save(args.out)
        report |= {"file": str(args.out), "sha256": sha, "seed": seeds[0]}
        report |= _metrics(oracles[0])
    else:
        report["seeds"] = [
            {"seed": seed, "file": (path := seed_file(args.out, seed)), "sha256": o.save(path),
             **_metrics(o)}
            for seed, o in zip(seeds, oracles, strict=True)
        ]  # fmt: skip
        report["spread"] = {
            figure: {k: None if math.isnan(v) else v for k, v in stats.items()}
            for figure, stats in spread.items()
        }  # JSON has no NaN: a figure no seed has is null
    if counted is not None:
        report |= counted
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    _print_train(report)
    return 0


def _metrics(oracle: Any) -> dict[str, Any]:
    """The card's metrics as its JSON file holds them (null where a figure is undefined)."""
    metrics: dict[str, Any] = oracle.card.model_dump(mode="json")["metrics"]
    return metrics


def seed_file(out: str, seed: int) -> str:
    """The oracle file of one seed of ``--seeds``: ``NAME.seedS`` (``.safetensors`` + ``.json``)."""
    from pathlib import Path

    path = Path(out)
    base = path.with_suffix("") if path.suffix in (".safetensors", ".json") else path
    return str(base.with_name(f"{base.name}.seed{seed}"))


def _seeds(text: str | None, first: int) -> list[int]:
    """``--seeds``: ``N`` (N seeds from *first* on) or ``S,S,…``; none: ``[first]``."""
    from anunnaki.enlil import EnlilError

    if text is None:
        return [first]
    try:
        if "," in text:
            seeds = [int(part) for part in text.split(",") if part.strip()]
        else:
            seeds = list(range(first, first + int(text)))
    except ValueError:
        seeds = []
    if not seeds or len(set(seeds)) != len(seeds) or min(seeds) < 0:
        raise EnlilError(
            f"oracle train --seeds {text!r}: give a number of seeds (--seeds 3: --seed and the "
            "next two) or distinct non-negative seeds separated by commas (--seeds 0,1,2)"
        )
    return seeds


def _check_architecture(name: str, flag: str = "oracle train --architecture") -> None:
    """An unknown ``--architecture`` is an error that lists the registered ones."""
    from anunnaki.enlil import ORACLE_ARCHITECTURES, EnlilError

    names = ORACLE_ARCHITECTURES.names()
    if name not in names:
        raise EnlilError(
            f"{flag} {name!r}: no such oracle architecture; the "
            f"registered ones are {', '.join(names)} (plugins register more under the "
            f"entry-point group {ORACLE_ARCHITECTURES.group})"
        )


def _console() -> Any:
    """Progress and warnings go to stderr: stdout stays the table (or the JSON)."""
    from rich.console import Console

    return Console(stderr=True, highlight=False)


def _bar(console: Any) -> Any:
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
    )

    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn())
    return Progress(*columns, TimeElapsedColumn(), console=console)


def _encoding(given: str | None, sets: list[Any]) -> str:
    """``--encoding``, or the archives' (they must agree): the frames' camera encoding."""
    from anunnaki.enlil import EnlilError
    from anunnaki.phenomena import CameraEncoding

    if given is None:
        found = {s.encoding for s in sets}
        if len(found) > 1:
            listed = ", ".join(f"{s.source}: {s.encoding or 'none'}" for s in sets)
            raise EnlilError(
                f"oracle train: the archives were assessed through different camera encodings "
                f"({listed}); assess them again with the same --encoding"
            )
        return found.pop() if found else ""
    parsed = CameraEncoding.parse(given)
    spec = "" if parsed is None else str(parsed)
    for s in sets:
        if s.encoding != spec:
            raise EnlilError(
                f"oracle train --encoding {given}: {s.source} was assessed through "
                f"{s.encoding or 'none'}; its categories hold for that encoding only "
                f"(leave --encoding out, or assess again with --encoding {given})"
            )
    return spec


def _random_sets(
    args: argparse.Namespace, model: Any, console: Any, encoding: str
) -> tuple[list[Any], Any]:
    """``--random N``: N uniform contexts per phenomenon measured on a val batch (MC baseline).

    They are measured through the camera's *encoding* (``""``: none).
    """
    from anunnaki.enlil import fixed_batch, random_contexts
    from anunnaki.lec import DetectorError, evaluate_detector
    from anunnaki.phenomena import CameraEncoding

    codec = CameraEncoding.parse(encoding)

    detector = model.load()
    batch = fixed_batch(args.data, "val", 32, seed=args.seed)
    counted = classes_counted(detector, batch)
    try:
        detector, batch = shared_view(args, detector, batch)
        clean = float(evaluate_detector(detector, batch, encoding=codec).f1)
    except DetectorError as exc:
        raise DetectorError(f"{args.models}: model {model.model_id!r}: {exc}") from None
    console.print(classes_line(counted))
    sets = [
        random_contexts(
            detector, batch, p, args.random, clean_f1=clean, seed=args.seed, encoding=codec
        )
        for p in args.phenomenon
    ]
    return sets, counted


def _no_degraded(sets: list[Any]) -> list[str]:
    """A warning per phenomenon whose contexts hold no category-1 (degraded) context."""
    return [
        f"warning: the {s.phenomenon} contexts ({s.source}) hold no category-1 (degraded) "
        f"context (categories 0/1/2: {'/'.join(map(str, s.counts()))}): the oracle cannot "
        "learn that category and will call a degraded frame unaffected or compromised. "
        "Give it contexts that reach the band: a longer search (anunnaki assess --budget N, "
        "the enlil search looks for the category edges), another archive of the phenomenon "
        "(--archive, repeatable), or more --random contexts."
        for s in sets
        if s.counts()[1] == 0
    ]


_FIGURES = {"accuracy": "accuracy", "macro_f1": "macro-F1", "ece": "ECE",
            "head_macro_f1": "head alone: macro-F1", "drop_rmse": "drop RMSE"}  # fmt: skip


def _val_figures(val: dict[str, Any]) -> dict[str, float]:
    """The figures of a card's val metrics the table shows (the drop's RMSE flattened)."""
    out = {k: float(val[k]) for k in _FIGURES if k in val}
    if "drop" in val:
        out["drop_rmse"] = float(val["drop"]["rmse"])
    return out


def _print_train(report: dict[str, Any]) -> None:
    """The contexts per phenomenon, the val figures and the file(s) to name in the registry."""
    from rich.table import Table

    where = f": {report['file']}" if "file" in report else f", {len(report['seeds'])} seeds"
    table = Table(title=f"oracle of {report['model_id']} ({report['architecture']}){where}")
    table.add_column("contexts", justify="left")
    table.add_column("categories 0/1/2", justify="right")
    for c in report["contexts"]:
        table.add_row(f"{c['phenomenon']} ({c['source']})", "/".join(map(str, c["counts"])))
    out = _stdout()
    out.print(table)
    seeds = report.get("seeds", [report])
    rows = [(f"seed {s['seed']}", _val_figures(s.get("val", {}))) for s in seeds]
    if "spread" in report:
        spread = report["spread"]
        for stat, label in (("mean", "mean"), ("sd", "SD"), ("spread", "spread (max - min)")):
            rows.append((label, {k: v[stat] for k, v in spread.items()}))
    figures = Table(title="val frames (after temperature scaling)")
    keys = [k for k in _FIGURES if any(k in row for _, row in rows)]
    figures.add_column("", justify="left")
    for k in keys:
        figures.add_column(_FIGURES[k], justify="right")
    for label, row in rows:
        figures.add_row(label, *(f"{row[k]:.3f}" if k in row else "-" for k in keys))
    out.print(figures)
    if "classes" in report:
        out.print(classes_line(report))
    for s in seeds:
        out.print(
            f"saved {s['file']} (sha256 {s['sha256']}); name it in the registry entry: "
            f"oracle: {{file: …, sha256: {s['sha256']}}}",
            soft_wrap=True,
        )


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
    e.add_argument(
        "--models",
        required=True,
        help="model registry YAML (any loader plugin its entries name), or a model file",
    )
    add_model_options(e, dest="model")
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
    e.add_argument(
        "--encoding",
        metavar="jpeg:Q|none",
        help="the camera encoding every frame goes through after the phenomenon, for the "
        "contexts' categories and the frames predicted on (default: the one the oracles were "
        "trained through, oracle train --encoding; none for an oracle trained without)",
    )
    e.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's default)")
    e.add_argument("--json", action="store_true", help="print one JSON object")
    e.set_defaults(run=run_evaluate)


def _oracles(args: argparse.Namespace, model: Any) -> dict[str, Any]:
    """Name → loaded oracle: ``--oracle [NAME=]FILE`` or the registry's."""
    from anunnaki.enlil import EnlilError, load_oracle

    ref = model.spec.oracle if model.spec is not None else None
    if not args.oracle:
        if ref is None:
            if args.baseline:
                return {}
            raise EnlilError(
                f"{args.models}: model {model.model_id!r} names no oracle; give --oracle FILE "
                "(or add oracle: {file, sha256} to its registry entry), or only --baseline"
            )
        return {"oracle": load_oracle(ref.file, sha256=ref.sha256)}
    out: dict[str, Any] = {}
    for i, text in enumerate(args.oracle):
        name, sep, path = text.partition("=")
        name, path = (name, path) if sep else (f"oracle{i}" if i else "oracle", text)
        oracle = load_oracle(path)
        if oracle.model_id != model.model_id:
            raise EnlilError(
                f"--oracle {path}: it assesses model {oracle.model_id!r}, not {model.model_id!r}"
            )
        out[name] = oracle
    return out


def _trained_encoding(oracle: Any) -> str:
    """The camera encoding an oracle's frames went through in training (``""``: none)."""
    return str((oracle.card.training or {}).get("config", {}).get("encoding") or "")


def _evaluate_encoding(given: str | None, oracles: dict[str, Any]) -> Any:
    """``--encoding``, or the one every evaluated oracle was trained through."""
    from anunnaki.enlil import EnlilError
    from anunnaki.phenomena import CameraEncoding

    if given is not None:
        return CameraEncoding.parse(given)
    trained = {n: _trained_encoding(o) for n, o in oracles.items()}
    if len(set(trained.values())) > 1:
        listed = ", ".join(f"{n}: {e or 'none'}" for n, e in trained.items())
        raise EnlilError(
            f"oracle evaluate: the oracles were trained through different camera encodings "
            f"({listed}); say which frames to score them on with --encoding"
        )
    return CameraEncoding.parse(next(iter(trained.values()), ""))


def run_evaluate(args: argparse.Namespace) -> int:
    """Score the oracle(s) and baselines; print the figures (JSON with --json)."""
    with torch_threads(args.threads):  # as it found them after (an in-process call)
        return _evaluate(args)


def _evaluate(args: argparse.Namespace) -> int:
    from anunnaki.datasets import load_split
    from anunnaki.enlil import EnlilError, evaluate_oracles, parse_contexts
    from anunnaki.lec import resolve_model

    spec_contexts = parse_contexts(args.contexts, ("random", "balanced", "interior"))
    low, high = args.thresholds
    if not 0.0 <= low < high <= 1.0:
        raise EnlilError(f"--thresholds {low} {high}: need 0 <= DEG < COMP <= 1")
    model = resolve_model(args.models, args.model)
    oracles = _oracles(args, model)
    encoding = _evaluate_encoding(args.encoding, oracles)
    detector = model.load()
    data = load_split(args.data, args.split)
    counted = classes_counted(detector, data)
    val = load_split(args.data, "val") if args.baseline else None
    detector, data, val = shared_view(args, detector, data, val)
    report = evaluate_oracles(
        detector,
        data,
        args.phenomenon,
        spec_contexts,
        oracles=oracles,
        baselines=tuple(args.baseline),
        val=val,
        fit_spec=parse_contexts(args.fit_contexts) if args.fit_contexts else None,
        per_context=args.frames_per_context,
        window=args.window,
        batch_images=args.batch_images,
        thresholds=(low, high),
        seed=args.seed,
        ceiling=args.ceiling,
        interior=args.interior,
        encoding=encoding,
    )
    report = {
        "model_id": model.model_id,
        "model_file": str(model.file),
        "model_sha256": model.sha256,
        "data": str(args.data),
        "split": args.split,
        "seed": args.seed,
        "thresholds": [low, high],
        **counted,
        **report,
    }
    first = next(iter(report["predictors"].values()))
    report.update({k: v for k, v in first.items() if k not in report})
    if args.json:
        print(json.dumps(report))
        return 0
    _print_table(report)
    print(classes_line(counted))
    return 0


def _stdout() -> Any:
    """The console tables go to (stdout); a pipe or a file gets room for every column."""
    from rich.console import Console

    console = Console(highlight=False)
    return console if console.is_terminal else Console(highlight=False, width=132)


def _print_table(report: dict[str, Any]) -> None:
    console = _stdout()
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


def _architecture_arguments(a: argparse.ArgumentParser, *, batch: bool) -> None:
    """The arguments of one oracle's choice (the command line's, or one ``--batch`` line's)."""
    a.add_argument(
        "phenomenon",
        nargs="*" if batch else "+",
        help="the oracle's phenomena (a+b: each part)"
        + ("; none with --batch (each line names its own)" if batch else ""),
    )
    a.add_argument("--model", metavar="ID", help="the oracle's model (a measured per-model choice)")
    a.add_argument(
        "--choose",
        action="append",
        default=[],
        metavar="P=ARCH",
        help="override the choice of phenomenon P (repeatable; P= drops it)",
    )
    a.add_argument("--default", help="the network when no phenomenon names one (small_cnn)")


def _add_architecture(osub: Any) -> None:
    a: argparse.ArgumentParser = osub.add_parser(
        "architecture",
        help="print the oracle network chosen for phenomena (the per-phenomenon rule)",
        description="Print the network one oracle covering PHENOMENON... gets by the measured "
        "choice (docs/enlil.md): the model's own (--model), else the architecture the phenomena "
        "name (they must agree), else --default. scripts/train-oracles.sh and robustify use "
        "the same rule. With --batch, the oracles come from stdin, one a line: the arguments "
        "of one call (PHENOMENON... --model ID, and --choose or --default of its own after "
        "the command line's); each line prints ID, a tab and the network, and the first line "
        "that fails stops it. One start for many oracles: scripts/train-oracles.sh asks "
        "for all of its models at once.",
    )
    _architecture_arguments(a, batch=True)
    a.add_argument(
        "--batch",
        action="store_true",
        help="read the oracles from stdin, one a line (PHENOMENON... --model ID [--choose "
        "P=ARCH]...); print ID<tab>ARCH a line",
    )
    a.set_defaults(run=run_architecture)


class _LineParser(argparse.ArgumentParser):
    """A ``--batch`` line's parser: a bad line is an error naming it, not an exit."""

    def error(self, message: str) -> Any:  # argparse's hook; it must not return
        from anunnaki.enlil import EnlilError

        raise EnlilError(message)


def _chosen(phenomena: list[str], model: str | None, choose: list[str], default: str | None) -> str:
    """One oracle's network by the measured choice, checked against the registered ones."""
    from anunnaki.enlil import DEFAULT_ORACLE_ARCHITECTURE, EnlilError, oracle_architecture

    choices: dict[str, str | None] = {}
    for item in choose:
        name, sep, arch = item.partition("=")
        if not sep or not name.strip():
            raise EnlilError(
                f"oracle architecture --choose {item!r}: write PHENOMENON=ARCH "
                "(hsl=patch_cnn), or PHENOMENON= to drop its choice"
            )
        choices[name.strip()] = arch.strip() or None
    chosen = oracle_architecture(
        phenomena,
        model_id=model,
        choices=choices,
        default=default or DEFAULT_ORACLE_ARCHITECTURE,
    )
    _check_architecture(chosen, "oracle architecture: the chosen network")
    return chosen


def run_architecture(args: argparse.Namespace) -> int:
    """Print the chosen architecture's name, or with ``--batch`` each stdin line's oracle's."""
    import sys

    from anunnaki.enlil import EnlilError

    if not args.batch:
        if not args.phenomenon:
            raise EnlilError(
                "oracle architecture: name the oracle's phenomena (oracle architecture fog "
                "--model uav-default), or give --batch and one oracle a line on stdin"
            )
        print(_chosen(args.phenomenon, args.model, args.choose, args.default))
        return 0
    if args.phenomenon or args.model:
        raise EnlilError(
            "oracle architecture --batch: each stdin line names its oracle's phenomena and "
            f"--model; the command line names none (it has {args.phenomenon or [args.model]})"
        )
    import shlex

    line_parser = _LineParser(prog="oracle architecture --batch line", add_help=False)
    _architecture_arguments(line_parser, batch=False)
    for number, text in enumerate(sys.stdin, 1):
        if not text.strip():
            continue
        where = f"oracle architecture --batch: stdin line {number} ({text.strip()!r})"
        try:
            line = line_parser.parse_args(shlex.split(text))
        except (EnlilError, ValueError) as exc:  # shlex: an unclosed quote
            raise EnlilError(f"{where}: {exc}; a line is PHENOMENON... --model ID") from exc
        if not line.model:
            raise EnlilError(f"{where}: no --model; a line is PHENOMENON... --model ID")
        try:
            chosen = _chosen(
                line.phenomenon, line.model, args.choose + line.choose, line.default or args.default
            )
        except EnlilError as exc:
            raise EnlilError(f"{where}: {exc}") from exc
        print(f"{line.model}\t{chosen}", flush=True)
    return 0
