"""One labelled image, its files, and what every dataset format reads and writes.

The floor of the datasets package: :class:`Record` (an image without its pixels),
:class:`Sample` (with them), image files in and out, the error every dataset file raises, and
:class:`Labelled` — what the COCO and YOLO writers need of a dataset (its classes, records and
pixels). The formats build on this module alone; :class:`~anunnaki.datasets.Dataset` builds
on them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple, Protocol

import numpy as np
import numpy.typing as npt

from anunnaki.errors import AnunnakiError, ModelFileError

__all__ = ["DatasetError", "Labelled", "Record", "Sample", "read_image", "write_image"]


class DatasetError(ModelFileError):
    """A dataset file (COCO JSON, YOLO label file, classes list, image) is missing or invalid.

    Renders as ``file:line: element: message (hint: …)``; COCO errors name the element by
    id (``annotations[id=17].bbox``), YOLO errors by ``file:line``.
    """


class Sample(NamedTuple):
    """One labelled image.

    Attributes:
        image: ``(H, W, 3)`` ``uint8`` RGB.
        boxes: ``[N, 4]`` ``float32`` ``x1, y1, x2, y2`` in pixels.
        labels: ``[N]`` ``int64`` indices into the dataset's ``classes``.

    """

    image: npt.NDArray[np.uint8]
    boxes: npt.NDArray[np.float32]
    labels: npt.NDArray[np.int64]


@dataclass(frozen=True)
class Record:
    """One image of a dataset without its pixels.

    Attributes:
        file_name: Name of the image relative to the dataset's image folder (the COCO
            ``file_name``).
        width: Image width in pixels.
        height: Image height in pixels.
        boxes: ``[N, 4]`` ``float32`` xyxy pixels.
        labels: ``[N]`` ``int64`` class indices.
        image_id: The COCO image id (unique within a dataset).
        path: Where the image is on disk, or ``None`` for an in-memory image.
        array: The image itself when held in memory.
        meta: Extra fields (``layout``, ``seed``, ``t`` … for generated data).
        ignore: ``[K, 4]`` ``float32`` xyxy *ignore boxes*: objects in the image that are
            not labelled (too small, mostly occluded or cut by the frame; COCO ``iscrowd``
            regions). A prediction lying mostly inside one counts neither as right nor as
            wrong, and training puts no background loss there. Empty by default.
        ignore_labels: ``[K]`` ``int64`` class of each ignore box.

    """

    file_name: str
    width: int
    height: int
    boxes: npt.NDArray[np.float32]
    labels: npt.NDArray[np.int64]
    image_id: int = 0
    path: Path | None = None
    array: npt.NDArray[np.uint8] | None = field(default=None, repr=False)
    meta: Mapping[str, Any] = field(default_factory=dict)
    ignore: npt.NDArray[np.float32] = field(
        default_factory=lambda: np.zeros((0, 4), np.float32), repr=False
    )
    ignore_labels: npt.NDArray[np.int64] = field(
        default_factory=lambda: np.zeros(0, np.int64), repr=False
    )


def read_image(path: str | Path) -> npt.NDArray[np.uint8]:
    """Read an image file as ``(H, W, 3)`` ``uint8`` RGB.

    Raises:
        DatasetError: The file is missing or not an image OpenCV can decode.

    """
    import cv2

    p = Path(path)
    data = np.fromfile(p, dtype=np.uint8) if p.is_file() else None
    if data is None:
        raise DatasetError("image file not found", path=p, hint="check the image folder")
    image = cv2.imdecode(data, cv2.IMREAD_COLOR) if data.size else None
    if image is None:
        raise DatasetError("not an image OpenCV can read", path=p, hint="use PNG or JPEG files")
    out: npt.NDArray[np.uint8] = np.ascontiguousarray(image[:, :, ::-1])
    return out


def write_image(path: str | Path, image: npt.NDArray[np.uint8]) -> None:
    """Write an ``(H, W, 3)`` ``uint8`` RGB image; the suffix picks the format (``.png``)."""
    import cv2

    p = Path(path)
    ok, buf = cv2.imencode(p.suffix or ".png", np.ascontiguousarray(image[:, :, ::-1]))
    if not ok:  # pragma: no cover - OpenCV refuses only unknown suffixes
        raise AnunnakiError(f"{p}: OpenCV cannot encode {p.suffix!r} images")
    p.write_bytes(buf.tobytes())


class Labelled(Protocol):
    """What a writer needs of a dataset: its classes, its records and each image's pixels."""

    @property
    def classes(self) -> tuple[str, ...]:
        """Class names; labels index into them."""
        ...

    @property
    def records(self) -> tuple[Record, ...]:
        """The images without their pixels."""
        ...

    def image(self, index: int) -> npt.NDArray[np.uint8]:
        """The ``(H, W, 3)`` ``uint8`` RGB pixels of image *index*."""
        ...
