"""A detector that is not an anunnaki model file, deployed from a registry YAML.

The plugin (``fixed_boxes_plugin.FixedBoxes``) stands for a third-party package wrapping an
ONNX or TensorFlow model: a registry entry names it (``loader: fixed_boxes``), the registry
pins every file it reads, and the same YAML serves ``load_registry``, the LEC node,
``anunnaki evaluate-detector`` and ``anunnaki sim --models``.
"""

from __future__ import annotations

import hashlib
import json
import sys
import textwrap
import threading
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest
from fixed_boxes_plugin import FixedBoxes, FixedBoxesDetector, write_model

from anunnaki.bus import Sample, open_bus
from anunnaki.cli.main import main
from anunnaki.errors import ModelFileError
from anunnaki.lec import (
    ARCHITECTURES,
    Detector,
    LecNode,
    ModelIntegrityError,
    ModelRegistry,
    ModelRegistryError,
    load_registry,
)
from anunnaki.messages import Detections, Image


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def plugin() -> Iterator[None]:
    ARCHITECTURES.register(FixedBoxes)
    try:
        yield
    finally:
        ARCHITECTURES.unregister("fixed_boxes")


def write_registry(folder: Path, *, sha256: str | None = None, extra: str = "") -> Path:
    model, names = write_model(folder)
    pins = sha256 or f"{{{model.name}: {sha(model)}, {names.name}: {sha(names)}}}"
    path = folder / "registry.yaml"
    path.write_text(
        textwrap.dedent(
            f"""\
            anunnaki: models/1
            models:
              - id: fixed-default
                domain: default
                loader: fixed_boxes
                file: {model.name}
                options: {{classes: {names.name}, score_threshold: 0.5}}
                sha256: {pins}
            """
        )
        + extra
    )
    return path


def test_a_registry_entry_names_its_loader(tmp_path: Path, plugin: None) -> None:
    registry = load_registry(write_registry(tmp_path))
    spec = registry.default
    assert (spec.loader, spec.options) == ("fixed_boxes", {"classes": "classes.txt",
                                                          "score_threshold": 0.5})  # fmt: skip
    assert registry.files(spec) == [tmp_path / "fixed-default.json", tmp_path / "classes.txt"]
    det = registry.load(spec)
    assert isinstance(det, FixedBoxesDetector) and isinstance(det, Detector)
    assert det.classes == ("pedestrian", "deer") and det.score_threshold == 0.5
    (result,) = det.detect(np.zeros((32, 32, 3), np.uint8))
    assert result.boxes.tolist() == [[4, 4, 20, 30]] and result.labels.tolist() == [0]


def test_every_file_the_loader_reads_is_pinned(tmp_path: Path, plugin: None) -> None:
    registry = load_registry(write_registry(tmp_path))
    (tmp_path / "classes.txt").write_text("deer\npedestrian\n")  # the second file changed
    with pytest.raises(ModelIntegrityError, match=r"sha256 mismatch for .*classes\.txt"):
        registry.load("fixed-default")


@pytest.mark.parametrize(
    ("sha256", "line", "message"),
    [
        ("a" * 64, 8, r"loader 'fixed_boxes' reads 2 files \(fixed-default.json, classes.txt\); "
                      "one sha256 pins only the first"),
        ("{fixed-default.json: " + "a" * 64 + "}", 8,
         "no sha256 for classes.txt, which loader 'fixed_boxes' reads"),
    ],
)  # fmt: skip
def test_pins_that_miss_a_file_are_refused_at_the_line(
    tmp_path: Path, plugin: None, sha256: str, line: int, message: str
) -> None:
    path = write_registry(tmp_path, sha256=sha256)
    with pytest.raises(ModelFileError, match=message) as info:
        load_registry(path)
    assert str(info.value).startswith(f"{path}:{line}: models[0].sha256: ")


def test_an_unknown_loader_lists_the_valid_ones_at_its_line(tmp_path: Path, plugin: None) -> None:
    path = write_registry(tmp_path)
    path.write_text(path.read_text().replace("loader: fixed_boxes", "loader: my_onnx"))
    with pytest.raises(ModelFileError) as info:
        load_registry(path)
    text = str(info.value)
    assert text.startswith(f"{path}:5: models[0].loader: unknown detector architecture 'my_onnx'")
    assert "valid names: centernet, fixed_boxes" in text and "anunnaki.detectors" in text
    with pytest.raises(ModelRegistryError, match="unknown detector architecture 'my_onnx'"):
        ModelRegistry([{"id": "m", "domain": "default", "file": path, "loader": "my_onnx"}])


def test_options_need_a_loader(tmp_path: Path) -> None:
    path = tmp_path / "registry.yaml"
    model, _ = write_model(tmp_path)
    path.write_text(
        f"anunnaki: models/1\nmodels:\n  - {{id: m, domain: default, file: {model.name}, "
        "options: {classes: classes.txt}}\n"
    )
    with pytest.raises(ModelFileError, match=r":3: models\[0\].options: options \['classes'\]"):
        load_registry(path)


