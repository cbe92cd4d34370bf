"""``anunnaki oracle train``: train a model's behavior oracle (docs/enlil.md)."""

from __future__ import annotations

import argparse
import json
from typing import Any

__all__ = ["add_parser"]


def add_parser(sub: Any) -> None:
    """Register ``oracle`` and its sub-commands."""
    p: argparse.ArgumentParser = sub.add_parser(
        "oracle", help="learned behavior oracles (Enlil): train", description=__doc__
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
    t.set_defaults(run=run_train)


def run_train(args: argparse.Namespace) -> int:
    """Train, save, print the oracle's sha256 and val metrics as JSON."""
    from anunnaki.datasets import load_split
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
    )
    oracle = train_oracle(
        load_split(args.data, "train"),
        load_split(args.data, "val"),
        sets,
        model_id=spec.id,
        model_sha256=digest,
        config=config,
    )
    sha = oracle.save(args.out)
    print(json.dumps({"file": str(args.out), "sha256": sha, **oracle.card.metrics}, indent=2))
    return 0
