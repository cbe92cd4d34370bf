"""A detector architecture plugin for the tests: a detector that returns fixed boxes.

It stands for a third-party package wrapping a model that is not an anunnaki safetensors
file. Its model file is JSON, ``{"model_id", "domain", "boxes": [[x1, y1, x2, y2, class,
score], ...]}`` (``class`` a name); the class names, in label order, are in a second file the
entry's options name (``classes: classes.txt``, one per line), so the registry pins two files.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from anunnaki.lec import DetectionResult, ImageBatch, as_image_list

OPTIONS = {"classes", "score_threshold"}


class FixedBoxesDetector:
    """Every image gets the same boxes (clipped to it); a :class:`~anunnaki.lec.Detector`."""

    def __init__(
        self,
        model_id: str,
        domain: str,
        classes: Sequence[str],
        rows: Sequence[Sequence[Any]],
        score_threshold: float = 0.0,
    ) -> None:
        self.model_id = model_id
        self.domain = domain
        self.classes = tuple(classes)
        self.score_threshold = score_threshold
        self._boxes = np.array([r[:4] for r in rows], np.float32).reshape(-1, 4)
        self._labels = np.array([self.classes.index(r[4]) for r in rows], np.int64)
        self._scores = np.array([r[5] for r in rows], np.float32)

    def detect(self, images: ImageBatch) -> list[DetectionResult]:
        out = []
        for image in as_image_list(images):
            h, w = image.shape[:2]
            boxes = self._boxes.copy()
            boxes[:, 0::2] = boxes[:, 0::2].clip(0, w)
            boxes[:, 1::2] = boxes[:, 1::2].clip(0, h)
            keep = (boxes[:, 2] > boxes[:, 0]) & (boxes[:, 3] > boxes[:, 1])
            out.append(DetectionResult(boxes[keep], self._labels[keep], self._scores[keep]))
        return out


class FixedBoxes:
    """The plugin: ``loader: fixed_boxes`` in a model registry entry."""

    name = "fixed_boxes"

    def files(self, file: Path, options: Mapping[str, Any]) -> list[Path]:
        return [file, file.parent / str(options.get("classes", "classes.txt"))]

    def load(self, file: Path, options: Mapping[str, Any]) -> FixedBoxesDetector:
        unknown = set(options) - OPTIONS
        if unknown:
            raise ValueError(f"unknown options {sorted(unknown)}; fixed_boxes takes {OPTIONS}")
        data = json.loads(file.read_text(encoding="utf-8"))
        names = self.files(file, options)[1].read_text(encoding="utf-8").split()
        return FixedBoxesDetector(
            data["model_id"],
            data["domain"],
            names,
            data["boxes"],
            float(options.get("score_threshold", 0.0)),
        )


def write_model(
    folder: Path,
    *,
    model_id: str = "fixed-default",
    domain: str = "default",
    classes: Sequence[str] = ("pedestrian", "deer"),
    boxes: Sequence[Sequence[Any]] = ((4, 4, 20, 30, "pedestrian", 0.9),),
) -> tuple[Path, Path]:
    """Write a model file and its class list into ``folder``; return both paths."""
    folder.mkdir(parents=True, exist_ok=True)
    model = folder / f"{model_id}.json"
    model.write_text(json.dumps({"model_id": model_id, "domain": domain, "boxes": boxes}))
    names = folder / "classes.txt"
    names.write_text("\n".join(classes) + "\n")
    return model, names
