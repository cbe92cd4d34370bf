"""``anunnaki oracle train`` and ``oracle evaluate`` end to end on a tiny dataset."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import pytest
from enlil_helpers import tiny_data

pytest.importorskip("torch")

from anunnaki.cli.main import main
from anunnaki.enlil import load_oracle

MODELS = Path(__file__).resolve().parents[2] / "examples" / "models" / "rover.yaml"


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, dict[str, Any]]:
    """A tiny dataset and an oracle trained on it by the CLI (Monte-Carlo contexts)."""
    tmp = tmp_path_factory.mktemp("oracle-cli")
    data = tmp / "data"
    for split in ("train", "val", "test"):
        tiny_data(6, seed=len(split)).to_coco(data / f"{split}.json", images_dir=data / "images")
    out = tmp / "o" / "rover-default.oracle"
    argv = ["oracle", "train", "--models", str(MODELS), "--model", "rover-default"]
    argv += ["--data", str(data), "--random", "3", "--phenomenon", "fog", "--out", str(out)]
    argv += ["--frames", "32", "--val-frames", "16", "--epochs", "1", "--threads", "1", "--json"]
    import contextlib
    import io

    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(argv) == 0
    return data, out, json.loads(printed.getvalue())


def test_oracle_train_random_contexts(trained: tuple[Path, Path, dict[str, Any]]) -> None:
    _, out, printed = trained
    oracle = load_oracle(out, sha256=printed["sha256"])
    assert oracle.model_id == "rover-default"
    assert oracle.card.model_sha256.startswith("5b47451b")
    assert oracle.card.training["contexts"][0]["source"] == "random"


def test_oracle_train_needs_contexts(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["oracle", "train", "--models", str(MODELS), "--model", "rover-default"]
    assert main([*argv, "--data", str(tmp_path), "--out", str(tmp_path / "x")]) == 2
    assert "give --archive PATH (repeatable) or --random N" in capsys.readouterr().err


def test_oracle_evaluate_scores_the_oracle_and_baselines(
    trained: tuple[Path, Path, dict[str, Any]], capsys: pytest.CaptureFixture[str]
) -> None:
    data, out, _ = trained
    capsys.readouterr()
    argv = ["oracle", "evaluate", "--models", str(MODELS), "--model", "rover-default"]
    argv += ["--data", str(data), "-p", "fog", "--contexts", "random:2", "--seed", "1"]
    argv += ["--oracle", f"enlil={out}", "--baseline", "max-score", "--fit-contexts", "random:2"]
    argv += ["--frames-per-context", "5", "--batch-images", "3"]
    assert main([*argv, "--threads", "1", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert set(report["predictors"]) == {"enlil", "max-score"}
    # every figure beside the labels' own agreement, measured on a second batch of 3
    ceiling = report["ceiling"]
    assert ceiling["batch_images"] == 3 and ceiling["contexts"] == 2
    assert {"kappa", "macro_f1", "drop_noise", "drop"} <= set(ceiling)
    for figures in report["predictors"].values():
        assert set(figures["of_ceiling"]) == {"macro_f1", "kappa"} and "kappa" in figures
    # the drop predicted by the baseline's curve (fitted on val) against the measured drop
    assert set(report["predictors"]["max-score"]["drop"]) >= {"rmse", "spearman"}
    assert report["model_id"] == "rover-default" and report["split"] == "test"
    assert report["test"]["contexts"] == 2 and report["test"]["frames"] == 10
    # the first predictor's figures are also the top level (the oracle's)
    for key in ("accuracy", "macro_f1", "per_category_recall", "confusion", "ece"):
        assert report[key] == report["predictors"]["enlil"][key]
    assert "context_error" in report and report["window"]["frames"] == 5
    assert main(argv) == 0
    assert "macro-F1" in capsys.readouterr().out


def test_oracle_evaluate_needs_an_oracle(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import shutil

    for suffix in (".safetensors", ".json"):  # a registry entry without an oracle
        shutil.copy(MODELS.parent / f"rover-default{suffix}", tmp_path / f"m{suffix}")
    digest = hashlib.sha256((tmp_path / "m.safetensors").read_bytes()).hexdigest()
    registry = tmp_path / "reg.yaml"
    registry.write_text(
        "anunnaki: models/1\nmodels:\n"
        f"  - {{id: rover-default, domain: default, file: m.safetensors, sha256: {digest}}}\n"
    )
    argv = ["oracle", "evaluate", "--models", str(registry), "--model", "rover-default"]
    argv += ["--data", str(tmp_path), "-p", "fog"]
    assert main([*argv, "--contexts", "some:3"]) == 2
    assert "write random:N or balanced:N" in capsys.readouterr().err
    assert main(argv) == 2
    assert "names no oracle; give --oracle FILE" in capsys.readouterr().err
