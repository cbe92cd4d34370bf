"""COCO and YOLO import/export: round trips, and malformed files with precise messages."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from anunnaki.datasets import Dataset, DatasetError, load_split, read_image
from anunnaki.errors import AnunnakiError


def toy(n: int = 4, size: tuple[int, int] = (40, 32)) -> Dataset:
    """A small in-memory dataset with known boxes (one image has none)."""
    w, h = size
    rng = np.random.default_rng(0)
    images, boxes, labels = [], [], []
    for i in range(n):
        images.append(rng.integers(0, 255, (h, w, 3), dtype=np.uint8))
        if i == 1:
            boxes.append(np.zeros((0, 4)))
            labels.append(np.zeros(0))
        else:
            boxes.append([[1.5, 2.25, 11.0, 20.5], [20, 3, 39, 30]])
            labels.append([0, i % 2])
    return Dataset.from_arrays(images, boxes, labels, ("pedestrian", "deer"))


def assert_same(a: Dataset, b: Dataset, *, atol: float = 1e-3) -> None:
    assert a.classes == b.classes and len(a) == len(b)
    for (ia, ba, la), (ib, bb, lb) in zip(a, b, strict=True):
        np.testing.assert_array_equal(ia, ib)
        np.testing.assert_allclose(ba, bb, atol=atol)
        np.testing.assert_array_equal(la, lb)


def test_dataset_interface() -> None:
    ds = toy()
    assert len(ds) == 4 and ds.num_boxes == 6
    image, boxes, labels = ds[0]
    assert image.shape == (32, 40, 3) and image.dtype == np.uint8
    assert boxes.dtype == np.float32 and boxes.shape == (2, 4) and labels.dtype == np.int64
    assert ds.class_counts() == {"pedestrian": 5, "deer": 1}
    sub = ds.subset([3, 0])
    assert len(sub) == 2 and np.array_equal(sub[1].image, ds[0].image)
    assert len(ds[1:3]) == 2 and len(list(ds)) == 4
    assert [len(lab) for _, lab, _ in ds.truths()] == [2, 0, 2, 2]
    assert ds.num_ignore == 0 and all(ig.shape == (0, 4) for *_, ig in ds.truths())


def with_ignore() -> Dataset:
    """The toy dataset with ignore boxes on images 0 and 1 (the one without labels)."""
    ds = toy()
    return Dataset.from_arrays(
        [ds.image(i) for i in range(len(ds))],
        [r.boxes for r in ds.records],
        [r.labels for r in ds.records],
        ds.classes,
        ignore=[[[30, 1, 34, 6]], [[2, 2, 6, 5], [10, 10, 12.5, 30]], [], []],
        ignore_labels=[[1], [0, 1], [], []],
    )


def test_ignore_boxes_are_carried_and_checked() -> None:
    ds = with_ignore()
    assert ds.num_ignore == 3 and ds.num_boxes == 6
    boxes, _, ignore = ds.truths()[1]
    assert len(boxes) == 0 and ignore.dtype == np.float32
    np.testing.assert_array_equal(ignore, [[2, 2, 6, 5], [10, 10, 12.5, 30]])
    assert ds.records[1].ignore_labels.tolist() == [0, 1]
    assert ds.subset([1]).num_ignore == 2 and ds.in_memory().num_ignore == 3
    image = ds.image(0)
    with pytest.raises(AnunnakiError, match="together"):
        Dataset.from_arrays([image], [[]], [[]], ds.classes, ignore=[[[0, 0, 1, 1]]])
    with pytest.raises(AnunnakiError, match="1 ignore boxes but 2 ignore labels"):
        Dataset.from_arrays(
            [image], [[]], [[]], ds.classes, ignore=[[[0, 0, 1, 1]]], ignore_labels=[[0, 1]]
        )
    with pytest.raises(AnunnakiError, match=r"label outside 0\.\.1"):
        Dataset.from_arrays(
            [image], [[]], [[]], ds.classes, ignore=[[[0, 0, 1, 1]]], ignore_labels=[[5]]
        )


def test_coco_round_trip_keeps_ignore_boxes_as_crowd(tmp_path: Path) -> None:
    ds = with_ignore()
    path = ds.to_coco(tmp_path / "test.json")
    data = json.loads(path.read_text())
    crowd = [a for a in data["annotations"] if a["iscrowd"] == 1]
    assert len(crowd) == 3 and len(data["annotations"]) == 9
    assert crowd[0] == {
        "id": 3, "image_id": 1, "category_id": 2, "bbox": [30.0, 1.0, 4.0, 5.0],
        "area": 20.0, "iscrowd": 1,
    }  # fmt: skip
    back = Dataset.from_coco(path)
    assert_same(ds, back)
    for a, b in zip(ds.records, back.records, strict=True):
        np.testing.assert_allclose(a.ignore, b.ignore, atol=1e-3)
        np.testing.assert_array_equal(a.ignore_labels, b.ignore_labels)
    again = Dataset.from_coco(back.to_coco(tmp_path / "copy" / "test.json"))
    assert again.num_ignore == 3 and again.num_boxes == 6


def test_coco_round_trip(tmp_path: Path) -> None:
    ds = toy()
    path = ds.to_coco(tmp_path / "train.json", info={"platform": "toy"})
    data = json.loads(path.read_text())
    assert data["categories"] == [{"id": 1, "name": "pedestrian"}, {"id": 2, "name": "deer"}]
    assert data["annotations"][0]["bbox"] == [1.5, 2.25, 9.5, 18.25]  # [x, y, w, h]
    back = Dataset.from_coco(path)
    assert_same(ds, back)
    again = back.to_coco(tmp_path / "copy" / "train.json")
    assert_same(ds, Dataset.from_coco(again))
    assert load_split(tmp_path, "train").classes == ds.classes


def test_yolo_round_trip(tmp_path: Path) -> None:
    ds = toy()
    ds.to_yolo(tmp_path / "y")
    assert (tmp_path / "y" / "classes.txt").read_text() == "pedestrian\ndeer\n"
    back = Dataset.from_yolo(tmp_path / "y" / "images")
    assert_same(ds, back, atol=1e-3)
    assert (tmp_path / "y" / "labels" / "000001.txt").read_text() == ""


def test_yolo_import_of_a_hand_written_folder(tmp_path: Path) -> None:
    """Known label lines give known pixel boxes: cx, cy, w, h scale by the image's size."""
    images, labels = tmp_path / "images", tmp_path / "labels"
    images.mkdir()
    labels.mkdir()
    # 80 x 40 images (width != height, so swapped axes show); names sort a, b, c.
    for name in ("a.png", "b.jpg", "c.png"):
        cv2.imwrite(str(images / name), np.full((40, 80, 3), 100, np.uint8))
    (tmp_path / "obj.names").write_text("car\npedestrian\nbike\n")
    (labels / "a.txt").write_text(
        "# class cx cy w h\n"
        "1 0.5 0.5 0.25 0.5\n"  # 20 x 20 px centred on (40, 20)
        "\n"
        "0 0.125 0.25 0.25 0.5\n"  # the top-left corner: (0, 0) - (20, 20)
        "2 0.9375 0.875 0.125 0.25\n"  # the bottom-right corner: (70, 30) - (80, 40)
    )
    (labels / "b.txt").write_text("2 0.1 0.3 0.05 0.3\n")  # (6, 6) - (10, 18)
    # c.png has no label file: an image without objects.
    ds = Dataset.from_yolo(images)
    assert ds.classes == ("car", "pedestrian", "bike")
    assert [r.file_name for r in ds.records] == ["a.png", "b.jpg", "c.png"]
    assert [(r.width, r.height) for r in ds.records] == [(80, 40)] * 3
    np.testing.assert_array_equal(ds[0].boxes, [[30, 10, 50, 30], [0, 0, 20, 20], [70, 30, 80, 40]])
    assert ds[0].labels.tolist() == [1, 0, 2] and ds[0].boxes.dtype == np.float32
    np.testing.assert_allclose(ds[1].boxes, [[6, 6, 10, 18]], atol=1e-4)
    assert ds[1].labels.tolist() == [2]
    assert ds[2].boxes.shape == (0, 4) and ds[2].labels.tolist() == []
    assert ds.class_counts() == {"car": 1, "pedestrian": 1, "bike": 2}
    assert ds[0].image.shape == (40, 80, 3) and ds.num_ignore == 0
    # A malformed line in a hand-written file: the error names the file and the line.
    (labels / "b.txt").write_text("2 0.1 0.3 0.05 0.3\n\n0 0.5 0.5 0.2\n")
    with pytest.raises(DatasetError) as info:
        Dataset.from_yolo(images)
    assert info.value.path == str(labels / "b.txt") and info.value.line == 3
    assert str(info.value).startswith(f"{labels / 'b.txt'}:3: expected 5 fields, got 4")


