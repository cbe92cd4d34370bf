"""Any model, from configuration (paper RQ2; issue 22, item 7).

A third-party person detector (``red_person_plugin``: one class, ``pedestrian``) is named by
a registry YAML (``loader: red_person``) and, through ``REG.yaml --model ID``, searched by
``assess``, given an oracle by ``oracle train`` and scored by ``oracle evaluate`` and
``evaluate-detector``, on data of two classes (``pedestrian``, ``deer``) with
``--shared-classes``; each says which classes counted.
"""

from __future__ import annotations

import hashlib
import json
import re
import textwrap
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from red_person_plugin import RedPerson, RedPersonDetector

from anunnaki.cli.main import main
from anunnaki.datasets import Dataset
from anunnaki.lec import (
    ARCHITECTURES,
    DetectorError,
    ModelRegistryError,
    UnknownModelError,
    resolve_model,
    shared_classes,
)

CLASSES = ("pedestrian", "deer")


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def two_class_data(n: int, seed: int) -> Dataset:
    """*n* 64 x 64 grey images, each with a red pedestrian and a green deer."""
    rng = np.random.default_rng(seed)
    images, boxes, labels = [], [], []
    for _ in range(n):
        image = np.full((64, 64, 3), 90, np.uint8)
        x, y = (int(v) for v in rng.integers(4, 24, 2))
        image[y : y + 16, x : x + 12] = (200 + int(rng.integers(0, 50)), 40, 40)
        image[44:60, 40:60] = (40, 160, 40)
        images.append(image)
        boxes.append([[x, y, x + 12, y + 16], [40, 44, 60, 60]])
        labels.append([0, 1])
    return Dataset.from_arrays(images, boxes, labels, CLASSES)


@pytest.fixture
def plugin() -> Iterator[None]:
    ARCHITECTURES.register(RedPerson)
    try:
        yield
    finally:
        ARCHITECTURES.unregister("red_person")


