"""Small options of the chain for tests: every stage runs, on a few images, in seconds."""

from __future__ import annotations

from pathlib import Path

TINY = [
    "--budget", "6", "--search", "sobol", "--round", "3", "--batch-images", "4",
    "--workers", "1", "--contexts", "4", "--epochs", "2", "--batch-size", "4",
    "--threads", "1", "--measure-contexts", "3", "--oracle-frames", "24",
    "--oracle-val-frames", "12", "--oracle-epochs", "1", "--oracle-threads", "1",
]  # fmt: skip


def argv(model: Path, data: Path, out: Path, *more: str) -> list[str]:
    """``robustify MODEL --data DATA --phenomenon brightness --domain low_light --out OUT``."""
    return [
        "robustify", str(model), "--data", str(data), "--phenomenon", "brightness",
        "--domain", "low_light", "--id", "rover-enki", "--out", str(out), *TINY, *more,
    ]  # fmt: skip