def test_the_lec_node_runs_a_plugin_model(tmp_path: Path, plugin: None) -> None:
    registry = load_registry(write_registry(tmp_path))
    got: list[Detections] = []
    done = threading.Event()

    def on(sample: Sample) -> None:
        assert isinstance(sample.message, Detections)
        got.append(sample.message)
        done.set()

    png = cv2.imencode(".png", np.zeros((24, 32, 3), np.uint8))[1].tobytes()
    with open_bus("inproc") as bus, LecNode(bus, registry, camera="/cam", active_period=None):
        bus.subscribe("/lec/detector/detections", on, queue=8)
        bus.publish("/cam", Image(encoding="png", width=32, height=24, data=png, seq=3))
        assert done.wait(30)
    (dets,) = got
    assert (dets.frame_seq, dets.model_id, dets.labels) == (3, "fixed-default", ["pedestrian"])
    assert dets.boxes == [[4.0, 4.0, 20.0, 24.0]]  # clipped to the 24-pixel-high frame


def coco(folder: Path, classes: tuple[str, ...]) -> Path:
    """One 32x32 image whose only object is where the plugin's fixed box is."""
    from anunnaki.datasets import Dataset

    label = classes.index("pedestrian")
    data = Dataset.from_arrays(
        [np.zeros((32, 32, 3), np.uint8)],
        [np.array([[4, 4, 20, 30]], np.float32)],
        [np.array([label])],
        classes,
    )
    return data.to_coco(folder / "test.json")


def evaluate(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(["evaluate-detector", *args])
    out, err = capsys.readouterr()
    return code, out, err


def test_evaluate_detector_measures_a_plugin_model_from_its_registry(
    tmp_path: Path, plugin: None, capsys: pytest.CaptureFixture[str]
) -> None:
    registry = write_registry(tmp_path)
    # The dataset lists the classes in the other order: they are matched by name.
    data = coco(tmp_path / "data", ("deer", "pedestrian"))
    code, out, err = evaluate([str(registry), "--data", str(data), "--json"], capsys)
    assert code == 0, err
    report = json.loads(out)
    assert (report["model_id"], report["domain"], report["score_threshold"]) == (
        "fixed-default", "default", 0.5)  # fmt: skip
    assert report["clean"]["f1"] == 1.0 and report["clean"]["tp"] == 1
    code, out, err = evaluate(
        [str(registry), "--model", "fixed-default", "--data", str(data), "-p", "fog"], capsys
    )
    assert code == 0, err
    assert "fixed-default (default)" in out and "category" in out


def test_evaluate_detector_refuses_other_class_names_naming_both(
    tmp_path: Path, plugin: None, capsys: pytest.CaptureFixture[str]
) -> None:
    registry = write_registry(tmp_path)
    data = coco(tmp_path / "data", ("pedestrian", "car"))
    code, _, err = evaluate([str(registry), "--data", str(data)], capsys)
    assert code == 2
    assert "model 'fixed-default'" in err
    assert "['pedestrian', 'deer'] are not the dataset's ['pedestrian', 'car']" in err
    code, _, err = evaluate([str(registry), "--model", "nope", "--data", str(data)], capsys)
    assert code == 2 and "unknown model 'nope'" in err and "fixed-default (default)" in err
    code, _, err = evaluate([str(registry), "--data", str(data), "--update-sidecar"], capsys)
    assert code == 2 and "is loaded by 'fixed_boxes'" in err


def test_a_file_that_is_no_anunnaki_model_says_how_to_name_a_loader(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model, _ = write_model(tmp_path)
    data = coco(tmp_path / "data", ("pedestrian", "deer"))
    code, _, err = evaluate([str(model.with_suffix(".onnx")), "--data", str(data)], capsys)
    assert code == 2 and "loader: NAME" in err


# -- from an installed package: the entry point --------------------------------------------


@pytest.fixture
def installed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """A fake distribution whose ``anunnaki.detectors`` entry point names the plugin."""
    site = tmp_path / "site"
    dist = site / "fake_detector_plugin-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: fake-detector-plugin\n"
                                   "Version: 0.1\n")  # fmt: skip
    (dist / "entry_points.txt").write_text(
        "[anunnaki.detectors]\nfixed_boxes = fixed_boxes_plugin:FixedBoxes\n"
    )
    monkeypatch.syspath_prepend(str(site))
    assert "fixed_boxes" not in ARCHITECTURES.names()
    ARCHITECTURES.load_entry_points(force=True)
    try:
        yield
    finally:
        ARCHITECTURES.unregister("fixed_boxes")


def test_an_installed_plugin_serves_evaluate_and_sim(
    tmp_path: Path, installed: None, capsys: pytest.CaptureFixture[str]
) -> None:
    assert "fixed_boxes" in ARCHITECTURES.names()
    registry = write_registry(tmp_path / "models")
    data = coco(tmp_path / "data", ("pedestrian", "deer"))
    code, out, err = evaluate([str(registry), "--data", str(data), "--json"], capsys)
    assert code == 0, err
    assert json.loads(out)["clean"]["f1"] == 1.0
    pytest.importorskip("pybullet")
    args = ["sim", "rover", "--models", str(registry), "--oracle", "none", "--until", "1",
            "--speed", "0", "--width", "32", "--height", "32", "--quiet"]  # fmt: skip
    code = main(args)
    out = capsys.readouterr().out
    assert code == 0, out
    assert "detector fixed-default (default) on /rover/camera/image" in out
    assert "fixed_boxes_plugin" in sys.modules
