"""Hidden boxes: labelled objects that a phenomenon covered become ignore boxes.

A raindrop on the lens replaces what is behind it by a refracted view of its surroundings
(``Phenomenon.occlusion``). A pedestrian more than half under the drop cannot be found, by
this model or any other, and teaching the model to "find" it there teaches it to fire on
drops. So a labelled box whose mean occlusion is at least
:data:`anunnaki.phenomena.HIDDEN` (0.5) is moved to the image's ignore boxes:

* in training, it is neither a target nor background (``encode_targets`` leaves every cell
  inside an ignore box out of the heat-map loss);
* in evaluation, it is not a miss, and a detection on it is not a false positive (the F1
  rule's ignore boxes, :func:`anunnaki.lec.match_image`).

The mean is taken over the pixels whose centres lie inside the box (at least one pixel: the
one holding the box's centre), in the coordinates of the image the mask was made for.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from anunnaki.lec._detector import DetectorError
from anunnaki.phenomena import HIDDEN

__all__ = ["box_occlusion", "hide_boxes"]


def box_occlusion(boxes: npt.ArrayLike, mask: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """The mean of *mask* over each box: ``[N, 4]`` xyxy pixels and ``[H, W]`` → ``[N]``.

    A box wholly outside the image gets 0 (nothing of it is hidden in the frame).
    """
    m = np.asarray(mask, np.float64)
    if m.ndim != 2:
        raise DetectorError(f"an occlusion mask is (height, width), got shape {m.shape}")
    b = np.asarray(boxes, np.float64).reshape(-1, 4)
    height, width = m.shape
    table = np.zeros((height + 1, width + 1))
    table[1:, 1:] = m.cumsum(0).cumsum(1)
    out = np.zeros(len(b))
    for k, (x1, y1, x2, y2) in enumerate(b):
        # Pixels whose centre (c + 0.5) lies in [x1, x2]; at least the centre pixel.
        c0, c1 = math.ceil(x1 - 0.5), math.floor(x2 - 0.5) + 1
        r0, r1 = math.ceil(y1 - 0.5), math.floor(y2 - 0.5) + 1
        if c1 <= c0:
            c0 = math.floor((x1 + x2) / 2)
            c1 = c0 + 1
        if r1 <= r0:
            r0 = math.floor((y1 + y2) / 2)
            r1 = r0 + 1
        c0, c1 = max(c0, 0), min(c1, width)
        r0, r1 = max(r0, 0), min(r1, height)
        if c1 <= c0 or r1 <= r0:
            continue
        total = table[r1, c1] - table[r0, c1] - table[r1, c0] + table[r0, c0]
        out[k] = total / ((r1 - r0) * (c1 - c0))
    return out


def hide_boxes(
    boxes: npt.ArrayLike,
    labels: npt.ArrayLike,
    ignore: npt.ArrayLike,
    mask: npt.ArrayLike | None,
    *,
    threshold: float = HIDDEN,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.int64], npt.NDArray[np.float32]]:
    """Move the boxes that *mask* hides (mean at least *threshold*) to the ignore boxes.

    Args:
        boxes: ``[N, 4]`` labelled boxes, xyxy pixels of the masked image.
        labels: ``[N]`` their classes.
        ignore: ``[K, 4]`` the image's ignore boxes.
        mask: ``[H, W]`` occlusion mask (``Phenomenon.occlusion``); ``None``: the
            phenomenon hides nothing, and everything is returned as it was.
        threshold: Mean occlusion from which a box is hidden.

    Returns:
        ``(boxes, labels, ignore)``: the visible boxes and their labels, and the ignore boxes
        followed by the hidden ones.

    """
    b = np.asarray(boxes, np.float32).reshape(-1, 4)
    lab = np.asarray(labels, np.int64).reshape(-1)
    ig = np.asarray(ignore, np.float32).reshape(-1, 4)
    if mask is None or len(b) == 0:
        return b, lab, ig
    if not 0.0 < threshold <= 1.0:
        raise DetectorError(f"the hidden threshold must be in (0, 1], got {threshold}")
    hidden = box_occlusion(b, mask) >= threshold
    if not hidden.any():
        return b, lab, ig
    return b[~hidden], lab[~hidden], np.concatenate([ig, b[hidden]])
