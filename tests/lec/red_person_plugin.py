"""A third-party person detector behind a 10-line loader plugin (``loader: red_person``).

It stands for a model of another framework that knows one class, ``pedestrian``: it finds
the red blob of each image (R above the model file's ``red``, G and B below 110), so a
darker or foggier image really lowers its F1. Its model file is JSON ``{"model_id",
"domain", "red"}``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from anunnaki.lec import DetectionResult, ImageBatch, as_image_list


class RedPersonDetector:
    """A :class:`~anunnaki.lec.Detector` of one class: the red blob is a pedestrian."""

    classes = ("pedestrian",)
    score_threshold = 0.5

    def __init__(self, model_id: str, domain: str, red: int) -> None:
        self.model_id, self.domain, self.red = model_id, domain, red

    def detect(self, images: ImageBatch) -> list[DetectionResult]:
        out = []
        for image in as_image_list(images):
            im = image.astype(np.int16)
            ys, xs = np.nonzero((im[..., 0] > self.red) & (im[..., 1] < 110) & (im[..., 2] < 110))
            box = [[xs.min(), ys.min(), xs.max() + 1, ys.max() + 1]] if len(xs) >= 20 else []
            out.append(DetectionResult(np.asarray(box, np.float32).reshape(-1, 4),
                                       np.zeros(len(box), np.int64),
                                       np.full(len(box), 0.9, np.float32)))  # fmt: skip
        return out


class RedPerson:
    """The loader plugin: the whole of what a third party writes to plug its model in."""

    name = "red_person"

    def load(self, file: Path, options: Mapping[str, Any]) -> RedPersonDetector:
        spec = json.loads(file.read_text(encoding="utf-8"))
        return RedPersonDetector(spec["model_id"], spec["domain"], int(spec["red"]))
