"""``anunnaki make-dataset | train-detector | evaluate-detector``: data and the default LEC.

* ``make-dataset rover --out DIR`` — render a labelled dataset from the simulated scenes,
  split by scene layout (COCO JSON per split, PNG images);
* ``train-detector --data DIR --out MODEL.safetensors`` — train the CenterNet detector,
  choose its score threshold on the validation split, report validation and test figures
  and save weights + sidecar;
* ``evaluate-detector MODEL|REG.yaml --data DIR`` — precision/recall/F1 on a split, optionally under
  a phenomenon, with the drop relative to clean data and the behaviour category.

See docs/detector.md.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

from anunnaki._blas import torch_threads
from anunnaki._names import check_domain, check_name
from anunnaki.errors import AnunnakiError

_CATEGORY = {0: "unaffected", 1: "degraded", 2: "compromised"}

#: ``train-detector --epochs`` default, the same as ``TrainConfig.epochs`` (a test checks it;
#: not imported from there, which would load torch to build the parser): 14 epochs train the
#: rover default model (2000 images, 128 x 128) in 247 s on 2 threads, inside the 5-minute
#: budget; 18 took about 320 s (docs/detector.md, Results).
DEFAULT_EPOCHS = 14


def add_parser(sub: Any) -> None:
    """Register the three sub-commands."""
    _add_make(sub)
    _add_train(sub)
    _add_evaluate(sub)


# -- argument types --------------------------------------------------------------------------


def _layouts(text: str) -> list[int]:
    """``0-39``, ``1,3,5`` or ``0-9,20-29`` → a list of layout numbers."""
    out: list[int] = []
    for raw in text.split(","):
        part = raw.strip()
        if not part:
            continue
        try:
            if "-" in part:
                lo, hi = (int(v) for v in part.split("-", 1))
                if hi < lo:
                    raise ValueError
                out.extend(range(lo, hi + 1))
            else:
                out.append(int(part))
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"bad layout list {text!r}; write e.g. 0-39 or 1,3,5 or 0-9,20-29"
            ) from None
    if any(v < 0 for v in out):
        raise argparse.ArgumentTypeError(f"layouts are numbers >= 0, got {text!r}")
    return out


def _positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def _unit(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (math.isfinite(value) and 0.0 <= value <= 1.0):
        raise argparse.ArgumentTypeError(f"must be in [0, 1], got {text}")
    return value


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected WIDTHxHEIGHT, e.g. 320x240, got {text!r}"
        ) from None
    if w < 16 or h < 16:
        raise argparse.ArgumentTypeError(f"size must be at least 16x16, got {text}")
    return w, h


def _params(text: str) -> dict[str, float]:
    out: dict[str, float] = {}
    for part in text.split(","):
        name, sep, value = part.partition("=")
        try:
            if not sep or not name.strip():
                raise ValueError
            out[name.strip()] = float(value)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"bad parameters {text!r}; write e.g. density=4,intensity=0.3"
            ) from None
    return out


def _console() -> Console:
    console = Console(highlight=False)
    return console if console.is_terminal else Console(highlight=False, width=120)


# -- the model a command measures: MODEL|REG.yaml --model ID [--shared-classes] -------------
# assess, evaluate-detector, oracle train and oracle evaluate read them alike (issue 22 item 7).


def add_model_options(p: argparse.ArgumentParser, *, dest: str = "model_id") -> None:
    """``--model ID`` (a model of a registry) and ``--shared-classes``."""
    p.add_argument(
        "--model",
        dest=dest,
        metavar="ID",
        help="with a registry: which of its models (default: its default-domain model)",
    )
    p.add_argument(
        "--shared-classes",
        action="store_true",
        help="measure on the class names the model and the data both have, leaving the "
        "others' boxes and detections out (default: refuse differing class lists)",
    )


def shared_view(args: argparse.Namespace, det: Any, *data: Any) -> tuple[Any, ...]:
    """``(det, *data)`` cut to their shared classes with ``--shared-classes``, else as given.

    Every dataset (``None`` passes through) is cut to the classes it shares with *det*.
    """
    if not args.shared_classes:
        return (det, *data)
    from anunnaki.lec import shared_classes

    out: list[Any] = []
    view = det
    for ds in data:
        kept = ds
        if ds is not None:
            view, kept = shared_classes(det, ds)
        out.append(kept)
    return (view, *out)


def classes_counted(det: Any, data: Any) -> dict[str, list[str]]:
    """Which classes a measurement counted, and which of the model's and the data's it left out."""
    mine, theirs = list(det.classes), list(data.classes)
    counted = [c for c in theirs if c in mine]
    return {
        "classes": counted,
        "model_only": [c for c in mine if c not in counted],
        "data_only": [c for c in theirs if c not in counted],
    }


def classes_line(counted: dict[str, list[str]]) -> str:
    """``classes counted: pedestrian (left out: the data's deer)`` for a console."""
    left = [f"the model's {', '.join(counted['model_only'])}"] if counted["model_only"] else []
    left += [f"the data's {', '.join(counted['data_only'])}"] if counted["data_only"] else []
    return f"classes counted: {', '.join(counted['classes'])}" + (
        f" (left out: {'; '.join(left)})" if left else ""
    )


# -- make-dataset ----------------------------------------------------------------------------


def _add_make(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "make-dataset",
        help="render a labelled dataset (COCO, split by scene layout) from a simulated scene",
        description=(
            "Render labelled frames of the simulated rover or UAV scenes into DIR/images/*.png "
            "with one COCO JSON per split (train.json, val.json, test.json). Each scene "
            "layout goes to exactly one split. Defaults: layouts 0-39 / 40-43 / 44-53 at 50 "
            "frames each = 2000 / 200 / 500 images."
        ),
    )
    p.add_argument("platform", choices=("rover", "uav"), help="which simulated scene")
    p.add_argument("--out", "-o", required=True, help="output folder")
    p.add_argument("--train-layouts", type=_layouts, default=list(range(0, 40)), metavar="L")
    p.add_argument("--val-layouts", type=_layouts, default=list(range(40, 44)), metavar="L")
    p.add_argument("--test-layouts", type=_layouts, default=list(range(44, 54)), metavar="L")
    p.add_argument("--per-layout", type=_positive, default=50, help="frames per layout (50)")
    p.add_argument("--width", type=_positive, default=128, help="image width (128)")
    p.add_argument("--height", type=_positive, default=128, help="image height (128)")
    p.add_argument("--seed", type=int, default=0, help="camera/light/pose seed (0)")
    p.add_argument("--workers", type=_positive, default=2, help="rendering processes (2)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing dataset")
    p.add_argument(
        "--min-label-height",
        type=_unit,
        help="smallest labelled box height as a fraction of the image height; smaller "
        "objects become ignore boxes (default: the platform's, rover 0.134, uav 0)",
    )
    p.add_argument(
        "--no-clutter",
        dest="clutter",
        action="store_false",
        help="only the layouts' pedestrians/deer (vehicles for the uav) on bare ground: no "
        "distractors, like a rover scenario with background: false",
    )
    p.add_argument(
        "--min-distance",
        type=float,
        default=None,
        metavar="M",
        help="rover: the nearest the camera comes to the object it aims at (default 1.5 m; "
        "0.4 shows objects filling the frame, as when the rover stops right before one)",
    )
    p.set_defaults(run=_run_make)


def _run_make(args: argparse.Namespace) -> int:
    from anunnaki.datasets import load_split
    from anunnaki.sim import make_dataset

    console = _console()
    start = time.perf_counter()
    paths = make_dataset(
        args.platform,
        args.out,
        train_layouts=args.train_layouts,
        val_layouts=args.val_layouts,
        test_layouts=args.test_layouts,
        per_layout=args.per_layout,
        width=args.width,
        height=args.height,
        seed=args.seed,
        workers=args.workers,
        progress=console.is_terminal,
        overwrite=args.overwrite,
        min_label_height=args.min_label_height,
        clutter=args.clutter,
        min_distance=args.min_distance,
    )
    seconds = time.perf_counter() - start
    table = Table(title=f"{args.platform} dataset in {args.out} ({seconds:.0f} s)")
    for col in ("split", "layouts", "images", "boxes", "ignore", "per class"):
        table.add_column(col, justify="right" if col in ("images", "boxes", "ignore") else "left")
    for split, path in paths.items():
        ds = load_split(path.parent, split)
        layouts = getattr(args, f"{split}_layouts")
        counts = ", ".join(f"{k} {v}" for k, v in ds.class_counts().items())
        table.add_row(
            split, _span(layouts), str(len(ds)), str(ds.num_boxes), str(ds.num_ignore), counts
        )
    console.print(table)
    return 0


def _span(layouts: list[int]) -> str:
    if layouts and layouts == list(range(layouts[0], layouts[-1] + 1)):
        return f"{layouts[0]}-{layouts[-1]}"
    return ",".join(map(str, layouts))


# -- train-detector --------------------------------------------------------------------------


def _add_train(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "train-detector",
        help="train the CenterNet detector on a dataset folder and save it (safetensors)",
        description=(
            "Train the default LEC (a compact CenterNet-style detector) on DATA's train split, "
            "choose the score threshold that maximises F1 on the val split, measure the test "
            "split, and save OUT (.safetensors weights + .json sidecar with the metrics). "
            "--augment trains a robust per-domain model by applying phenomena at random "
            "strengths (see docs/detector.md)."
        ),
    )
    p.add_argument("--data", "-d", required=True, help="dataset folder (train/val/test)")
    p.add_argument("--out", "-o", required=True, help="model file NAME.safetensors")
    p.add_argument(
        "--epochs",
        type=_positive,
        default=DEFAULT_EPOCHS,
        help=f"passes over the data ({DEFAULT_EPOCHS}: the rover default model's, about 4 "
        "minutes for 2000 images at 128x128 on 2 threads)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed for weights/order/augment (0)")
    p.add_argument("--threads", type=_positive, default=2, help="torch threads (2)")
    p.add_argument("--domain", default="default", help="the model's domain (default)")
    p.add_argument("--model-id", help="model id (default: OUT's file name without suffix)")
    p.add_argument(
        "--augment",
        nargs="+",
        default=[],
        metavar="PHENOMENON",
        help="phenomena applied at random strengths during training, e.g. fog raindrop",
    )
    p.add_argument(
        "--augment-prob", type=_unit, default=0.8, help="share of images augmented (0.8)"
    )
    p.add_argument("--batch-size", type=_positive, default=32, help="images per step (32)")
    p.add_argument("--lr", type=float, default=3e-3, help="peak learning rate (3e-3)")
    p.add_argument("--width", type=_positive, default=16, help="network base width (16)")
    p.add_argument("--input-size", type=_size, help="WIDTHxHEIGHT (default: the images')")
    p.add_argument(
        "--stride", type=int, choices=(2, 4), default=4, help="heat-map stride (4; 2 for tiny)"
    )
    p.add_argument(
        "--init", metavar="MODEL", help="start from this model's weights (fine-tune a domain)"
    )
    p.add_argument(
        "--no-ignore",
        action="store_true",
        help="treat the data's ignore boxes as background when training",
    )
    p.add_argument("--json", action="store_true", help="print the sidecar as JSON at the end")
    p.set_defaults(run=_run_train)


def _run_train(args: argparse.Namespace) -> int:
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from anunnaki.datasets import load_split
    from anunnaki.lec import TrainConfig, read_card, save_detector, train_detector
    from anunnaki.phenomena import PHENOMENA

    for name in args.augment:
        PHENOMENA.create(name)  # unknown names fail now, listing the valid ones
    out = Path(args.out)
    if out.suffix != ".safetensors":
        raise AnunnakiError(f"--out {out}: a model file ends in .safetensors")
    if args.model_id is not None:
        check_name(args.model_id, what="--model-id")
    else:
        check_name(out.stem, what=f"the model id (--out {out.name} without .safetensors)",
                   fix="give one with --model-id NAME, or another --out file name")  # fmt: skip
    check_domain(args.domain, what="--domain")
    console = _console()
    train = load_split(args.data, "train", cache=True)
    val = load_split(args.data, "val", cache=True)
    try:
        test = load_split(args.data, "test", cache=True)
    except AnunnakiError:
        test = None
    config = TrainConfig(
        epochs=args.epochs,
        batch_size=args.batch_size,
        lr=args.lr,
        width=args.width,
        seed=args.seed,
        threads=args.threads,
        input_size=args.input_size,
        augment=tuple(args.augment),
        augment_prob=args.augment_prob,
        model_id=args.model_id or out.stem,
        domain=args.domain,
        stride=args.stride,
        init=args.init,
        ignore=not args.no_ignore,
    )
    console.print(
        f"training on {len(train)} images ({train.num_boxes} boxes, {train.num_ignore} ignore "
        f"boxes, classes "
        f"{', '.join(train.classes)}); val {len(val)}, test {len(test) if test else 0}; "
        f"{args.epochs} epochs, {args.threads} threads"
        + (f", augment {' '.join(args.augment)}" if args.augment else "")
        + (f", from {args.init}" if args.init else "")
    )
    with Progress(
        TextColumn("epoch {task.fields[epoch]}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("loss {task.fields[loss]:.3f}  val F1 {task.fields[val_f1]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
        disable=not console.is_terminal,
    ) as bar:
        task = bar.add_task("train", total=None, epoch=0, loss=float("nan"), val_f1="-")

        def on_step(step: int, total: int, info: dict[str, float]) -> None:
            bar.update(
                task, completed=step, total=total, epoch=int(info["epoch"]), loss=info["loss"]
            )

        spent: list[float] = []

        def on_epoch(info: dict[str, float]) -> None:
            bar.update(task, val_f1=f"{info['val_f1']:.3f}")
            spent.append(info["seconds"])
            left = int(info["epochs"]) - int(info["epoch"])
            eta = f", about {sum(spent) / len(spent) * left:.0f} s left" if left > 0 else ""
            console.print(
                f"epoch {int(info['epoch'])}/{int(info['epochs'])}: loss {info['loss']:.3f}, "
                f"val F1 {info['val_f1']:.3f} ({info['seconds']:.0f} s{eta})"
            )

        result = train_detector(
            train, val, config=config, test=test, on_step=on_step, on_epoch=on_epoch
        )
    digest = save_detector(result.detector, out)
    table = Table(title=f"{config.model_id} ({config.domain}), trained in {result.seconds:.0f} s")
    for col in ("split", "precision", "recall", "F1", "tp", "fp", "fn"):
        table.add_column(col, justify="left" if col == "split" else "right")
    for split, m in (("val", result.val), ("test", result.test)):
        if m is not None:
            table.add_row(
                split, f"{m.precision:.3f}", f"{m.recall:.3f}", f"{m.f1:.3f}",
                str(m.tp), str(m.fp), str(m.fn),
            )  # fmt: skip
    console.print(table)
    images_per_s = result.detector.training.get("images_per_second", 0.0)
    console.print(
        f"{images_per_s:.0f} images/s over {config.epochs} epochs; "
        f"score threshold {result.threshold:.3f} (chosen on val); saved {out} "
        f"({out.stat().st_size / 1e6:.2f} MB, sha256 {digest[:16]}…) and {out.with_suffix('.json')}"
    )
    if args.json:
        print(json.dumps(read_card(out).model_dump(mode="json"), indent=2))
    return 0


# -- evaluate-detector -----------------------------------------------------------------------


def _add_evaluate(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "evaluate-detector",
        help="precision/recall/F1 of a model on a dataset split, optionally under a phenomenon",
        description=(
            "Measure MODEL on a split of DATA with the F1 rule of docs/detector.md (IoU >= 0.5, "
            "class-aware greedy matching, the model's own score threshold). With --phenomenon, "
            "every image is perturbed first (at --strength or --params) and the drop relative "
            "to clean data is printed with its behaviour category (0 < 5 %, 1 > 5 %, 2 > 10 %). "
            "A phenomenon that hides objects (raindrop) also gets F1 on the visible boxes "
            "(those less than half hidden) and the ceiling: the F1 of a detector that finds "
            "every visible box and nothing else."
        ),
    )
    p.add_argument(
        "model",
        help="model file (NAME.safetensors or NAME.json), or a model registry (REG.yaml: its "
        "default model, or --model ID; any loader plugin its entries name)",
    )
    add_model_options(p)
    p.add_argument("--data", "-d", required=True, help="dataset folder or COCO JSON")
    p.add_argument("--split", default="test", help="train, val or test (test)")
    p.add_argument("--phenomenon", "-p", help="e.g. fog, raindrop, hsl, fog+raindrop")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--strength", type=_unit, help="phenomenon strength in [0, 1] (1.0)")
    group.add_argument(
        "--params", type=_params, help="exact parameters, e.g. density=4,intensity=0.3"
    )
    group.add_argument(
        "--contexts",
        metavar="random:N",
        help="N contexts drawn uniformly from the phenomenon's parameter space, each applied "
        "to a fixed batch of the split (--batch-images): per-context F1, drop and category, "
        "and their mean F1 at the top level (f1)",
    )
    p.add_argument(
        "--batch-images",
        type=_positive,
        default=64,
        help="with --contexts: images of the split in the fixed batch (64; all if fewer)",
    )
    p.add_argument(
        "--thresholds",
        type=_unit,
        nargs=2,
        default=[0.05, 0.10],
        metavar=("DEGRADED", "COMPROMISED"),
        help="relative F1 drops above which the category is 1 and 2 (0.05 0.10)",
    )
    p.add_argument("--seed", type=int, default=0, help="phenomenon seed (image i: seed + i)")
    p.add_argument("--threshold", type=_unit, help="score threshold (default: the model's)")
    p.add_argument("--threads", type=_positive, default=2, help="torch threads (2)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument(
        "--update-sidecar",
        action="store_true",
        help="re-measure the val and test splits of DATA at the model's threshold and write "
        "them into the model's sidecar (weights unchanged; e.g. after the F1 rule changed)",
    )
    p.set_defaults(run=_run_evaluate)


def _report_head(args: argparse.Namespace, det: Any, model: Any, images: int) -> dict[str, Any]:
    """What every ``evaluate-detector`` report starts with: the model, data and threshold.

    ``model_file`` and ``model_sha256`` are the file that was loaded and measured (the
    weights of a model file, the registry entry's file) and its hash.
    """
    threshold = args.threshold
    return {
        "model": str(args.model),
        "model_id": model.model_id,
        "domain": model.domain,
        "model_file": str(model.file),
        "model_sha256": model.sha256,
        "data": str(args.data),
        "split": args.split,
        "images": images,
        "score_threshold": (
            threshold if threshold is not None else float(getattr(det, "score_threshold", 0.0))
        ),
    }


def _load_evaluated(args: argparse.Namespace) -> tuple[Any, Any]:
    """The model ``evaluate-detector`` measures: ``(detector, resolved model)``."""
    from anunnaki.lec import resolve_model

    model = resolve_model(args.model, args.model_id)
    if args.update_sidecar and model.spec is not None and model.spec.loader is not None:
        raise AnunnakiError(
            f"--update-sidecar writes an anunnaki model file's sidecar; model "
            f"{model.model_id!r} is loaded by {model.spec.loader!r}: put its metrics in the "
            "registry instead"
        )
    if args.update_sidecar and args.shared_classes:
        raise AnunnakiError(
            "--update-sidecar records the model's own figures; drop --shared-classes"
        )
    return model.load(), model


def _check_evaluate_options(args: argparse.Namespace) -> None:
    if args.phenomenon is None and (args.strength is not None or args.params is not None):
        raise AnunnakiError("--strength and --params need --phenomenon")
    if args.contexts is not None:
        from anunnaki.enlil import parse_contexts

        if args.phenomenon is None:
            raise AnunnakiError("--contexts random:N needs --phenomenon P")
        if args.update_sidecar:
            raise AnunnakiError("--update-sidecar measures clean splits; drop --contexts")
        args.contexts = parse_contexts(args.contexts, kinds=("random",))
    low, high = args.thresholds
    if not low < high:
        raise AnunnakiError(
            f"--thresholds {low} {high}: the degraded drop must be below the compromised one"
        )


def _run_evaluate(args: argparse.Namespace) -> int:
    import anunnaki.lec  # noqa: F401  # before torch: its OMP policy

    _check_evaluate_options(args)
    with torch_threads(args.threads):  # as it found them after (an in-process call)
        return _evaluate(args)


def _evaluate(args: argparse.Namespace) -> int:
    from anunnaki.datasets import load_split
    from anunnaki.lec import DetectorError, evaluate_detector
    from anunnaki.phenomena import PHENOMENA

    phen = PHENOMENA.create(args.phenomenon) if args.phenomenon else None
    params = phen.validate(args.params) if phen is not None and args.params else None
    det, model = _load_evaluated(args)
    model_id, domain = model.model_id, model.domain
    if args.contexts is not None:
        return _run_contexts(args, det, model)
    data = load_split(args.data, args.split)
    try:
        counted = classes_counted(det, data)
        det, data = shared_view(args, det, data)
        clean = evaluate_detector(det, data, score_threshold=args.threshold)
        report = _report_head(args, det, model, len(data))
        report |= counted
        report["clean"] = clean.as_dict()
        rows = [("clean", clean)]
        if phen is not None:
            rows += _perturbed(
                args, det, data, phen=phen, params=params, clean=clean, report=report
            )
    except DetectorError as exc:
        raise AnunnakiError(f"{args.model}: model {model_id!r}: {exc}") from None
    if args.update_sidecar:
        report["sidecar"] = _update_sidecar(str(model.file), det, args.data, clean, args.split)
    if args.json:
        print(json.dumps(report))
        return 0
    console = _console()
    table = Table(title=f"{model_id} ({domain}) on {args.split} of {args.data}: {len(data)} images")
    for col in ("condition", "precision", "recall", "F1", "tp", "fp", "fn"):
        table.add_column(col, justify="left" if col == "condition" else "right")
    for name, m in rows:
        table.add_row(
            name, f"{m.precision:.3f}", f"{m.recall:.3f}", f"{m.f1:.3f}",
            str(m.tp), str(m.fp), str(m.fn),
        )  # fmt: skip
    console.print(table)
    console.print(classes_line(counted))
    if args.update_sidecar:
        console.print(f"updated the metrics in {report['sidecar']}")
    if phen is not None:
        _print_perturbed(console, phen.name, report)
    return 0


def _perturbed(
    args: argparse.Namespace,
    det: Any,
    data: Any,
    *,
    phen: Any,
    params: dict[str, float] | None,
    clean: Any,
    report: dict[str, Any],
) -> list[tuple[str, Any]]:
    """Measure under the phenomenon into *report*; the table rows (visible boxes if hidden)."""
    from anunnaki.lec import evaluate_visible

    used = (
        params
        if params is not None
        else phen.strength_params(1.0 if args.strength is None else args.strength)
    )
    measured = evaluate_visible(
        det, data, phenomenon=phen, params=used, seed=args.seed, score_threshold=args.threshold
    )
    perturbed = measured.all
    drop = clean.f1 - perturbed.f1
    rel = drop / clean.f1 if clean.f1 > 0 else 0.0
    category = 2 if rel > args.thresholds[1] else 1 if rel > args.thresholds[0] else 0
    report["phenomenon"] = {"name": phen.name, "params": used, "seed": args.seed}
    report["perturbed"] = perturbed.as_dict()
    report["f1_drop"] = drop
    report["f1_drop_relative"] = rel
    report["category"] = category
    rows = [(phen.name, perturbed)]
    if measured.visible is not None:  # the phenomenon hides objects: visible boxes too
        report["perturbed_visible"] = measured.visible.as_dict()
        report["occlusion"] = {
            "boxes": measured.boxes,
            "hidden_boxes": measured.hidden,
            "hidden_threshold": measured.threshold,
            "ceiling_f1": measured.ceiling,
        }
        rows.append((f"{phen.name}, visible boxes", measured.visible))
    return rows


def _print_perturbed(console: Any, name: str, report: dict[str, Any]) -> None:
    params_text = ", ".join(f"{k}={v:g}" for k, v in report["phenomenon"]["params"].items())
    console.print(
        f"{name} ({params_text}): F1 drop {report['f1_drop']:.3f} "
        f"({100 * report['f1_drop_relative']:.1f} % of clean) → category "
        f"{report['category']} ({_CATEGORY[report['category']]})"
    )
    if "occlusion" in report:
        occ = report["occlusion"]
        console.print(
            f"{occ['hidden_boxes']} of {occ['boxes']} boxes at least "
            f"{100 * occ['hidden_threshold']:.0f} % hidden (ignore boxes on the visible row); "
            f"a detector finding every visible box and nothing else: F1 {occ['ceiling_f1']:.3f}"
        )


def _run_contexts(args: argparse.Namespace, det: Any, model: Any) -> int:
    """``--contexts random:N``: F1 over N uniform contexts on a fixed batch (issue 13, item 1)."""
    import numpy as np

    from anunnaki.enlil import draw_contexts, fixed_batch, resolve_phenomenon, to_phenomenon_vector
    from anunnaki.lec import DetectorError, evaluate_detector

    model_id, domain = model.model_id, model.domain
    phen = resolve_phenomenon(args.phenomenon)
    batch = fixed_batch(args.data, args.split, args.batch_images, seed=args.seed)
    thresholds = (float(args.thresholds[0]), float(args.thresholds[1]))
    counted = classes_counted(det, batch)
    try:
        det, batch = shared_view(args, det, batch)
        clean = evaluate_detector(det, batch, score_threshold=args.threshold)
        drawn = draw_contexts(
            det, batch, phen, args.contexts, clean_f1=clean.f1, thresholds=thresholds,
            seed=args.seed, score_threshold=args.threshold,
        )  # fmt: skip
    except DetectorError as exc:
        raise AnunnakiError(f"{args.model}: model {model_id!r}: {exc}") from None
    items: list[dict[str, Any]] = [
        {
            "params": dict(zip(phen.param_names, r.params.round(6).tolist(), strict=True)),
            "values": phen.from_vector(to_phenomenon_vector(phen, r.params)),
            "f1": r.f1,
            "drop": r.drop,
            "category": r.category,
        }
        for r in drawn.results
    ]
    f1s = np.asarray([r.f1 for r in drawn.results])
    counts = drawn.counts()
    visible = _visible_contexts(args, det, batch, phen=phen, results=drawn.results, items=items)
    report = _report_head(args, det, model, len(batch))
    report |= counted
    report |= {
        "phenomenon": phen.name,
        "param_names": list(phen.param_names),
        "contexts_spec": str(args.contexts),
        "seed": args.seed,
        "thresholds": list(thresholds),
        "clean": clean.as_dict(),
        "f1": float(f1s.mean()),
        "f1_std": float(f1s.std()),
        "f1_min": float(f1s.min()),
        "category_counts": counts,
        "category_fraction": [c / len(items) for c in counts],
        "contexts": items,
    }
    report |= visible
    if args.json:
        print(json.dumps(report))
        return 0
    console = _console()
    table = Table(
        title=f"{model_id} ({domain}) under {len(items)} random {phen.name} contexts, "
        f"{len(batch)} {args.split} images each"
    )
    for col in ("#", *phen.param_names, "F1", "drop", "category"):
        table.add_column(col, justify="right")
    for i, item in enumerate(items):
        values = [f"{item['values'][n]:.3g}" for n in phen.param_names]
        table.add_row(
            str(i), *values, f"{item['f1']:.3f}", f"{100 * item['drop']:.1f} %",
            f"{item['category']} ({_CATEGORY[item['category']]})",
        )  # fmt: skip
    console.print(table)
    console.print(
        f"clean F1 {clean.f1:.3f}; mean F1 under {phen.name} {report['f1']:.3f} "
        f"(min {report['f1_min']:.3f}); categories 0/1/2: {counts[0]}/{counts[1]}/{counts[2]}"
    )
    if visible:
        console.print(
            f"visible boxes (less than half hidden): mean F1 {visible['f1_visible']:.3f}; a "
            f"detector finding every visible box and nothing else: {visible['ceiling_f1']:.3f}"
        )
    console.print(classes_line(counted))
    return 0


def _visible_contexts(
    args: argparse.Namespace,
    det: Any,
    batch: Any,
    *,
    phen: Any,
    results: list[Any],
    items: list[dict[str, Any]],
) -> dict[str, Any]:
    """For a phenomenon that hides objects: each context's F1 on visible boxes and ceiling.

    Adds ``f1_visible``, ``ceiling_f1`` and ``hidden_boxes`` to each of *items*; returns the
    means for the report (empty when the phenomenon has no mask).
    """
    import numpy as np

    from anunnaki.enlil import to_phenomenon_vector
    from anunnaki.lec import evaluate_visible
    from anunnaki.phenomena import HIDDEN

    if not results:
        return {}
    first = phen.from_vector(to_phenomenon_vector(phen, results[0].params))
    if phen.occlusion((8, 8), first, args.seed) is None:
        return {}
    for r, item in zip(results, items, strict=True):
        params = phen.from_vector(to_phenomenon_vector(phen, r.params))
        m = evaluate_visible(
            det, batch, phenomenon=phen, params=params, seed=args.seed,
            score_threshold=args.threshold,
        )  # fmt: skip
        assert m.visible is not None and m.ceiling is not None
        item |= {"f1_visible": m.visible.f1, "ceiling_f1": m.ceiling, "hidden_boxes": m.hidden}
    return {
        "f1_visible": float(np.mean([i["f1_visible"] for i in items])),
        "ceiling_f1": float(np.mean([i["ceiling_f1"] for i in items])),
        "hidden_share": float(
            np.sum([i["hidden_boxes"] for i in items]) / max(1, len(items) * _boxes(batch))
        ),
        "hidden_threshold": HIDDEN,
    }


def _boxes(data: Any) -> int:
    return sum(len(r.labels) for r in data.records)


def _update_sidecar(model: str, det: Any, data: str, measured: Any, split: str) -> str:
    """Write val and test metrics of *det* on *data* into the model's sidecar."""
    from anunnaki.datasets import load_split
    from anunnaki.lec import evaluate_detector, read_card, sidecar_path, update_metrics

    threshold = float(det.score_threshold)
    metrics: dict[str, Any] = {
        **read_card(model).metrics,
        "iou": 0.5,
        "score_threshold": threshold,
        "data": str(data),
    }
    for name in ("val", "test"):
        if name == split:
            metrics[name] = measured.as_dict()
            continue
        try:
            ds = load_split(data, name)
        except AnunnakiError:
            continue
        metrics[name] = evaluate_detector(det, ds, score_threshold=threshold).as_dict()
    update_metrics(model, metrics)
    return str(sidecar_path(model))
