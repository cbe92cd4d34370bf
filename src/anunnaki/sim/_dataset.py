"""Labelled datasets rendered from the simulated scenes (``anunnaki make-dataset``).

:func:`anunnaki.datasets.make_dataset` writes any frame source's frames as a dataset split by
layout; this module is its source for the pybullet scenes, next to the scenes themselves, so
``anunnaki.datasets`` needs nothing from the simulator.
"""

from __future__ import annotations

from collections.abc import Iterable
from functools import partial
from pathlib import Path
from typing import Any

from anunnaki.datasets import make_dataset as _make_dataset
from anunnaki.errors import AnunnakiError
from anunnaki.sim._layout import ROVER_CLASSES, UAV_CLASSES
from anunnaki.sim._scene import dataset_frames

__all__ = ["make_dataset", "platform_classes", "scene_frames"]


def platform_classes(platform: str) -> tuple[str, ...]:
    """Class names of a simulated platform (``rover``: pedestrian, deer; ``uav``: …)."""
    known = {"rover": ROVER_CLASSES, "uav": UAV_CLASSES}
    if platform not in known:
        raise AnunnakiError(f"unknown platform {platform!r}; choose one of: rover, uav")
    return tuple(known[platform])


def scene_frames(platform: str, **kwargs: Any) -> Iterable[Any]:
    """The frames of one scene layout (a picklable frame source for worker processes)."""
    frames: Iterable[Any] = dataset_frames(platform, **kwargs)  # type: ignore[arg-type]
    return frames


def make_dataset(
    platform: str,
    out_dir: str | Path,
    *,
    clutter: bool = True,
    min_distance: float | None = None,
    **kwargs: Any,
) -> dict[str, Path]:
    """Render a labelled dataset of a simulated platform's scenes, split by layout.

    ``platform`` is ``"rover"`` or ``"uav"``; ``clutter=False`` renders only the layouts'
    objects of a class on bare ground and ``min_distance`` (metres; ``None``: the camera's
    default, 1.5) brings the rover's camera closer to what it aims at
    (:func:`anunnaki.sim.dataset_frames`); only what differs from the defaults is passed to
    the frame source. Every other argument is
    :func:`anunnaki.datasets.make_dataset`'s (``per_layout``, ``width``, ``height``,
    ``seed``, ``workers``, ``progress``, ``overwrite``, the layouts of each split,
    ``min_label_height``).
    """
    options: dict[str, Any] = {}
    if not clutter:
        options["clutter"] = False
    if min_distance is not None:
        options["min_distance"] = min_distance
    kwargs.setdefault("source", partial(scene_frames, **options) if options else scene_frames)
    kwargs.setdefault("classes", platform_classes(platform))
    return _make_dataset(platform, out_dir, **kwargs)
