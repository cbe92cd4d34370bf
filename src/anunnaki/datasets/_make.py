"""Generate labelled datasets from the simulated scenes, split by scene layout.

Why split by layout: frames of one layout show the same objects in the same places from
different cameras, so a random split of frames would put near-copies of test images in the
training set and overstate F1. Each layout goes to exactly one split.

Layout: ``OUT/images/*.png`` and ``OUT/train.json``, ``OUT/val.json``, ``OUT/test.json``
(COCO, one per split; each image carries ``layout``, ``seed``, ``t`` and ``seq``).
"""

from __future__ import annotations

import multiprocessing
import sys
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from anunnaki.datasets._coco import write_coco
from anunnaki.datasets._dataset import Dataset, read_yolo
from anunnaki.datasets._record import DatasetError, Record, write_image
from anunnaki.errors import AnunnakiError

__all__ = [
    "DEFAULT_LAYOUTS",
    "SPLITS",
    "FrameLike",
    "FrameSource",
    "load_split",
    "make_dataset",
]

SPLITS = ("train", "val", "test")
#: Default layouts per split: 40 / 4 / 10 layouts, so 2000 / 200 / 500 images at 50 a layout.
DEFAULT_LAYOUTS: dict[str, range] = {
    "train": range(0, 40),
    "val": range(40, 44),
    "test": range(44, 54),
}


class FrameLike(Protocol):
    """What a frame source yields (``anunnaki.sim.Frame`` is one)."""

    @property
    def image(self) -> Any:
        """``(H, W, 3)`` ``uint8`` RGB."""

    @property
    def boxes(self) -> Any:
        """``[N, 4]`` xyxy pixels."""

    @property
    def labels(self) -> Any:
        """``[N]`` class indices."""

    @property
    def t(self) -> float:
        """Time stamp (s)."""

    @property
    def seq(self) -> int:
        """Frame number."""


#: Optional on a frame: ``ignore`` (``[K, 4]`` xyxy ignore boxes) and ``ignore_labels``
#: (``[K]``), read with ``getattr`` — objects seen but not labelled (``Record.ignore``).


#: ``source(platform, *, layout, seed, n, width, height)`` → frames; the signature of
#: :func:`anunnaki.sim.dataset_frames`. Must be picklable (a module-level function) when
#: ``workers > 1``.
FrameSource = Callable[..., Iterable[FrameLike]]


def _pool_context() -> multiprocessing.context.BaseContext:
    """``fork`` where it is safe and available, else ``spawn``.

    ``fork`` needs no ``if __name__ == "__main__":`` guard in the calling script and starts
    in milliseconds; it is not used once torch is imported (its thread pools do not survive
    a fork reliably), and then the calling script needs the guard, as with any ``spawn``.
    """
    if "fork" in multiprocessing.get_all_start_methods() and "torch" not in sys.modules:
        return multiprocessing.get_context("fork")
    return multiprocessing.get_context("spawn")


def _render_layout(
    source: FrameSource,
    *,
    platform: str,
    layout: int,
    seed: int,
    n: int,
    width: int,
    height: int,
    images_dir: str,
    **extra: Any,
) -> list[dict[str, Any]]:
    """Render one layout's frames, write their PNGs, return their annotations."""
    out = []
    for k, frame in enumerate(
        source(platform, layout=layout, seed=seed, n=n, width=width, height=height, **extra)
    ):
        image = np.asarray(frame.image)
        if image.shape != (height, width, 3) or image.dtype != np.uint8:
            raise AnunnakiError(
                f"frame source gave a {image.shape} {image.dtype} image for layout {layout}; "
                f"expected ({height}, {width}, 3) uint8"
            )
        name = f"{platform}_L{layout:04d}_{k:04d}.png"
        write_image(Path(images_dir) / name, image)
        out.append(
            {
                "file_name": name,
                "boxes": np.asarray(frame.boxes, np.float32).reshape(-1, 4).tolist(),
                "labels": np.asarray(frame.labels, np.int64).reshape(-1).tolist(),
                "ignore": np.asarray(getattr(frame, "ignore", ()), np.float32)
                .reshape(-1, 4)
                .tolist(),
                "ignore_labels": np.asarray(getattr(frame, "ignore_labels", ()), np.int64)
                .reshape(-1)
                .tolist(),
                "meta": {"layout": layout, "seed": seed, "t": float(frame.t), "seq": frame.seq},
            }
        )
    return out


