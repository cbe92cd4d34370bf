"""``anunnaki make-dataset``, ``train-detector`` and ``evaluate-detector`` on a tiny dataset."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from lec_helpers import Trained

from anunnaki.cli.main import main


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    pytest.importorskip("pybullet")
    out = tmp_path_factory.mktemp("cli") / "tiny"
    code = main(
        [
            "make-dataset", "rover", "--out", str(out), "--train-layouts", "0-1",
            "--val-layouts", "2", "--test-layouts", "3", "--per-layout", "3",
            "--width", "64", "--height", "64", "--workers", "1",
        ]
    )  # fmt: skip
    assert code == 0
    return out


def test_make_dataset(tiny: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert {p.name for p in tiny.iterdir()} == {"images", "train.json", "val.json", "test.json"}
    assert len(list((tiny / "images").glob("*.png"))) == 12
    code = main(["make-dataset", "rover", "--out", str(tiny), "--per-layout", "1"])
    assert code == 2
    assert "already holds a dataset" in capsys.readouterr().err


def test_train_detector(tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    out = tmp_path / "m.safetensors"
    code = main(
        [
            "train-detector", "--data", str(tiny), "--out", str(out), "--epochs", "1",
            "--seed", "1", "--width", "8", "--augment", "fog", "raindrop", "--domain", "fog",
            "--json",
        ]
    )  # fmt: skip
    assert code == 0
    text = capsys.readouterr().out
    assert "score threshold" in text and "chosen on val" in text and "test" in text
    assert re.search(r"epoch 1/1: loss \d+\.\d{3}, val F1 \d\.\d{3} \(\d+ s\)", text), text
    card = json.loads(text[text.index("{") :])
    assert card["domain"] == "fog" and card["model_id"] == "m"
    assert card["training"]["augment"] == ["fog", "raindrop"] and "test" in card["metrics"]
    assert out.is_file() and out.with_suffix(".json").is_file()


def test_train_detector_progress_bar(
    tiny: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """On a terminal, the bar counts the optimiser steps up to the total, epoch by epoch."""
    from io import StringIO

    from rich.console import Console

    from anunnaki.cli import _detector

    screen = StringIO()
    console = Console(file=screen, force_terminal=True, width=120, highlight=False)
    monkeypatch.setattr(_detector, "_console", lambda: console)
    out = tmp_path / "m.safetensors"
    args = ["train-detector", "--data", str(tiny), "--out", str(out), "--epochs", "3",
            "--batch-size", "4", "--width", "8"]  # fmt: skip
    assert main(args) == 0
    text = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", screen.getvalue())  # without ANSI codes
    # 6 training images in batches of 4: 2 steps an epoch, 6 in all; the last frame drawn
    # shows them all done, in epoch 3.
    assert "3 epochs" in text
    assert re.search(r"epoch 3 .*\b6/6\b", text), text
    assert re.search(r"epoch 3/3: loss .*, val F1 \d\.\d{3}", text), text  # one line each
    assert re.search(r"val F1 \d\.\d{3}\s", text)  # and the bar shows the latest
    assert not re.search(r"\b[7-9]/6\b", text)  # never beyond the total


def test_train_detector_default_epochs() -> None:
    from anunnaki.cli.main import build_parser

    args = build_parser().parse_args(["train-detector", "--data", "d", "--out", "m"])
    assert args.epochs == 14  # within the 5-minute budget (docs/detector.md)


def test_train_detector_errors(
    tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    assert main(["train-detector", "--data", str(tiny), "--out", str(tmp_path / "m.pt")]) == 2
    assert "ends in .safetensors" in capsys.readouterr().err
    args = ["train-detector", "--data", str(tiny), "--out", str(tmp_path / "m.safetensors")]
    assert main([*args, "--augment", "smog"]) == 2
    assert "smog" in capsys.readouterr().err
    assert main(["train-detector", "--data", str(tmp_path), "--out", "x.safetensors"]) == 2
    assert "no 'train' split here" in capsys.readouterr().err


def test_evaluate_detector(trained: Trained, capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    base = ["evaluate-detector", str(trained.model), "--data", str(trained.data)]
    assert main([*base, "--phenomenon", "fog", "--strength", "0.7", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["clean"]["f1"] == pytest.approx(trained.metrics["test"]["f1"])
    assert report["phenomenon"]["name"] == "fog" and report["category"] in (0, 1, 2)
    assert report["f1_drop"] == pytest.approx(report["clean"]["f1"] - report["perturbed"]["f1"])
    assert main([*base, "--split", "val", "--phenomenon", "raindrop", "--params",
                 "x=0.5,y=0.6,radius=0.3"]) == 0  # fmt: skip
    text = capsys.readouterr().out
    assert "clean" in text and "raindrop" in text and "F1 drop" in text and "category" in text


def test_evaluate_detector_errors(
    trained: Trained, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    assert (
        main(["evaluate-detector", str(tmp_path / "nope.safetensors"), "--data", str(trained.data)])
        == 2
    )
    assert "nope.json: model sidecar not found" in capsys.readouterr().err
    base = ["evaluate-detector", str(trained.model), "--data", str(trained.data)]
    assert main([*base, "--strength", "0.5"]) == 2
    assert "need --phenomenon" in capsys.readouterr().err
    assert main([*base, "--phenomenon", "fog", "--params", "density=40"]) == 2
    assert "density" in capsys.readouterr().err


def test_evaluate_detector_random_contexts(
    trained: Trained, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 13, item 1: F1 over N uniform contexts of a fixed batch, per-context rows."""
    capsys.readouterr()
    base = ["evaluate-detector", str(trained.model), "--data", str(trained.data)]
    args = [*base, "-p", "fog", "--contexts", "random:4", "--batch-images", "6", "--seed", "3"]
    assert main([*args, "--thresholds", "0.02", "0.2", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["images"] == 6 and report["contexts_spec"] == "random:4"
    assert report["thresholds"] == [0.02, 0.2] and report["param_names"] == ["density", "intensity"]
    items = report["contexts"]
    assert len(items) == 4 and sum(report["category_counts"]) == 4
    clean = report["clean"]["f1"]
    for item in items:
        assert set(item["params"]) == {"density", "intensity"}
        assert all(0.0 <= v <= 1.0 for v in item["params"].values())
        assert item["drop"] == pytest.approx(max(0.0, (clean - item["f1"]) / clean))
        rel = item["drop"]
        assert item["category"] == (2 if rel > 0.2 else 1 if rel > 0.02 else 0)
    assert report["f1"] == pytest.approx(sum(i["f1"] for i in items) / 4)
    # the same seed draws the same contexts; the table shows them
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "4 random fog contexts" in text and "categories 0/1/2" in text


def test_evaluate_detector_contexts_errors(
    trained: Trained, capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    base = ["evaluate-detector", str(trained.model), "--data", str(trained.data)]
    assert main([*base, "--contexts", "random:3"]) == 2
    assert "needs --phenomenon" in capsys.readouterr().err
    assert main([*base, "-p", "fog", "--contexts", "balanced:3"]) == 2
    assert "write random:N with N >= 1" in capsys.readouterr().err
    assert main([*base, "-p", "fog", "--contexts", "random:2", "--thresholds", "0.2", "0.1"]) == 2
    assert "degraded drop must be below" in capsys.readouterr().err
