"""``anunnaki make-dataset``, ``train-detector`` and ``evaluate-detector`` on a tiny dataset."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from lec_helpers import Trained

from anunnaki.cli.main import main

MODELS = Path(__file__).resolve().parents[2] / "examples" / "models"


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
    import torch

    capsys.readouterr()
    base = ["evaluate-detector", str(trained.model), "--data", str(trained.data)]
    threads = torch.get_num_threads()
    assert main([*base, "--phenomenon", "fog", "--strength", "0.7", "--json", "--threads",
                 str(threads + 1)]) == 0  # fmt: skip
    assert torch.get_num_threads() == threads  # its --threads only while it ran
    report = json.loads(capsys.readouterr().out)
    assert report["clean"]["f1"] == pytest.approx(trained.metrics["test"]["f1"])
    assert report["phenomenon"]["name"] == "fog" and report["category"] in (0, 1, 2)
    assert report["f1_drop"] == pytest.approx(report["clean"]["f1"] - report["perturbed"]["f1"])
    assert "perturbed_visible" not in report and "occlusion" not in report  # fog hides nothing
    assert main([*base, "--split", "val", "--phenomenon", "raindrop", "--params",
                 "x=0.5,y=0.6,radius=0.3"]) == 0  # fmt: skip
    text = capsys.readouterr().out
    assert "clean" in text and "raindrop" in text and "F1 drop" in text and "category" in text
    assert "raindrop, visible boxes" in text and "a detector finding every visible box" in text
    assert main([*base, "--phenomenon", "raindrop", "--params", "x=0.5,y=0.6,radius=0.3",
                 "--json"]) == 0  # fmt: skip
    report = json.loads(capsys.readouterr().out)
    occ, visible = report["occlusion"], report["perturbed_visible"]
    assert occ["hidden_threshold"] == 0.5 and 0 < occ["hidden_boxes"] < occ["boxes"]
    assert visible["tp"] + visible["fn"] == occ["boxes"] - occ["hidden_boxes"]
    assert report["perturbed"]["tp"] + report["perturbed"]["fn"] == occ["boxes"]
    assert visible["fp"] <= report["perturbed"]["fp"]  # a detection on a hidden box is no FP
    assert 0.0 < occ["ceiling_f1"] < 1.0  # what the drop leaves to be found


def test_evaluate_detector_errors(
    trained: Trained, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    assert (
        main(["evaluate-detector", str(tmp_path / "nope.safetensors"), "--data", str(trained.data)])
        == 2
    )
    assert "nope.safetensors: model file not found" in capsys.readouterr().err
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
    assert "f1_visible" not in report and "f1_visible" not in items[0]  # fog hides nothing
    drops = [*base, "-p", "raindrop", "--contexts", "random:3", "--batch-images", "6", "--json"]
    assert main(drops) == 0
    report = json.loads(capsys.readouterr().out)
    for item in report["contexts"]:  # the same measurement, hidden boxes ignored
        assert 0.0 <= item["ceiling_f1"] <= 1.0 and item["hidden_boxes"] >= 0
        if item["hidden_boxes"] == 0:
            assert item["f1_visible"] == pytest.approx(item["f1"])
    assert report["f1_visible"] == pytest.approx(
        sum(i["f1_visible"] for i in report["contexts"]) / 3
    )
    assert report["hidden_threshold"] == 0.5
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


# -- which file is measured, and names (issue 34 items 1, 2 and 12) --------------------------


@pytest.fixture
def rover(tmp_path: Path) -> Path:
    """A copy of the shipped rover-default model (weights and sidecar) in a fresh folder."""
    folder = tmp_path / "models"
    folder.mkdir()
    for suffix in (".safetensors", ".json"):
        shutil.copy(MODELS / f"rover-default{suffix}", folder / f"rover-default{suffix}")
    return folder / "rover-default.safetensors"


@pytest.fixture
def toy_data(tmp_path: Path) -> Path:
    """A four-image test split of the rover's classes (noise images: measuring is what counts)."""
    from anunnaki.datasets import Dataset

    rng = np.random.default_rng(0)
    images = [rng.integers(0, 255, (64, 64, 3), dtype=np.uint8) for _ in range(4)]
    boxes = [[[8.0, 8.0, 30.0, 50.0]] for _ in range(4)]
    ds = Dataset.from_arrays(images, boxes, [[0]] * 4, ("pedestrian", "deer"))
    ds.to_coco(tmp_path / "data" / "test.json")
    return tmp_path / "data"


