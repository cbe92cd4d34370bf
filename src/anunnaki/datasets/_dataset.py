"""The labelled-image dataset every part of Anunnaki trains and assesses on.

Why one small class: a dataset generated from the simulator, a COCO export of a real
robot's images and a YOLO folder all become the same thing — a list of images with boxes
and class labels — so training, evaluation, Enlil and Enki never care where data came from.
Images are read lazily from disk (``cv2``), or held in memory for datasets made in code.
The formats (``_coco``, ``_yolo``) read records and write any :class:`Labelled`; this module
makes them a :class:`Dataset`.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any, overload

import numpy as np
import numpy.typing as npt

from anunnaki.datasets._coco import coco_records, write_coco
from anunnaki.datasets._record import DatasetError, Record, Sample, read_image
from anunnaki.datasets._yolo import write_yolo, yolo_records
from anunnaki.errors import AnunnakiError

__all__ = ["Dataset", "read_coco", "read_yolo"]


class Dataset:
    """Images with boxes and class labels; indexing gives a :class:`Sample`.

    Build one with :meth:`from_coco`, :meth:`from_yolo`, :meth:`from_arrays`, or
    :func:`anunnaki.datasets.load_split` for a generated folder. ``len(ds)``, ``ds[i]``
    (``image, boxes, labels``), iteration, :attr:`classes`, :meth:`subset` and
    :meth:`truths` (labels without reading images) are the whole interface.

    Args:
        classes: Class names; labels index into them.
        records: The images (see :class:`Record`).
        name: A label for messages (usually the annotation file).
        cache: Keep decoded images in memory after the first read (training reads each
            image many times).

    """

    def __init__(
        self,
        classes: Sequence[str],
        records: Sequence[Record],
        *,
        name: str = "",
        cache: bool = False,
    ) -> None:
        self.classes: tuple[str, ...] = tuple(classes)
        if not self.classes:
            raise AnunnakiError(f"{name or 'dataset'}: a dataset needs at least one class")
        if len(set(self.classes)) != len(self.classes):
            raise AnunnakiError(f"{name or 'dataset'}: duplicate class names in {self.classes}")
        self.records: tuple[Record, ...] = tuple(records)
        for r in self.records:
            for labels in (r.labels, r.ignore_labels):
                if len(labels) and (labels.min() < 0 or labels.max() >= len(self.classes)):
                    raise AnunnakiError(
                        f"{name or 'dataset'}: image {r.file_name} has a label outside "
                        f"0..{len(self.classes) - 1}"
                    )
            if len(r.ignore) != len(r.ignore_labels):
                raise AnunnakiError(
                    f"{name or 'dataset'}: image {r.file_name} has {len(r.ignore)} ignore "
                    f"boxes but {len(r.ignore_labels)} ignore labels"
                )
        self.name = name
        self.cache = cache
        self._cache: dict[int, npt.NDArray[np.uint8]] = {}

    def __repr__(self) -> str:
        return (
            f"Dataset({self.name or 'in-memory'}: {len(self)} images, "
            f"{self.num_boxes} boxes, classes={self.classes})"
        )

    def __len__(self) -> int:
        return len(self.records)

    @overload
    def __getitem__(self, index: int) -> Sample: ...

    @overload
    def __getitem__(self, index: slice) -> Dataset: ...

    def __getitem__(self, index: int | slice) -> Sample | Dataset:
        """``ds[i]`` → :class:`Sample`; ``ds[a:b]`` → a :class:`Dataset` (like :meth:`subset`)."""
        if isinstance(index, slice):
            return self.subset(range(len(self))[index])
        record = self.records[index]
        return Sample(self.image(index), record.boxes, record.labels)

    def __iter__(self) -> Iterator[Sample]:
        for i in range(len(self)):
            yield self[i]

    @property
    def num_boxes(self) -> int:
        """Number of ground-truth (labelled) boxes over all images."""
        return sum(len(r.labels) for r in self.records)

    @property
    def num_ignore(self) -> int:
        """Number of ignore boxes over all images."""
        return sum(len(r.ignore) for r in self.records)

    def image(self, index: int) -> npt.NDArray[np.uint8]:
        """The ``(H, W, 3)`` ``uint8`` RGB pixels of image *index*.

        Raises:
            DatasetError: The file is unreadable or its size differs from the annotation's.

        """
        i = range(len(self))[index]
        if i in self._cache:
            return self._cache[i]
        record = self.records[i]
        if record.array is not None:
            return record.array
        if record.path is None:  # pragma: no cover - constructors always set one
            raise AnunnakiError(f"image {record.file_name} has neither pixels nor a path")
        image = read_image(record.path)
        if image.shape[:2] != (record.height, record.width):
            raise DatasetError(
                f"image is {image.shape[1]}x{image.shape[0]} but the annotations say "
                f"{record.width}x{record.height}",
                path=record.path,
                element=f"images[id={record.image_id}]",
                hint="fix width/height in the annotation file or use the original image",
            )
        if self.cache:
            self._cache[i] = image
        return image

    def truths(
        self,
    ) -> list[tuple[npt.NDArray[np.float32], npt.NDArray[np.int64], npt.NDArray[np.float32]]]:
        """``(boxes, labels, ignore)`` of every image, without reading pixels (for the metrics).

        ``ignore`` is the image's ``[K, 4]`` ignore boxes (see :class:`Record`); the metrics
        (``anunnaki.lec.f1_at_iou``) take these triples as they are.
        """
        return [(r.boxes, r.labels, r.ignore) for r in self.records]

    def subset(self, indices: Sequence[int] | npt.NDArray[np.integer] | range) -> Dataset:
        """A dataset of the images at *indices* (in that order), sharing the cache policy."""
        picked = [self.records[int(i)] for i in indices]
        return Dataset(self.classes, picked, name=self.name, cache=self.cache)

    def class_counts(self) -> dict[str, int]:
        """Number of boxes per class name."""
        counts = np.zeros(len(self.classes), np.int64)
        for r in self.records:
            counts += np.bincount(r.labels, minlength=len(self.classes))
        return {c: int(n) for c, n in zip(self.classes, counts, strict=True)}

    def in_memory(self) -> Dataset:
        """A copy with every image decoded and held in memory."""
        records = [replace(r, array=self.image(i)) for i, r in enumerate(self.records)]
        return Dataset(self.classes, records, name=self.name)

    # -- constructors and writers (see _coco.py and _yolo.py) ------------------------------

    @classmethod
    def from_arrays(
        cls,
        images: Sequence[npt.NDArray[np.uint8]],
        boxes: Sequence[npt.ArrayLike],
        labels: Sequence[npt.ArrayLike],
        classes: Sequence[str],
        *,
        name: str = "",
        meta: Sequence[Mapping[str, Any]] | None = None,
        ignore: Sequence[npt.ArrayLike] | None = None,
        ignore_labels: Sequence[npt.ArrayLike] | None = None,
    ) -> Dataset:
        """A dataset held in memory.

        Args:
            images: ``(H, W, 3)`` ``uint8`` RGB images.
            boxes: ``[N_i, 4]`` xyxy pixel boxes per image.
            labels: ``[N_i]`` class indices per image.
            classes: Class names.
            name: A label for messages.
            meta: Extra fields per image (kept in COCO exports).
            ignore: ``[K_i, 4]`` xyxy ignore boxes per image (see :class:`Record`).
            ignore_labels: ``[K_i]`` their classes (required with *ignore*).

        """
        if not len(images) == len(boxes) == len(labels):
            raise AnunnakiError(
                f"{len(images)} images, {len(boxes)} box lists and {len(labels)} label lists; "
                "give one of each per image"
            )
        if (ignore is None) != (ignore_labels is None):
            raise AnunnakiError("give ignore boxes and ignore_labels together")
        if (
            ignore is not None
            and ignore_labels is not None
            and not len(ignore) == len(ignore_labels) == len(images)
        ):
            raise AnunnakiError(
                f"{len(images)} images, {len(ignore)} ignore box lists and "
                f"{len(ignore_labels)} ignore label lists; give one of each per image"
            )
        records = []
        for i, (raw, b, lab) in enumerate(zip(images, boxes, labels, strict=True)):
            image = np.asarray(raw)
            if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
                raise AnunnakiError(
                    f"image {i}: expected (H, W, 3) uint8 RGB, got {image.shape} {image.dtype}"
                )
            bx = np.asarray(b, dtype=np.float32).reshape(-1, 4)
            lb = np.asarray(lab, dtype=np.int64).reshape(-1)
            if len(bx) != len(lb):
                raise AnunnakiError(f"image {i}: {len(bx)} boxes but {len(lb)} labels")
            ig = np.zeros((0, 4), np.float32)
            il = np.zeros(0, np.int64)
            if ignore is not None and ignore_labels is not None:
                ig = np.asarray(ignore[i], dtype=np.float32).reshape(-1, 4)
                il = np.asarray(ignore_labels[i], dtype=np.int64).reshape(-1)
                if len(ig) != len(il):
                    raise AnunnakiError(
                        f"image {i}: {len(ig)} ignore boxes but {len(il)} ignore labels"
                    )
            records.append(
                Record(
                    file_name=f"{i:06d}.png",
                    width=int(image.shape[1]),
                    height=int(image.shape[0]),
                    boxes=bx,
                    labels=lb,
                    image_id=i + 1,
                    array=image,
                    meta=dict(meta[i]) if meta is not None else {},
                    ignore=ig,
                    ignore_labels=il,
                )
            )
        return cls(classes, records, name=name)

    @classmethod
    def from_coco(
        cls, path: str | Path, *, images_dir: str | Path | None = None, cache: bool = False
    ) -> Dataset:
        """Read a COCO detection JSON (see :func:`anunnaki.datasets.read_coco`)."""
        return read_coco(path, images_dir=images_dir, cache=cache)

    def to_coco(
        self, path: str | Path, *, images_dir: str | Path | None = None, info: Any = None
    ) -> Path:
        """Write COCO JSON and the images (see :func:`anunnaki.datasets.write_coco`)."""
        return write_coco(self, path, images_dir=images_dir, info=info)

    @classmethod
    def from_yolo(
        cls,
        images_dir: str | Path,
        *,
        labels_dir: str | Path | None = None,
        classes: Sequence[str] | str | Path | None = None,
        cache: bool = False,
    ) -> Dataset:
        """Read a YOLO folder (see :func:`anunnaki.datasets.read_yolo`)."""
        return read_yolo(images_dir, labels_dir=labels_dir, classes=classes, cache=cache)

    def to_yolo(self, out_dir: str | Path) -> Path:
        """Write a YOLO folder (see :func:`anunnaki.datasets.write_yolo`)."""
        return write_yolo(self, out_dir)


def read_coco(
    path: str | Path, *, images_dir: str | Path | None = None, cache: bool = False
) -> Dataset:
    """Read a COCO detection file into a :class:`Dataset`.

    Args:
        path: The JSON file.
        images_dir: Folder the ``file_name`` s are relative to; by default ``images/`` next to
            the JSON file when it exists, else the JSON file's folder.
        cache: Keep decoded images in memory.

    Raises:
        DatasetError: The file is not JSON, a required element is missing or of the wrong
            type, an id is duplicated, an annotation refers to an unknown image or category,
            a bbox is not four finite numbers with positive size, or an image file is
            missing. The message names the file and the element (``annotations[id=17].bbox``).

    """
    classes, records = coco_records(path, images_dir=images_dir)
    return Dataset(classes, records, name=str(Path(path)), cache=cache)


def read_yolo(
    images_dir: str | Path,
    *,
    labels_dir: str | Path | None = None,
    classes: Sequence[str] | str | Path | None = None,
    cache: bool = False,
) -> Dataset:
    """Read a YOLO-format folder into a :class:`Dataset`.

    Args:
        images_dir: The folder of images (``DIR/images``).
        labels_dir: The folder of ``.txt`` label files; by default ``labels/`` beside
            ``images/`` (``DIR/labels``), else *images_dir* itself.
        classes: Class names, or a ``classes.txt``/``obj.names``/``data.yaml`` path; by
            default found next to the folders.
        cache: Keep decoded images in memory.

    Raises:
        DatasetError: A label line is malformed (``file:line``, the field and the fix), a
            class index is out of range, the classes list is missing, or an image is
            unreadable.

    """
    names, records = yolo_records(
        images_dir, labels_dir=labels_dir, classes=classes, keep_pixels=cache
    )
    return Dataset(names, records, name=str(Path(images_dir)), cache=cache)
