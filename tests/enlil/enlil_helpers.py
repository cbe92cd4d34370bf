"""A fast stand-in model and data for Enlil's tests: no torch, deterministic.

``ColourDetector`` finds the one red box of each :func:`tiny_data` image by thresholding
the colour, so darkening, fog or a hue shift really lowers its F1, in microseconds.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from anunnaki.datasets import Dataset
from anunnaki.lec import DetectionResult


class ColourDetector:
    """Detects the red blob: pixels with R > 150 and G, B < 110."""

    model_id = "colour"
    classes = ("pedestrian", "deer")
    score_threshold = 0.5

    def detect(self, images: Sequence[npt.NDArray[np.uint8]]) -> list[DetectionResult]:
        out = []
        for image in images:
            im = np.asarray(image).astype(np.int16)
            mask = (im[..., 0] > 150) & (im[..., 1] < 110) & (im[..., 2] < 110)
            ys, xs = np.nonzero(mask)
            if len(xs) < 20:
                out.append(DetectionResult(np.zeros((0, 4)), np.zeros(0), np.zeros(0)))
                continue
            box = [[xs.min(), ys.min(), xs.max() + 1, ys.max() + 1]]
            out.append(DetectionResult(np.asarray(box, np.float32), [0], [0.9]))
        return out


def tiny_data(n: int = 12, seed: int = 0) -> Dataset:
    """*n* 64 × 64 grey images with one red 12 × 16 box each."""
    rng = np.random.default_rng(seed)
    images, boxes, labels = [], [], []
    for _ in range(n):
        image = np.full((64, 64, 3), 90, np.uint8)
        x, y = (int(v) for v in rng.integers(4, 40, 2))
        image[y : y + 16, x : x + 12] = (180 + int(rng.integers(0, 70)), 40, 40)
        images.append(image)
        boxes.append([[x, y, x + 12, y + 16]])
        labels.append([0])
    return Dataset.from_arrays(images, boxes, labels, ("pedestrian", "deer"))