def test_yolo_split_layout_and_data_yaml(tmp_path: Path) -> None:
    ds = toy()
    root = tmp_path / "yolo"
    ds.to_yolo(tmp_path / "tmp")
    for sub in ("images", "labels"):
        (root / sub).mkdir(parents=True)
        (tmp_path / "tmp" / sub).rename(root / sub / "val")
    (root / "data.yaml").write_text("names: {0: pedestrian, 1: deer}\n")
    assert_same(ds, load_split(root, "val"))


def test_real_images_read_back(tmp_path: Path) -> None:
    ds = toy(1)
    ds.to_coco(tmp_path / "d.json")
    np.testing.assert_array_equal(read_image(tmp_path / "images" / "000000.png"), ds[0].image)


# -- malformed COCO ----------------------------------------------------------------------------


def write_coco(tmp_path: Path, mutate) -> Path:  # type: ignore[no-untyped-def]
    path = toy(2).to_coco(tmp_path / "bad.json")
    data = json.loads(path.read_text())
    mutate(data)
    path.write_text(json.dumps(data, indent=1))
    return path


@pytest.mark.parametrize(
    ("mutate", "pattern"),
    [
        (
            lambda d: d["annotations"][1].update(bbox=[1, 2, -3, 4]),
            r"bad\.json: annotations\[id=2\]\.bbox: width and height must be > 0.*\[x, y, width",
        ),
        (
            lambda d: d["annotations"][0].update(bbox=[1, 2, 3]),
            r"annotations\[id=1\]\.bbox: expected four finite numbers",
        ),
        (
            lambda d: d["annotations"][0].update(category_id=9),
            r"annotations\[id=1\]\.category_id: unknown category 9; known ids: \[1, 2\]",
        ),
        (
            lambda d: d["annotations"][0].update(image_id=77),
            r"annotations\[id=1\]\.image_id: refers to image 77.*add the image",
        ),
        (
            lambda d: d["annotations"].append(dict(d["annotations"][0])),
            r"annotations\[id=1\]: duplicate annotation id",
        ),
        (
            lambda d: d["images"][0].update(width="wide"),
            r"images\[id=1\]\.width: width must be a positive integer",
        ),
        (
            lambda d: d["images"][0].update(file_name="missing.png"),
            r"images\[id=1\]\.file_name: image file .*missing\.png not found.*images_dir",
        ),
        (lambda d: d.pop("categories"), r"categories: missing or not a list"),
        (
            lambda d: d["annotations"][0].update(bbox=[500, 500, 3, 3]),
            r"annotations\[id=1\]\.bbox: box .* lies outside the 40x32 image",
        ),
    ],
)
def test_malformed_coco(tmp_path: Path, mutate, pattern: str) -> None:  # type: ignore[no-untyped-def]
    path = write_coco(tmp_path, mutate)
    with pytest.raises(DatasetError, match=pattern) as info:
        Dataset.from_coco(path)
    assert info.value.path == str(path) or "missing.png" in str(info.value)


