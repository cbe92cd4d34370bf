"""Ground truth of a frame: labelled and ignore boxes from pybullet's segmentation mask.

Ground truth comes from the mask, never from a model: :func:`annotate_mask` holds the rule
that keeps a box (size, in-frame fraction, visible fraction, the platform's smallest
labelled height) and :class:`Frame` carries an image with its boxes. Kept apart from the
scene so the rule can be read and tested on a plain array.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from anunnaki.sim._world import Camera

__all__ = [
    "MIN_BOX_SIZE",
    "MIN_IN_FRAME",
    "MIN_LABEL_HEIGHT",
    "MIN_VISIBLE",
    "Annotation",
    "Frame",
    "annotate_mask",
    "boxes_from_mask",
]

MIN_BOX_SIZE = 4.0
"""A kept box is at least this many pixels wide *and* high."""
MIN_VISIBLE = 0.25
"""A kept box covers at least this fraction of the object's projected, in-frame extent."""
MIN_IN_FRAME = 0.5
"""At least this fraction of the object's projected extent lies inside the image."""
MIN_LABEL_HEIGHT: dict[str, float] = {"rover": 0.134, "uav": 0.0}
"""Per platform: a labelled box is at least this fraction of the image height tall.

Objects seen but smaller become *ignore boxes* (see :func:`annotate_mask`). The rover's
value follows from its stop rule (``anunnaki.sim.StopRule``): it acts on pedestrians and
deer within ``stop_distance`` = 3 m, and its detector is asked to see them from twice that
far, 6 m, so it has locked on before they are in range (at the 0.8 m/s cruise speed, 3.75 s
or about 37 frames at 10 Hz). The smallest such object is the smallest deer, 0.93 m tall
(a pedestrian is 1.59-1.95 m). With the camera's 60° vertical field of view the focal
length is ``f = (H/2) / tan 30° = 0.866 H`` pixels, so a 0.93 m object at 6 m is
``0.866 H · 0.93 / 6 = 0.134 H`` tall: 17.2 px at 128 × 128 (a pedestrian at 6 m: 29 px;
the smallest deer at 3 m: 34 px). The UAV has no such rule: 0 keeps every box of at least
:data:`MIN_BOX_SIZE`.
"""


@dataclass(frozen=True)
class Frame:
    """One rendered camera frame with its ground truth.

    Attributes:
        image: ``[H, W, 3]`` ``uint8`` RGB.
        boxes: ``[N, 4]`` ``float32`` ``x1, y1, x2, y2`` in pixels (``x2``/``y2`` exclusive:
            a box one pixel wide has ``x2 = x1 + 1``), from the segmentation mask.
        labels: ``[N]`` ``int64`` indices into the scene's classes.
        t: Simulation time (s).
        seq: Frame sequence number.
        ignore: ``[K, 4]`` ``float32`` *ignore boxes*: objects of a class that are in the
            image but not labelled (too small, mostly occluded or mostly cut by the frame),
            tight around their visible pixels. A detection there is neither right nor wrong
            (``anunnaki.lec.f1_at_iou``) and training puts no background loss there — the
            KITTI "DontCare" / COCO ``iscrowd`` practice.
        ignore_labels: ``[K]`` ``int64`` class of each ignore box.

    """

    image: np.ndarray
    boxes: np.ndarray
    labels: np.ndarray
    t: float
    seq: int
    ignore: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), np.float32))
    ignore_labels: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))


class Annotation(NamedTuple):
    """Ground truth of one frame (:func:`annotate_mask`).

    Attributes:
        boxes: ``[N, 4]`` ``float32`` labelled boxes (xyxy pixels, ``x2``/``y2`` exclusive).
        labels: ``[N]`` ``int64`` their classes.
        ignore: ``[K, 4]`` ``float32`` ignore boxes: seen but not labelled.
        ignore_labels: ``[K]`` ``int64`` their classes.

    """

    boxes: np.ndarray
    labels: np.ndarray
    ignore: np.ndarray
    ignore_labels: np.ndarray


