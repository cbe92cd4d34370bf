"""Labelled image datasets: generated from the simulated scenes, or imported (COCO, YOLO).

Everything that trains or assesses a detector reads a :class:`Dataset`: ``len(ds)``,
``ds[i]`` → ``(image, boxes, labels)`` (``(H, W, 3)`` ``uint8`` RGB, ``[N, 4]`` ``float32``
xyxy pixels, ``[N]`` ``int64`` class indices), iteration, ``ds.classes``, ``ds.subset(idx)``
and ``ds.truths()`` (boxes, labels and ignore boxes — objects seen but not labelled —
without reading images).

Generating one from the simulator (``anunnaki make-dataset``, or
:func:`anunnaki.sim.make_dataset`, which passes the scenes to :func:`make_dataset` here), split
by scene layout so no scene is in two splits::

    from anunnaki.datasets import load_split
    from anunnaki.sim import make_dataset

    make_dataset("rover", "data/rover", per_layout=50, progress=True)   # 2000/200/500 images
    test = load_split("data/rover", "test")

:func:`make_dataset` here writes any frame source's frames (``source=``, ``classes=``): plug
another simulator in. Nothing in this package imports the simulator.

Bringing your own data: :meth:`Dataset.from_coco` (``bbox`` = ``[x, y, w, h]`` pixels) and
:meth:`Dataset.from_yolo` (``class cx cy w h`` normalised, one ``.txt`` per image and a
classes list); :meth:`Dataset.to_coco` and :meth:`Dataset.to_yolo` write them. A malformed
file raises :class:`DatasetError` naming the file and the element (COCO: the annotation or
image id; YOLO: ``file:line``) and the fix. See ``docs/detector.md``.

Needs the ``vision`` extra (numpy, OpenCV; generation also pybullet).
"""

from anunnaki.datasets._coco import coco_dict, write_coco
from anunnaki.datasets._dataset import Dataset, read_coco, read_yolo
from anunnaki.datasets._make import (
    DEFAULT_LAYOUTS,
    SPLITS,
    FrameLike,
    FrameSource,
    load_split,
    make_dataset,
)
from anunnaki.datasets._record import DatasetError, Record, Sample, read_image, write_image
from anunnaki.datasets._yolo import IMAGE_SUFFIXES, write_yolo

__all__ = [
    "DEFAULT_LAYOUTS",
    "IMAGE_SUFFIXES",
    "SPLITS",
    "Dataset",
    "DatasetError",
    "FrameLike",
    "FrameSource",
    "Record",
    "Sample",
    "coco_dict",
    "load_split",
    "make_dataset",
    "read_coco",
    "read_image",
    "read_yolo",
    "write_coco",
    "write_image",
    "write_yolo",
]