def test_coco_not_json(tmp_path: Path) -> None:
    path = tmp_path / "x.json"
    path.write_text('{"images": [\n  1,\n  oops]}')
    with pytest.raises(DatasetError, match=r"x\.json:3: not valid JSON"):
        Dataset.from_coco(path)


def test_coco_crowd_becomes_ignore_and_boxes_are_clipped(tmp_path: Path) -> None:
    def mutate(d: dict) -> None:
        d["annotations"][0]["iscrowd"] = 1
        d["annotations"][1]["bbox"] = [30, -5, 20, 10]

    ds = Dataset.from_coco(write_coco(tmp_path, mutate))
    np.testing.assert_allclose(ds[0].boxes, [[30, 0, 40, 5]])
    np.testing.assert_allclose(ds.records[0].ignore, [[1.5, 2.25, 11.0, 20.5]])
    assert ds.records[0].ignore_labels.tolist() == [0]


# -- malformed YOLO ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("line", "pattern"),
    [
        ("0 0.5 0.5 0.2", r"000000\.txt:2: expected 5 fields, got 4"),
        ("0 0.5 0.5 0.2 x", r"000000\.txt:2: not a number"),
        ("2 0.5 0.5 0.2 0.2", r"000000\.txt:2: class: class 2 is not an index in 0\.\.1"),
        ("1 0.5 40 0.2 0.2", r"000000\.txt:2: cy: cy = 40.0 is outside 0\.\.1.*divided by"),
        ("0 0.5 0.5 0 0.2", r"000000\.txt:2: box size 0.0 x 0.2 is not positive"),
    ],
)
def test_malformed_yolo(tmp_path: Path, line: str, pattern: str) -> None:
    toy(1).to_yolo(tmp_path)
    label = tmp_path / "labels" / "000000.txt"
    label.write_text(label.read_text().splitlines()[0] + "\n" + line + "\n")
    with pytest.raises(DatasetError, match=pattern) as info:
        Dataset.from_yolo(tmp_path / "images")
    assert info.value.line == 2 and info.value.path == str(label)