@pytest.fixture(scope="module")
def setup(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A registry naming the plugin's model (and a native one first), and a dataset folder."""
    tmp = tmp_path_factory.mktemp("any-model")
    data = tmp / "data"
    for i, split in enumerate(("train", "val", "test")):
        drawn = two_class_data(8, seed=i)
        named = [replace(r, file_name=f"{split}-{r.file_name}") for r in drawn.records]
        Dataset(CLASSES, named).to_coco(data / f"{split}.json", images_dir=data / "images")
    models = tmp / "models"
    models.mkdir()
    person = models / "person.json"
    person.write_text(json.dumps({"model_id": "person-tf", "domain": "fog", "red": 150}))
    other = models / "other.json"
    other.write_text(json.dumps({"model_id": "other", "domain": "default", "red": 250}))
    registry = models / "registry.yaml"
    registry.write_text(
        textwrap.dedent(
            f"""\
            anunnaki: models/1
            models:
              - {{id: other, domain: default, loader: red_person, file: other.json,
                  sha256: {sha(other)}}}
              - {{id: person, domain: fog, loader: red_person, file: person.json,
                  sha256: {sha(person)}}}
            """
        )
    )
    return registry, data


def run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


def test_one_resolver_names_a_registry_model_or_a_file(
    setup: tuple[Path, Path], plugin: None
) -> None:
    registry, _ = setup
    model = resolve_model(registry, "person")
    assert (model.model_id, model.domain, model.sha256) == (
        "person", "fog", sha(registry.parent / "person.json"))  # fmt: skip
    assert model.spec is not None and model.spec.loader == "red_person"
    assert model.load().classes == ("pedestrian",)
    assert resolve_model(registry).model_id == "other"  # the default-domain model
    with pytest.raises(UnknownModelError, match=r"unknown model 'nope'.*other \(default\)"):
        resolve_model(registry, "nope")
    with pytest.raises(ModelRegistryError, match=r"--model x picks a model of a registry"):
        resolve_model(registry.parent / "person.json", "x")


def test_shared_classes_drop_the_other_boxes_and_detections() -> None:
    data = two_class_data(2, seed=0)

    class Both:
        model_id, domain, classes = "both", "default", ("deer", "cat", "pedestrian")

        def detect(self, images: Any) -> list[Any]:
            from anunnaki.lec import DetectionResult

            boxes = np.asarray([[0, 0, 5, 5], [1, 1, 6, 6], [2, 2, 7, 7]], np.float32)
            return [DetectionResult(boxes, np.asarray([0, 1, 2]), np.ones(3, np.float32))
                    for _ in images]  # fmt: skip

    det, kept = shared_classes(Both(), data)
    assert kept.classes == CLASSES and det.classes == CLASSES  # the cat is left out
    (result,) = det.detect([data.image(0)])
    assert result.labels.tolist() == [1, 0]  # deer, pedestrian renumbered to the data's
    assert result.boxes.tolist() == [[0, 0, 5, 5], [2, 2, 7, 7]]
    person, cut = shared_classes(RedPersonDetector("p", "default", 150), data)
    assert cut.classes == ("pedestrian",) and cut.num_boxes == 2  # the deer boxes are gone
    assert isinstance(person, RedPersonDetector)  # its classes are all shared: not wrapped
    cats = Dataset.from_arrays([data.image(0)], [[]], [[]], ("cat",))
    with pytest.raises(DetectorError, match=r"no class in common.*labelled with \(some of\)"):
        shared_classes(person, cats)


def test_evaluate_detector_measures_a_subset_detector_on_the_shared_classes(
    setup: tuple[Path, Path], plugin: None, capsys: pytest.CaptureFixture[str]
) -> None:
    registry, data = setup
    base = ["evaluate-detector", str(registry), "--model", "person", "--data", str(data)]
    code, _, err = run(base, capsys)
    assert code == 2
    assert "['pedestrian'] are not the dataset's ['pedestrian', 'deer']" in err
    assert "--shared-classes" in err
    code, out, err = run([*base, "--shared-classes", "--json"], capsys)
    assert code == 0, err
    report = json.loads(out)
    assert (report["model_id"], report["domain"]) == ("person", "fog")
    assert (report["classes"], report["data_only"], report["model_only"]) == (
        ["pedestrian"], ["deer"], [])  # fmt: skip
    assert report["clean"]["f1"] == 1.0 and report["clean"]["tp"] == 8
    code, out, err = run([*base, "--shared-classes"], capsys)
    assert code == 0, err
    assert "classes counted: pedestrian (left out: the data's deer)" in out


def test_assess_oracle_train_and_evaluate_a_plugin_model(
    setup: tuple[Path, Path], plugin: None, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("torch")
    from anunnaki.enlil import load_oracle, read_archive

    registry, data = setup
    model = ["--model", "person", "--shared-classes"]
    archive = tmp_path / "archive"
    assess = ["assess", str(registry), "--data", str(data), "-p", "brightness", "--budget", "6",
              "--search", "sobol", "--batch-images", "4", "--round", "3", "--workers", "1",
              "--out", str(archive)]  # fmt: skip
    code, _, err = run([*assess, "--model", "person"], capsys)
    assert code == 2 and "--shared-classes" in err  # refused before any evaluation
    code, out, err = run([*assess, *model, "--json"], capsys)
    assert code == 0, err
    summary = json.loads(out)
    assert summary["evaluations"] == 6 and summary["model_id"] == "person"
    assert summary["clean_f1"] == 1.0  # the deer left out, every pedestrian found
    assert summary["classes"] == ["pedestrian"] and summary["data_only"] == ["deer"]
    meta = read_archive(archive).meta
    assert (meta.model_id, meta.sha256) == ("person", sha(registry.parent / "person.json"))
    assert meta.extra["classes"]["classes"] == ["pedestrian"]

    oracle = tmp_path / "person.oracle"
    train = ["oracle", "train", "--models", str(registry), "--model", "person", "--data",
             str(data), "--archive", str(archive), "--out", str(oracle), "--frames", "24",
             "--val-frames", "12", "--epochs", "1", "--threads", "1"]  # fmt: skip
    code, out, err = run([*train, "--json"], capsys)
    assert code == 0, err
    printed = json.loads(out)
    trained = load_oracle(oracle, sha256=printed["sha256"])
    assert trained.model_id == "person"
    assert trained.card.model_sha256 == sha(registry.parent / "person.json")

    evaluate = ["oracle", "evaluate", "--models", str(registry), *model, "--data", str(data),
                "-p", "brightness", "--contexts", "random:2", "--oracle", str(oracle),
                "--frames-per-context", "2", "--window", "2", "--batch-images", "4", "--threads",
                "1"]  # fmt: skip
    code, out, err = run([*evaluate, "--json"], capsys)
    assert code == 0, err
    report = json.loads(out)
    assert report["model_id"] == "person" and report["classes"] == ["pedestrian"]
    assert report["test"]["contexts"] == 2


def test_oracle_train_shows_progress_a_table_and_warns_without_category_1(
    setup: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A model no phenomenon moves (fixed boxes) gives only category-0 contexts: warned."""
    pytest.importorskip("torch")
    from fixed_boxes_plugin import FixedBoxes, write_model

    _, data = setup
    model, names = write_model(tmp_path, boxes=((4, 4, 16, 20, "pedestrian", 0.9),))
    registry = tmp_path / "registry.yaml"
    registry.write_text(
        "anunnaki: models/1\nmodels:\n  - {id: fixed, domain: default, loader: fixed_boxes, "
        f"file: {model.name}, options: {{classes: {names.name}}}, sha256: "
        f"{{{model.name}: {sha(model)}, {names.name}: {sha(names)}}}}}\n"
    )
    ARCHITECTURES.register(FixedBoxes)
    try:
        code, out, err = run(
            ["oracle", "train", "--models", str(registry), "--data", str(data), "--random", "3",
             "-p", "fog", "--out", str(tmp_path / "fixed.oracle"), "--frames", "16",
             "--val-frames", "8", "--epochs", "2", "--threads", "1"],
            capsys,
        )  # fmt: skip
    finally:
        ARCHITECTURES.unregister("fixed_boxes")
    assert code == 0, err
    assert "hold no category-1 (degraded) context (categories 0/1/2: 3/0/0)" in err
    assert "the oracle cannot learn that category" in err and "--budget" in err
    assert "epochs 1/2" in err and "epochs 2/2" in err  # a line per epoch in a log
    assert "oracle of fixed" in out and "3/0/0" in out and "macro-F1" in out
    assert re.search(r"sha256: [0-9a-f]{64}}", out)  # one line to paste into the registry
    assert "classes counted: pedestrian, deer" in err
    assert not out.lstrip().startswith("{")  # the JSON only with --json


def test_oracle_train_measures_random_contexts_on_the_shared_classes(
    setup: tuple[Path, Path], plugin: None, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``oracle train --random`` measures the plugin model itself: shared classes on request."""
    pytest.importorskip("torch")
    from anunnaki.enlil import load_oracle

    registry, data = setup
    out_file = tmp_path / "mc.oracle"
    train = ["oracle", "train", "--models", str(registry), "--model", "person", "--data",
             str(data), "--random", "3", "-p", "brightness", "--out", str(out_file),
             "--frames", "16", "--val-frames", "8", "--epochs", "1", "--threads", "1"]  # fmt: skip
    code, _, err = run(train, capsys)
    assert code == 2 and "--shared-classes" in err  # refused before any training
    assert not out_file.with_name("mc.oracle.safetensors").exists()
    code, out, err = run([*train, "--shared-classes", "--json"], capsys)
    assert code == 0, err
    report = json.loads(out)
    assert report["model_id"] == "person"
    assert (report["classes"], report["data_only"], report["model_only"]) == (
        ["pedestrian"], ["deer"], [])  # fmt: skip
    assert "classes counted: pedestrian (left out: the data's deer)" in err
    trained = load_oracle(out_file, sha256=report["sha256"])
    assert trained.card.model_sha256 == sha(registry.parent / "person.json")
    # oracle evaluate measures the model too: refused without --shared-classes, naming it
    evaluate = ["oracle", "evaluate", "--models", str(registry), "--model", "person", "--data",
                str(data), "-p", "brightness", "--contexts", "random:2", "--oracle",
                str(out_file), "--frames-per-context", "2", "--window", "2", "--batch-images",
                "4", "--threads", "1"]  # fmt: skip
    code, _, err = run(evaluate, capsys)
    assert code == 2 and "--shared-classes" in err
