"""COCO detection JSON: import with element-precise errors, and export.

The subset of COCO we read and write: ``categories`` (``id``, ``name``), ``images``
(``id``, ``file_name``, ``width``, ``height``, plus any extra fields, kept as metadata) and
``annotations`` (``id``, ``image_id``, ``category_id``, ``bbox`` = ``[x, y, width, height]``
in pixels, optional ``iscrowd``). Labels are the categories' positions in the ``categories``
list. Crowd annotations (``iscrowd: 1``) become the image's *ignore boxes*
(``Record.ignore``): regions where a detection is neither right nor wrong, as in COCO's own
evaluation; the simulator's unlabelled objects (too small, occluded, cut by the frame) are
exported the same way. Boxes that stick out of the image are clipped to it.
"""

from __future__ import annotations

import json
import math
import shutil
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from anunnaki._names import inside
from anunnaki.datasets._record import DatasetError, Labelled, Record, write_image

__all__ = ["coco_dict", "coco_records", "write_coco"]

_MAX_JSON_BYTES = 512 * 1024 * 1024
_BBOX_HINT = "bbox is [x, y, width, height] in pixels with width and height above 0"


def _is_int(v: object) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_num(v: object) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _load_json(path: Path) -> Any:
    if not path.is_file():
        raise DatasetError("annotation file not found", path=path, hint="check the path")
    if path.stat().st_size > _MAX_JSON_BYTES:
        raise DatasetError("annotation file is larger than 512 MiB", path=path)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise DatasetError(
            f"not valid JSON: {exc.msg} (column {exc.colno})",
            path=path,
            line=exc.lineno,
            hint="a COCO file is one JSON object with images, annotations and categories",
        ) from None
    except UnicodeDecodeError:
        raise DatasetError("not UTF-8 text", path=path, hint="save it as UTF-8 JSON") from None


def coco_records(
    path: str | Path, *, images_dir: str | Path | None = None
) -> tuple[list[str], list[Record]]:
    """The classes and image records of a COCO detection file.

    :func:`~anunnaki.datasets.read_coco` makes them a dataset; its docstring says what is
    checked.

    Raises:
        DatasetError: Naming the file and the element (``annotations[id=17].bbox``).

    """
    p = Path(path)
    data = _load_json(p)

    def fail(element: str, message: str, hint: str) -> DatasetError:
        return DatasetError(message, path=p, element=element, hint=hint)

    if not isinstance(data, dict):
        raise fail("<root>", "expected a JSON object", "see docs/detector.md for the format")
    for key in ("images", "annotations", "categories"):
        if not isinstance(data.get(key), list):
            raise fail(key, f"missing or not a list: {key!r}", "a COCO file has all three lists")
    if images_dir is None:
        root = p.parent / "images" if (p.parent / "images").is_dir() else p.parent
    else:
        root = Path(images_dir)
    cat_index, classes = _categories(data["categories"], fail)
    images = _images(data["images"], fail)
    boxes = _boxes(data["annotations"], images, cat_index, fail)
    records = [
        _record(image_id, img, root, boxes[image_id], fail) for image_id, img in images.items()
    ]
    return classes, records


_Fail = Callable[[str, str, str], DatasetError]
"""Makes the error for an element: ``fail(element, message, hint)``."""


def _categories(categories: list[Any], fail: _Fail) -> tuple[dict[int, int], list[str]]:
    """Category id → class index, and the class names in order."""
    cat_index: dict[int, int] = {}
    classes: list[str] = []
    for i, cat in enumerate(categories):
        where = f"categories[{i}]"
        if not isinstance(cat, dict) or not _is_int(cat.get("id")):
            raise fail(where, "a category needs an integer 'id'", 'e.g. {"id": 1, "name": "deer"}')
        where = f"categories[id={cat['id']}]"
        if not isinstance(cat.get("name"), str) or not cat["name"]:
            raise fail(where, "a category needs a non-empty 'name'", 'e.g. "name": "deer"')
        if cat["id"] in cat_index:
            raise fail(where, "duplicate category id", "give every category its own id")
        if cat["name"] in classes:
            raise fail(where, f"duplicate category name {cat['name']!r}", "merge the categories")
        cat_index[cat["id"]] = len(classes)
        classes.append(cat["name"])
    if not classes:
        raise fail("categories", "no categories", "list the classes under 'categories'")
    return cat_index, classes


