"""YOLO text labels: import with ``file:line`` errors, and export.

The layout (Darknet / Ultralytics)::

    DIR/images/NAME.png        # or .jpg, .jpeg, .bmp
    DIR/labels/NAME.txt        # one object per line: class cx cy w h (normalised to 0..1)
    DIR/classes.txt            # one class name per line (or data.yaml with names:)

An image without a label file has no objects. Blank lines and lines starting with ``#`` are
skipped. Coordinates may overshoot ``[0, 1]`` by 1 % (rounding in exporters) and are clipped.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from anunnaki.datasets._record import DatasetError, Labelled, Record, read_image, write_image

__all__ = ["IMAGE_SUFFIXES", "write_yolo", "yolo_records"]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp")
_LINE_HINT = "each line is: class_index cx cy width height, the last four normalised to 0..1"
_SLACK = 0.01


def _read_classes(path: Path) -> list[str]:
    if not path.is_file():
        raise DatasetError("classes file not found", path=path, hint="one class name per line")
    if path.suffix in (".yaml", ".yml"):
        from anunnaki._safeyaml import load_yaml

        data, _ = load_yaml(path)
        names: Any = data.get("names") if isinstance(data, dict) else None
        if isinstance(names, dict) and all(isinstance(k, int) for k in names):
            names = [names[k] for k in sorted(names)]
        if not isinstance(names, list) or not all(isinstance(n, str) and n for n in names):
            raise DatasetError(
                "expected 'names:' as a list of class names (or a dict index -> name)",
                path=path,
                element="names",
                hint="e.g. names: [pedestrian, deer]",
            )
        return list(names)
    lines = path.read_text(encoding="utf-8").splitlines()
    names = [line.strip() for line in lines if line.strip()]
    if not names:
        raise DatasetError("no class names", path=path, hint="one class name per line")
    return list(names)


def _find_classes(images_dir: Path, labels_dir: Path) -> Path:
    for folder in dict.fromkeys((labels_dir, images_dir.parent, labels_dir.parent, images_dir)):
        for name in ("classes.txt", "obj.names", "data.yaml"):
            if (folder / name).is_file():
                return folder / name
    raise DatasetError(
        "no classes list found (classes.txt, obj.names or data.yaml)",
        path=images_dir.parent,
        hint="pass classes= (CLI: --classes) or put classes.txt next to the images folder",
    )


def _parse_labels(
    path: Path, width: int, height: int, n_classes: int
) -> tuple[list[list[float]], list[int]]:
    boxes: list[list[float]] = []
    labels: list[int] = []
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise DatasetError("not UTF-8 text", path=path, hint=_LINE_HINT) from None
    for n, line in enumerate(text.splitlines(), start=1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        if len(fields) != 5:
            raise DatasetError(
                f"expected 5 fields, got {len(fields)}: {line.strip()!r}",
                path=path,
                line=n,
                hint=_LINE_HINT + " (segmentation polygons are not supported)",
            )
        try:
            cls_f = float(fields[0])
            cx, cy, w, h = (float(v) for v in fields[1:])
        except ValueError:
            raise DatasetError(
                f"not a number in {line.strip()!r}", path=path, line=n, hint=_LINE_HINT
            ) from None
        if not cls_f.is_integer() or not 0 <= cls_f < n_classes:
            raise DatasetError(
                f"class {fields[0]} is not an index in 0..{n_classes - 1}",
                path=path,
                line=n,
                element="class",
                hint="class indices count from 0 in the order of the classes list",
            )
        for name, v in (("cx", cx), ("cy", cy), ("w", w), ("h", h)):
            if not math.isfinite(v) or not -_SLACK <= v <= 1 + _SLACK:
                raise DatasetError(
                    f"{name} = {v} is outside 0..1",
                    path=path,
                    line=n,
                    element=name,
                    hint=_LINE_HINT + " (pixel coordinates must be divided by the image size)",
                )
        if w <= 0 or h <= 0:
            raise DatasetError(
                f"box size {w} x {h} is not positive", path=path, line=n, hint=_LINE_HINT
            )
        x1, x2 = max(0.0, (cx - w / 2) * width), min(float(width), (cx + w / 2) * width)
        y1, y2 = max(0.0, (cy - h / 2) * height), min(float(height), (cy + h / 2) * height)
        if x2 <= x1 or y2 <= y1:
            raise DatasetError("box lies outside the image", path=path, line=n, hint=_LINE_HINT)
        boxes.append([x1, y1, x2, y2])
        labels.append(int(cls_f))
    return boxes, labels


def yolo_records(
    images_dir: str | Path,
    *,
    labels_dir: str | Path | None = None,
    classes: Sequence[str] | str | Path | None = None,
    keep_pixels: bool = False,
) -> tuple[list[str], list[Record]]:
    """The class names and image records of a YOLO folder.

    :func:`~anunnaki.datasets.read_yolo` makes them a dataset; its docstring says where the
    labels and the classes are looked for.

    Raises:
        DatasetError: A label line is malformed (``file:line``), a class index is out of
            range, the classes list is missing, or an image is unreadable.

    """
    idir = Path(images_dir)
    if not idir.is_dir():
        raise DatasetError("image folder not found", path=idir, hint="check the path")
    if labels_dir is not None:
        ldir = Path(labels_dir)
    elif idir.name == "images" and (idir.parent / "labels").is_dir():
        ldir = idir.parent / "labels"
    else:
        ldir = idir
    if classes is None:
        names = _read_classes(_find_classes(idir, ldir))
    elif isinstance(classes, str | Path):
        names = _read_classes(Path(classes))
    else:
        names = list(classes)
    files = sorted(f for f in idir.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES)
    records = []
    for k, file in enumerate(files):
        image = read_image(file)
        h, w = image.shape[:2]
        label_file = ldir / (file.stem + ".txt")
        boxes, labels = (
            _parse_labels(label_file, w, h, len(names)) if label_file.is_file() else ([], [])
        )
        records.append(
            Record(
                file_name=file.name,
                width=w,
                height=h,
                boxes=np.asarray(boxes, np.float32).reshape(-1, 4),
                labels=np.asarray(labels, np.int64),
                image_id=k + 1,
                path=file,
                array=image if keep_pixels else None,
            )
        )
    return names, records


def write_yolo(ds: Labelled, out_dir: str | Path) -> Path:
    """Write *ds* as ``out_dir/images``, ``out_dir/labels`` and ``out_dir/classes.txt``.

    Images are written as PNG under their ``file_name`` stem; coordinates get 6 decimals.
    YOLO has no ignore regions: the records' ignore boxes are not written (use COCO, where
    they are ``iscrowd: 1`` annotations, to keep them).

    Returns:
        *out_dir*.

    """
    out = Path(out_dir)
    (out / "images").mkdir(parents=True, exist_ok=True)
    (out / "labels").mkdir(parents=True, exist_ok=True)
    (out / "classes.txt").write_text("\n".join(ds.classes) + "\n", encoding="utf-8")
    for i, r in enumerate(ds.records):
        stem = Path(r.file_name).stem
        write_image(out / "images" / f"{stem}.png", ds.image(i))
        lines = []
        for (x1, y1, x2, y2), label in zip(r.boxes.tolist(), r.labels.tolist(), strict=True):
            cx, cy = (x1 + x2) / 2 / r.width, (y1 + y2) / 2 / r.height
            w, h = (x2 - x1) / r.width, (y2 - y1) / r.height
            lines.append(f"{label} {cx:.6f} {cy:.6f} {w:.6f} {h:.6f}")
        (out / "labels" / f"{stem}.txt").write_text(
            "".join(line + "\n" for line in lines), encoding="utf-8"
        )
    return out