def test_evaluate_detector_json_states_the_file_and_hash_it_measured(
    rover: Path, toy_data: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from anunnaki.lec import sha256_file

    capsys.readouterr()
    digest = sha256_file(rover)
    for given in (rover, rover.with_suffix(".json")):
        assert main(["evaluate-detector", str(given), "--data", str(toy_data), "--json"]) == 0
        report = json.loads(capsys.readouterr().out)
        assert report["model"] == str(given)
        assert (report["model_file"], report["model_sha256"]) == (str(rover), digest)
    registry = rover.parent / "rover.yaml"
    registry.write_text(
        f"anunnaki: models/1\nmodels:\n  - file: rover-default.safetensors\n    sha256: {digest}\n"
    )
    assert main(["evaluate-detector", str(registry), "--data", str(toy_data), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert (report["model_file"], report["model_sha256"]) == (str(rover), digest)


def test_evaluate_detector_refuses_a_copied_sidecar(
    rover: Path, toy_data: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 34 item 2: corrupt-header.safetensors beside a copy of rover-default.json was
    reported as F1 1.000: the sidecar's weights field loaded rover-default.safetensors."""
    corrupt = rover.with_name("corrupt-header.safetensors")
    corrupt.write_bytes(b"\xff\xff\xff\xff\xff\xff\xff\x7f{corrupt")
    shutil.copy(rover.with_suffix(".json"), corrupt.with_suffix(".json"))
    capsys.readouterr()
    code = main(["evaluate-detector", str(corrupt), "--data", str(toy_data), "--json"])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert err.startswith(f"error: {corrupt.with_suffix('.json')}: weights: the sidecar names "
                          "the weights 'rover-default.safetensors', not "
                          "'corrupt-header.safetensors'")  # fmt: skip
    assert "Traceback" not in err
    # with its own sidecar (its name, its hash) the corrupt file is read, and refused
    from anunnaki.lec import sha256_file

    card = json.loads(corrupt.with_suffix(".json").read_text())
    card.update(weights=corrupt.name, sha256=sha256_file(corrupt))
    corrupt.with_suffix(".json").write_text(json.dumps(card))
    assert main(["evaluate-detector", str(corrupt), "--data", str(toy_data)]) == 2
    err = capsys.readouterr().err
    assert (
        err.startswith(f"error: {corrupt}: not a valid safetensors file") and "Traceback" not in err
    )


def test_a_misspelt_model_file_is_named_with_a_close_name(
    rover: Path, toy_data: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 34 item 12: rover-defualt.safetensors was reported as 'rover-defualt.json: model
    sidecar not found'."""
    typo = rover.with_name("rover-defualt.safetensors")
    capsys.readouterr()
    assert main(["evaluate-detector", str(typo), "--data", str(toy_data)]) == 2
    err = capsys.readouterr().err
    assert err.strip() == (f"error: {typo}: model file not found (hint: did you mean {rover}?)")
    nowhere = rover.parent / "gone" / "rover-default.safetensors"
    assert main(["evaluate-detector", str(nowhere), "--data", str(toy_data)]) == 2
    err = capsys.readouterr().err
    assert f"{nowhere}: model file not found" in err and f"no folder {nowhere.parent}" in err
    rover.unlink()  # the weights gone, the sidecar there: the weights are named
    assert main(["evaluate-detector", str(rover), "--data", str(toy_data)]) == 2
    assert f"error: {rover}: model weights not found" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("option", "value"),
    [("--model-id", "../x"), ("--model-id", "/tmp/x"), ("--model-id", "a\\b"),
     ("--model-id", "a\x00b"), ("--model-id", ""), ("--domain", "fog/../x y"),
     ("--domain", "heavy-fog"), ("--domain", "")],
)  # fmt: skip
def test_train_detector_refuses_an_id_or_domain_that_is_no_name(
    tmp_path: Path, option: str, value: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """The id and the domain become file names later (robustify, registries)."""
    out = tmp_path / "m.safetensors"
    capsys.readouterr()
    code = main(["train-detector", "--data", str(tmp_path / "no-data"), "--out", str(out),
                 option, value])  # fmt: skip
    assert code == 2
    assert f"error: {option} {value!r} is not allowed: a " in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
    code = main(["train-detector", "--data", "d", "--out", str(tmp_path / "my model.safetensors")])
    assert code == 2
    err = capsys.readouterr().err
    assert "the model id (--out my model.safetensors without .safetensors) 'my model'" in err
    assert "--model-id NAME" in err


def test_train_config_refuses_them_as_train_detector_does() -> None:
    from anunnaki.lec import DetectorError, TrainConfig

    with pytest.raises(DetectorError, match=r"TrainConfig: model id '\.\./x' is not allowed"):
        TrainConfig(model_id="../x")
    with pytest.raises(DetectorError, match=r"TrainConfig: domain 'a/b' is not allowed"):
        TrainConfig(domain="a/b")
    assert TrainConfig(model_id="rover-fog", domain="fog").model_id == "rover-fog"
    assert TrainConfig(domain="rover-hsl").domain == "rover-hsl"  # a label; registries want fog
