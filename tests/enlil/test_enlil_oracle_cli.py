"""``anunnaki oracle train`` end to end on a tiny dataset (Monte-Carlo contexts)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from enlil_helpers import tiny_data

pytest.importorskip("torch")

from anunnaki.cli.main import main
from anunnaki.enlil import load_oracle

MODELS = Path(__file__).resolve().parents[2] / "examples" / "models" / "rover.yaml"


def test_oracle_train_random_contexts(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "data"
    for split in ("train", "val"):
        tiny_data(8, seed=len(split)).to_coco(data / f"{split}.json", images_dir=data / "images")
    out = tmp_path / "o" / "rover-default.oracle"
    argv = ["oracle", "train", "--models", str(MODELS), "--model", "rover-default"]
    argv += ["--data", str(data), "--random", "3", "--phenomenon", "fog", "--out", str(out)]
    argv += ["--frames", "32", "--val-frames", "16", "--epochs", "1", "--threads", "1"]
    assert main(argv) == 0
    printed = json.loads(capsys.readouterr().out)
    oracle = load_oracle(out, sha256=printed["sha256"])
    assert oracle.model_id == "rover-default"
    assert oracle.card.model_sha256.startswith("5b47451b")
    assert oracle.card.training["contexts"][0]["source"] == "random"


def test_oracle_train_needs_contexts(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["oracle", "train", "--models", str(MODELS), "--model", "rover-default"]
    assert main([*argv, "--data", str(tmp_path), "--out", str(tmp_path / "x")]) == 2
    assert "give --archive PATH (repeatable) or --random N" in capsys.readouterr().err