def annotate_mask(
    mask: np.ndarray,
    instances: Mapping[int, tuple[int, Callable[[], tuple[np.ndarray, np.ndarray]]]],
    camera: Camera,
    *,
    min_size: float = MIN_BOX_SIZE,
    min_height: float = 0.0,
    min_visible: float = MIN_VISIBLE,
    min_in_frame: float = MIN_IN_FRAME,
) -> Annotation:
    """Ground-truth and ignore boxes from a segmentation mask.

    For each object of a class (``instances``: body id → (label, world AABB)) with at least
    one visible pixel, the box is tight around its visible pixels (``x2``/``y2``
    exclusive). It is *labelled* when

    * it is at least ``min_size`` pixels wide and high (default 4), and at least
      ``min_height`` pixels high (the platform's :data:`MIN_LABEL_HEIGHT`);
    * the object is not mostly cut by the frame: at least ``min_in_frame`` (0.5) of the
      area of its projected world bounding box lies inside the image;
    * it is not mostly occluded: the visible box covers at least ``min_visible`` (0.25) of
      that projected box's in-frame part.

    Every other visible object becomes an *ignore box*: it is there, so a detector that
    finds it is not wrong, but it is not required either.

    Args:
        mask: ``[H, W]`` pybullet segmentation (object and link index).
        instances: body id → (label index, a function returning the body's world AABB
            ``(low[3], high[3])``; called only for bodies seen in the mask).
        camera: The camera that rendered ``mask``.
        min_size: See above.
        min_height: See above.
        min_visible: See above.
        min_in_frame: See above.

    Returns:
        An :class:`Annotation`; boxes ordered by body id.

    """
    h, w = mask.shape
    objects = np.where(mask >= 0, mask & 0xFFFFFF, -1)
    present = set(np.unique(objects).tolist())
    kept: tuple[list[list[float]], list[int]] = ([], [])
    ignored: tuple[list[list[float]], list[int]] = ([], [])
    for body in sorted(instances):
        if body not in present:
            continue
        label, aabb = instances[body]
        box = _visible_box(objects == body)
        x1, y1, x2, y2 = box
        out = ignored
        if x2 - x1 >= min_size and y2 - y1 >= max(min_size, min_height):
            in_frame, visible = _in_frame_and_visible(box, aabb(), camera, w, h)
            if in_frame >= min_in_frame and visible >= min_visible:
                out = kept
        out[0].append(box)
        out[1].append(label)
    return Annotation(
        np.asarray(kept[0], dtype=np.float32).reshape(-1, 4),
        np.asarray(kept[1], dtype=np.int64),
        np.asarray(ignored[0], dtype=np.float32).reshape(-1, 4),
        np.asarray(ignored[1], dtype=np.int64),
    )


def _visible_box(pix: np.ndarray) -> list[float]:
    """``[x1, y1, x2, y2]`` tight around the true pixels of ``pix`` (``x2``/``y2`` exclusive)."""
    cols = np.flatnonzero(pix.any(axis=0))
    rows = np.flatnonzero(pix.any(axis=1))
    return [float(cols[0]), float(rows[0]), float(cols[-1] + 1), float(rows[-1] + 1)]


def _in_frame_and_visible(
    box: list[float], aabb: tuple[np.ndarray, np.ndarray], camera: Camera, w: int, h: int
) -> tuple[float, float]:
    """How much of an object the image shows, from its world AABB projected by ``camera``.

    Returns:
        The fraction of the projected box's area inside the ``w`` × ``h`` image, and the
        fraction of that in-frame part the visible ``box`` covers (occlusion).

    """
    lo, hi = aabb
    corners = np.array(
        [[a, b, c] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])]
    )
    uv = camera.project(corners, w, h)
    px1, py1 = uv.min(axis=0)
    px2, py2 = uv.max(axis=0)
    full = max((px2 - px1) * (py2 - py1), 1e-9)
    cx1, cy1 = max(px1, 0.0), max(py1, 0.0)
    cx2, cy2 = min(px2, float(w)), min(py2, float(h))
    inside = max(cx2 - cx1, 0.0) * max(cy2 - cy1, 0.0)
    x1, y1, x2, y2 = box
    return float(inside / full), float((x2 - x1) * (y2 - y1) / max(inside, 1e-9))


def boxes_from_mask(
    mask: np.ndarray,
    instances: Mapping[int, tuple[int, Callable[[], tuple[np.ndarray, np.ndarray]]]],
    camera: Camera,
    *,
    min_size: float = MIN_BOX_SIZE,
    min_height: float = 0.0,
    min_visible: float = MIN_VISIBLE,
    min_in_frame: float = MIN_IN_FRAME,
) -> tuple[np.ndarray, np.ndarray]:
    """The labelled boxes of :func:`annotate_mask` (``boxes [N, 4]``, ``labels [N]``)."""
    ann = annotate_mask(
        mask,
        instances,
        camera,
        min_size=min_size,
        min_height=min_height,
        min_visible=min_visible,
        min_in_frame=min_in_frame,
    )
    return ann.boxes, ann.labels