def _images(entries: list[Any], fail: _Fail) -> dict[int, dict[str, Any]]:
    """Image id → its checked entry."""
    images: dict[int, dict[str, Any]] = {}
    for i, img in enumerate(entries):
        if not isinstance(img, dict) or not _is_int(img.get("id")):
            raise fail(f"images[{i}]", "an image needs an integer 'id'", "number the images")
        where = f"images[id={img['id']}]"
        if img["id"] in images:
            raise fail(where, "duplicate image id", "give every image its own id")
        if not isinstance(img.get("file_name"), str) or not img["file_name"]:
            raise fail(where, "missing 'file_name'", "file_name is relative to the image folder")
        for key in ("width", "height"):
            if not _is_int(img.get(key)) or img[key] <= 0:
                raise fail(
                    f"{where}.{key}",
                    f"{key} must be a positive integer, got {img.get(key)!r}",
                    "width and height are the image size in pixels",
                )
        images[img["id"]] = img
    return images


_Boxes = tuple[list[list[float]], list[int], list[list[float]], list[int]]
"""An image's boxes, labels, ignore boxes and ignore labels."""


def _boxes(
    annotations: list[Any],
    images: dict[int, dict[str, Any]],
    cat_index: dict[int, int],
    fail: _Fail,
) -> dict[int, _Boxes]:
    """Image id → its labelled and (``iscrowd``) ignore boxes, clipped to the image."""
    out: dict[int, _Boxes] = {k: ([], [], [], []) for k in images}
    seen: set[int] = set()
    for i, ann in enumerate(annotations):
        if not isinstance(ann, dict) or not _is_int(ann.get("id")):
            raise fail(f"annotations[{i}]", "an annotation needs an integer 'id'", "number them")
        where = f"annotations[id={ann['id']}]"
        if ann["id"] in seen:
            raise fail(where, "duplicate annotation id", "give every annotation its own id")
        seen.add(ann["id"])
        _check_refs(ann, where, images, cat_index, fail)
        box = _clipped_box(ann, where, images[ann["image_id"]], fail)
        boxes, labels, ignore, ignore_labels = out[ann["image_id"]]
        crowd = bool(ann.get("iscrowd", 0))
        (ignore if crowd else boxes).append(box)
        (ignore_labels if crowd else labels).append(cat_index[ann["category_id"]])
    return out


def _check_refs(
    ann: dict[str, Any],
    where: str,
    images: dict[int, dict[str, Any]],
    cat_index: dict[int, int],
    fail: _Fail,
) -> None:
    """The annotation's image and category exist, and its ``iscrowd`` is 0 or 1."""
    if ann.get("image_id") not in images or not _is_int(ann.get("image_id")):
        raise fail(
            f"{where}.image_id",
            f"refers to image {ann.get('image_id')!r}, which is not in 'images'",
            "add the image or remove the annotation",
        )
    if ann.get("category_id") not in cat_index or not _is_int(ann.get("category_id")):
        raise fail(
            f"{where}.category_id",
            f"unknown category {ann.get('category_id')!r}; known ids: {sorted(cat_index)}",
            "add the category or fix the id",
        )
    if ann.get("iscrowd", 0) not in (0, 1, False, True):
        raise fail(f"{where}.iscrowd", "iscrowd must be 0 or 1", "use 0 for single objects")


def _clipped_box(ann: dict[str, Any], where: str, img: dict[str, Any], fail: _Fail) -> list[float]:
    """The annotation's bbox as ``[x1, y1, x2, y2]`` clipped to the image."""
    bbox = ann.get("bbox")
    if not isinstance(bbox, list) or len(bbox) != 4 or not all(_is_num(v) for v in bbox):
        raise fail(f"{where}.bbox", f"expected four finite numbers, got {bbox!r}", _BBOX_HINT)
    x, y, w, h = (float(v) for v in bbox)
    if w <= 0 or h <= 0:
        raise fail(f"{where}.bbox", f"width and height must be > 0, got {w} x {h}", _BBOX_HINT)
    x1, y1 = max(0.0, x), max(0.0, y)
    x2, y2 = min(float(img["width"]), x + w), min(float(img["height"]), y + h)
    if x2 <= x1 or y2 <= y1:
        raise fail(
            f"{where}.bbox",
            f"box {bbox} lies outside the {img['width']}x{img['height']} image",
            "bbox is [x, y, width, height] in pixels from the top-left corner",
        )
    return [x1, y1, x2, y2]