def test_yolo_missing_classes(tmp_path: Path) -> None:
    toy(1).to_yolo(tmp_path)
    (tmp_path / "classes.txt").unlink()
    with pytest.raises(DatasetError, match=r"no classes list found.*pass classes="):
        Dataset.from_yolo(tmp_path / "images")
    ds = Dataset.from_yolo(tmp_path / "images", classes=["a", "b"])
    assert ds.classes == ("a", "b")


def test_load_split_explains_what_it_looked_for(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match=r"no 'test' split here.*expected test\.json"):
        load_split(tmp_path, "test")


def test_an_image_name_that_leaves_the_image_folder_is_not_written(tmp_path: Path) -> None:
    """A COCO file_name of '../../evil.png' is read where it points, but an export writes
    every image inside its own image folder (issue 34 item 1)."""
    src = toy(2).to_coco(tmp_path / "src" / "a" / "d.json")
    data = json.loads(src.read_text())
    first = tmp_path / "src" / "a" / "images" / data["images"][0]["file_name"]
    first.rename(tmp_path / "src" / "evil.png")
    data["images"][0]["file_name"] = "../../evil.png"
    src.write_text(json.dumps(data))
    ds = Dataset.from_coco(src)
    assert ds.records[0].file_name == "../../evil.png" and ds.image(0).shape == (32, 40, 3)
    with pytest.raises(AnunnakiError, match=r"image '\.\./\.\./evil\.png' .* would be written "
                       "outside its folder"):  # fmt: skip
        ds.to_coco(tmp_path / "out" / "d.json")
    assert not (tmp_path / "evil.png").exists()
    assert [p.name for p in (tmp_path / "out").rglob("*")] == ["images"]
