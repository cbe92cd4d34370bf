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
    # the architecture and the seed: in the report and in the card
    assert printed["architecture"] == oracle.card.architecture == "small_cnn"
    assert printed["seed"] == oracle.card.training["config"]["seed"] == 0


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


def _train_argv(data: Path, out: Path) -> list[str]:
    argv = ["oracle", "train", "--models", str(MODELS), "--model", "rover-default"]
    argv += ["--data", str(data), "--random", "3", "--phenomenon", "fog", "--out", str(out)]
    return [*argv, "--frames", "32", "--val-frames", "16", "--epochs", "1", "--threads", "1"]


def test_oracle_train_several_seeds_of_an_architecture(
    trained: tuple[Path, Path, dict[str, Any]],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    data = trained[0]
    out = tmp_path / "rover-default.oracle"
    argv = [*_train_argv(data, out), "--architecture", "patch_cnn", "--seeds", "3,5"]
    capsys.readouterr()
    assert main([*argv, "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["architecture"] == "patch_cnn" and "file" not in report
    assert [s["seed"] for s in report["seeds"]] == [3, 5]
    for entry in report["seeds"]:  # one file per seed, named so, its card saying both
        assert entry["file"] == f"{out}.seed{entry['seed']}"
        oracle = load_oracle(entry["file"], sha256=entry["sha256"])
        assert oracle.card.architecture == "patch_cnn"
        assert oracle.card.training["config"]["seed"] == entry["seed"]
        assert oracle.card.metrics["val"] == entry["val"]
    assert not out.with_name(out.name + ".safetensors").exists()
    f1 = [s["val"]["macro_f1"] for s in report["seeds"]]
    spread = report["spread"]["macro_f1"]
    assert spread["mean"] == pytest.approx(sum(f1) / 2)
    assert spread["spread"] == pytest.approx(abs(f1[0] - f1[1]))
    assert spread["sd"] == pytest.approx(abs(f1[0] - f1[1]) / 2**0.5)
    assert set(report["spread"]) >= {"accuracy", "macro_f1", "ece"}
    # N seeds from --seed on, and the table: a row per seed, then mean, SD and spread
    assert main([*_train_argv(data, out), "--seed", "7", "--seeds", "2"]) == 0
    printed = capsys.readouterr()
    table = printed.out
    assert "seed 8: epochs 1/1" in printed.err  # the progress names the seed (a log's lines)
    for row in ("seed 7", "seed 8", "mean", "SD", "spread (max - min)", "(small_cnn)"):
        assert row in table
    assert Path(f"{out}.seed8.safetensors").exists() and Path(f"{out}.seed8.json").exists()


def test_oracle_train_bad_architecture_or_seeds(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = _train_argv(tmp_path, tmp_path / "x")
    assert main([*argv, "--architecture", "resnet"]) == 2
    err = capsys.readouterr().err
    assert "--architecture 'resnet': no such oracle architecture" in err
    assert "patch_cnn, small_cnn" in err
    for bad in ("0,0", "zero", "0", "-1,2"):
        assert main([*argv, f"--seeds={bad}"]) == 2
        assert "give a number of seeds" in capsys.readouterr().err