def _check_layouts(splits: Mapping[str, Sequence[int]]) -> None:
    """Layouts are numbers >= 0, each in one split only (its frames show one scene)."""
    owner: dict[int, str] = {}
    for split, layouts in splits.items():
        for layout in layouts:
            if layout < 0:
                raise AnunnakiError(f"{split} layout {layout}: layouts are numbers >= 0")
            if layout in owner:
                raise AnunnakiError(
                    f"layout {layout} is in both the {owner[layout]} and the {split} split; "
                    "a layout may be in one split only (its frames show the same scene)"
                )
            owner[layout] = split


def _render_all(
    src: FrameSource,
    tasks: Sequence[tuple[str, int]],
    job: Mapping[str, Any],
    *,
    workers: int,
    progress: bool,
) -> dict[tuple[str, int], list[dict[str, Any]]]:
    """Render every (split, layout) task, in worker processes when there are several."""
    platform, per_layout = job["platform"], job["n"]
    results: dict[tuple[str, int], list[dict[str, Any]]] = {}
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    columns = (
        TextColumn(f"[bold]{platform}[/] frames"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
    )
    if workers <= 1 or len(tasks) == 1:
        with Progress(*columns, disable=not progress) as bar:
            task = bar.add_task("render", total=len(tasks) * per_layout)
            for split, layout in tasks:
                results[split, layout] = _render_layout(src, layout=layout, **job)
                bar.advance(task, per_layout)
    else:
        with ProcessPoolExecutor(max_workers=workers, mp_context=_pool_context()) as pool:
            # Submit (and so start the workers) before the progress bar starts its thread.
            futures: dict[Future[list[dict[str, Any]]], tuple[str, int]] = {
                pool.submit(_render_layout, src, layout=layout, **job): (split, layout)
                for split, layout in tasks
            }
            with Progress(*columns, disable=not progress) as bar:
                task = bar.add_task("render", total=len(tasks) * per_layout)
                for fut in as_completed(futures):
                    results[futures[fut]] = fut.result()
                    bar.advance(task, per_layout)
    return results


def _write_splits(
    splits: Mapping[str, Sequence[int]],
    results: Mapping[tuple[str, int], list[dict[str, Any]]],
    out: Path,
    names: tuple[str, ...],
    job: Mapping[str, Any],
    *,
    min_label_height: float | None,
) -> dict[str, Path]:
    """One COCO file per split with layouts; image ids run across the splits."""
    platform, per_layout, seed = job["platform"], job["n"], job["seed"]
    width, height, images_dir = job["width"], job["height"], Path(job["images_dir"])
    paths: dict[str, Path] = {}
    next_id = 1
    for split, layouts in splits.items():
        if not layouts:
            continue
        records = []
        for layout in layouts:
            for item in results[split, layout]:
                records.append(
                    Record(
                        file_name=item["file_name"],
                        width=width,
                        height=height,
                        boxes=np.asarray(item["boxes"], np.float32).reshape(-1, 4),
                        labels=np.asarray(item["labels"], np.int64),
                        image_id=next_id,
                        path=images_dir / item["file_name"],
                        meta=item["meta"],
                        ignore=np.asarray(item["ignore"], np.float32).reshape(-1, 4),
                        ignore_labels=np.asarray(item["ignore_labels"], np.int64),
                    )
                )
                next_id += 1
        info = {
            "description": f"anunnaki simulated {platform} dataset, {split} split",
            "generator": "anunnaki make-dataset",
            "platform": platform,
            "split": split,
            "layouts": list(layouts),
            "per_layout": per_layout,
            "seed": seed,
            "width": width,
            "height": height,
            "min_label_height": min_label_height,
        }
        ds = Dataset(names, records, name=f"{platform} {split}")
        paths[split] = write_coco(ds, out / f"{split}.json", info=info)
    return paths


def make_dataset(
    platform: str,
    out_dir: str | Path,
    *,
    train_layouts: Sequence[int] = DEFAULT_LAYOUTS["train"],
    val_layouts: Sequence[int] = DEFAULT_LAYOUTS["val"],
    test_layouts: Sequence[int] = DEFAULT_LAYOUTS["test"],
    per_layout: int = 50,
    width: int = 128,
    height: int = 128,
    seed: int = 0,
    workers: int = 2,
    progress: bool = False,
    overwrite: bool = False,
    source: FrameSource | None = None,
    classes: Sequence[str] | None = None,
    min_label_height: float | None = None,
) -> dict[str, Path]:
    """Render a labelled dataset with train/val/test splits by scene layout.

    Args:
        platform: ``"rover"`` or ``"uav"`` (passed to *source*).
        out_dir: The folder to create (``images/`` and one COCO JSON per split).
        train_layouts: Scene layouts of the training split.
        val_layouts: Scene layouts of the validation split (threshold choice).
        test_layouts: Scene layouts of the test split (the reported figures).
        per_layout: Frames per layout (default 50: 2000 / 200 / 500 images).
        width: Image width in pixels.
        height: Image height in pixels.
        seed: Seeds camera poses, lighting and object poses within every layout.
        workers: Processes rendering layouts in parallel (1 renders in this process). They
            are forked on POSIX unless torch is already imported; then they are spawned,
            and a calling script needs the ``if __name__ == "__main__":`` guard.
        progress: Show a rich progress bar.
        overwrite: Replace an existing dataset in *out_dir*.
        source: A frame source with the signature of :func:`anunnaki.sim.dataset_frames`
            (:func:`anunnaki.sim.make_dataset` passes the simulated scenes); plug your own
            simulator in here.
        classes: The class names of the frames' labels.
        min_label_height: Passed to *source* when given: the smallest labelled box height
            as a fraction of the image height (default: the platform's
            ``anunnaki.sim.MIN_LABEL_HEIGHT``); objects seen but smaller become ignore
            boxes (``iscrowd: 1`` in the COCO files).

    Returns:
        ``{"train": OUT/train.json, "val": …, "test": …}`` (splits with no layouts are
        skipped).

    Raises:
        AnunnakiError: A layout is in two splits, *out_dir* already holds a dataset, or an
            argument is out of range.

    """
    splits = {"train": list(train_layouts), "val": list(val_layouts), "test": list(test_layouts)}
    _check_layouts(splits)
    if per_layout < 1:
        raise AnunnakiError(f"per_layout must be at least 1, got {per_layout}")
    if width < 16 or height < 16:
        raise AnunnakiError(f"images must be at least 16x16 px, got {width}x{height}")
    if source is None or classes is None:
        raise AnunnakiError(
            "give the frame source and the class names (source=, classes=); the simulated "
            "scenes are anunnaki.sim.make_dataset (CLI: anunnaki make-dataset)"
        )
    names = tuple(classes)
    out = Path(out_dir)
    if not overwrite and any((out / f"{s}.json").exists() for s in SPLITS):
        raise AnunnakiError(
            f"{out} already holds a dataset; choose another folder or pass overwrite=True "
            "(CLI: --overwrite)"
        )
    images_dir = out / "images"
    images_dir.mkdir(parents=True, exist_ok=True)
    src: FrameSource = source
    tasks = [(split, layout) for split, layouts in splits.items() for layout in layouts]
    job: dict[str, Any] = {
        "platform": platform,
        "seed": seed,
        "n": per_layout,
        "width": width,
        "height": height,
        "images_dir": str(images_dir),
    }
    if min_label_height is not None:
        job["min_label_height"] = min_label_height

    results = _render_all(src, tasks, job, workers=workers, progress=progress)
    return _write_splits(splits, results, out, names, job, min_label_height=min_label_height)


def load_split(data: str | Path, split: str = "test", *, cache: bool = False) -> Dataset:
    """Load one split of a dataset, whatever its format.

    Looked for, in order:

    1. *data* is a ``.json`` file: that COCO file (*split* is ignored);
    2. ``DATA/SPLIT.json`` (what :func:`make_dataset` writes; images in ``DATA/images``);
    3. ``DATA/images/SPLIT`` with ``DATA/labels/SPLIT`` (the Ultralytics YOLO layout;
       classes from ``DATA/classes.txt`` or ``DATA/data.yaml``);
    4. ``DATA/SPLIT/images`` with ``DATA/SPLIT/labels`` (YOLO, one folder per split).

    Raises:
        DatasetError: None of these exists, or the files found are invalid.

    """
    root = Path(data)
    if root.suffix == ".json":
        return Dataset.from_coco(root, cache=cache)
    if (root / f"{split}.json").is_file():
        return Dataset.from_coco(root / f"{split}.json", cache=cache)
    classes = next(
        (
            root / name
            for name in ("classes.txt", "obj.names", "data.yaml")
            if (root / name).is_file()
        ),
        None,
    )
    if (root / "images" / split).is_dir():
        return read_yolo(
            root / "images" / split,
            labels_dir=root / "labels" / split,
            classes=classes,
            cache=cache,
        )
    if (root / split / "images").is_dir():
        return read_yolo(root / split / "images", classes=classes, cache=cache)
    present = [s for s in SPLITS if (root / f"{s}.json").is_file()]
    raise DatasetError(
        f"no {split!r} split here (COCO splits found: {', '.join(present) or 'none'})",
        path=root,
        hint=f"expected {split}.json, images/{split}/ + labels/{split}/ or {split}/images/; "
        "make one with `anunnaki make-dataset`",
    )