def _record(image_id: int, img: dict[str, Any], root: Path, boxes: _Boxes, fail: _Fail) -> Record:
    """The dataset's record of one image, whose file must exist under ``root``."""
    file = root / img["file_name"]
    if not file.is_file():
        raise fail(
            f"images[id={image_id}].file_name",
            f"image file {file} not found",
            "pass images_dir= (CLI: --images) pointing at the folder of the images",
        )
    meta = {k: v for k, v in img.items() if k not in ("id", "file_name", "width", "height")}
    kept, labels, ignore, ignore_labels = boxes
    return Record(
        file_name=img["file_name"],
        width=img["width"],
        height=img["height"],
        boxes=np.asarray(kept, np.float32).reshape(-1, 4),
        labels=np.asarray(labels, np.int64),
        image_id=image_id,
        path=file,
        meta=meta,
        ignore=np.asarray(ignore, np.float32).reshape(-1, 4),
        ignore_labels=np.asarray(ignore_labels, np.int64),
    )


def coco_dict(ds: Labelled, *, info: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The COCO JSON object of *ds* (category ids are label + 1, annotation ids from 1).

    Each image's labelled boxes come first (``iscrowd: 0``), then its ignore boxes
    (``iscrowd: 1``).
    """
    return _coco_json(ds.classes, ds.records, info)


def _coco_json(
    classes: Sequence[str], records: Sequence[Record], info: Mapping[str, Any] | None
) -> dict[str, Any]:
    images, annotations = [], []
    ann_id = 1
    for k, r in enumerate(records):
        image_id = r.image_id if r.image_id else k + 1
        images.append(
            {
                **dict(r.meta),
                "id": image_id,
                "file_name": r.file_name,
                "width": r.width,
                "height": r.height,
            }
        )
        pairs = [
            (box, label, crowd)
            for bxs, lbs, crowd in ((r.boxes, r.labels, 0), (r.ignore, r.ignore_labels, 1))
            for box, label in zip(bxs.tolist(), lbs.tolist(), strict=True)
        ]
        for box, label, crowd in pairs:
            x1, y1, x2, y2 = box
            w, h = x2 - x1, y2 - y1
            annotations.append(
                {
                    "id": ann_id,
                    "image_id": image_id,
                    "category_id": int(label) + 1,
                    "bbox": [round(x1, 3), round(y1, 3), round(w, 3), round(h, 3)],
                    "area": round(w * h, 3),
                    "iscrowd": crowd,
                }
            )
            ann_id += 1
    categories = [{"id": i + 1, "name": n} for i, n in enumerate(classes)]
    out: dict[str, Any] = {"info": dict(info or {}), "categories": categories}
    out["images"] = images
    out["annotations"] = annotations
    return out


def write_coco(
    ds: Labelled,
    path: str | Path,
    *,
    images_dir: str | Path | None = None,
    info: Mapping[str, Any] | None = None,
) -> Path:
    """Write *ds* as COCO JSON at *path*, with its images in *images_dir*.

    Args:
        ds: The dataset.
        path: The JSON file to write.
        images_dir: Where the images go (default ``images/`` next to *path*); an image
            already there is not rewritten, an in-memory one is saved as PNG, a file
            elsewhere is copied.
        info: The COCO ``info`` block (free-form).

    Returns:
        *path*.

    Raises:
        NameRuleError: A record's ``file_name`` would put its image outside *images_dir*
            (``..``, an absolute path).

    """
    p = Path(path)
    root = Path(images_dir) if images_dir is not None else p.parent / "images"
    root.mkdir(parents=True, exist_ok=True)
    records = list(ds.records)
    ids = [r.image_id for r in records]
    if len(set(ids)) != len(ids) or 0 in ids:
        records = [replace(r, image_id=k + 1) for k, r in enumerate(records)]
    for i, r in enumerate(records):
        # a file_name is relative to the image folder; '..' or an absolute one would write
        # elsewhere
        target = inside(root, root / r.file_name, what=f"image {r.file_name!r}")
        if r.path is not None and target.exists() and target.resolve() == r.path.resolve():
            continue
        target.parent.mkdir(parents=True, exist_ok=True)
        if r.array is None and r.path is not None:
            shutil.copyfile(r.path, target)
        else:
            write_image(target, ds.image(i))
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(_coco_json(ds.classes, records, info)) + "\n", encoding="utf-8")
    return p
