"""Running a search: the evaluator job, the local pool / Dask executors, resume, summary.

One code path for both executors: a round's contexts become tasks ``(job, vector)`` that
:func:`evaluate_task` runs wherever the executor puts it (a process of the local pool or a
Dask worker); each worker loads the model and the fixed batch once per job and caches them.
"""

from __future__ import annotations

import json
import multiprocessing
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from anunnaki import lec  # lec.evaluate_detector, lec.predict: torch at first call
from anunnaki.datasets import Dataset
from anunnaki.enlil._archive import Archive, ArchiveMeta, ArchiveWriter, read_archive
from anunnaki.enlil._context import ContextResult, EnlilError, evaluate_context, fixed_batch
from anunnaki.enlil._search import SEARCHES, Search
from anunnaki.lec import Detector
from anunnaki.phenomena import CameraEncoding, reuse_fog_noise

__all__ = [
    "Job",
    "SearchOutcome",
    "evaluate_task",
    "occupied_cells",
    "run_search",
    "summarise",
]


@dataclass(frozen=True)
class Job:
    """What every evaluation of one search shares (picklable: it travels to the workers).

    Attributes:
        model: A model file or a registry (``REG.yaml``; read with
            :func:`anunnaki.lec.resolve_model`), or a detector.
        data: A dataset folder or a loaded split.
        phenomenon: Phenomenon or composition name.
        split: The split of the fixed batch.
        batch_images: Images in the fixed batch.
        seed: Seed of the batch choice and of the phenomenon (the same for every context).
        thresholds: Category thresholds.
        model_id: With a registry: which of its models (default: its default model).
        shared_classes: Measure on the classes the model and the data share
            (:func:`anunnaki.lec.shared_classes`) instead of refusing other class lists.
        encoding: The camera's encoding (``jpeg:90``; ``""`` none) every frame goes
            through after the phenomenon, the clean batch's too
            (:class:`anunnaki.phenomena.CameraEncoding`).

    """

    model: str | Detector
    data: str | Dataset
    phenomenon: str
    split: str = "val"
    batch_images: int = 32
    seed: int = 0
    thresholds: tuple[float, float] = (0.05, 0.10)
    model_id: str | None = None
    shared_classes: bool = False
    encoding: str = ""

    def __post_init__(self) -> None:
        # a bad spec fails here, in the caller, not in every worker; kept in its one spelling
        parsed = CameraEncoding.parse(self.encoding)
        object.__setattr__(self, "encoding", "" if parsed is None else str(parsed))

    def key(self) -> str:
        """Cache key of the loaded model and batch in a worker."""
        parts: list[str | int | bool | None] = [
            self.model if isinstance(self.model, str) else id(self.model)
        ]
        parts += [self.data if isinstance(self.data, str) else id(self.data)]
        parts += [self.split, self.batch_images, self.seed, self.model_id, self.shared_classes]
        parts += [self.encoding]  # the clean F1 is measured through it
        return json.dumps(parts, default=str)


#: Per job in this process: the model, the fixed batch, its clean F1 and the fog noise
#: layers of the batch's seeds (the same for every context, see ``reuse_fog_noise``).
_LOADED: dict[str, tuple[Detector, Dataset, float, dict[Any, Any]]] = {}


def _loaded(job: Job) -> tuple[Detector, Dataset, float, dict[Any, Any]]:
    key = job.key()
    if key not in _LOADED:
        from anunnaki.lec import resolve_model, shared_classes

        if isinstance(job.model, str):
            det = resolve_model(job.model, job.model_id).load()
        else:
            det = job.model
        batch = fixed_batch(job.data, job.split, job.batch_images, job.seed)
        if job.shared_classes:
            det, batch = shared_classes(det, batch)
        clean = lec.evaluate_detector(det, batch, encoding=CameraEncoding.parse(job.encoding))
        _LOADED[key] = (det, batch, float(clean.f1), {})
    return _LOADED[key]


def clean_f1(job: Job) -> float:
    """The model's F1 on the clean fixed batch."""
    return _loaded(job)[2]


def evaluate_task(task: tuple[Job, list[float]]) -> ContextResult:
    """Evaluate one context (runs in a pool process or on a Dask worker)."""
    job, vector = task
    det, batch, clean, noise = _loaded(job)
    with reuse_fog_noise(noise):
        return evaluate_context(
            det,
            batch,
            job.phenomenon,
            vector,
            clean_f1=clean,
            thresholds=job.thresholds,
            seed=job.seed,
            encoding=CameraEncoding.parse(job.encoding),
        )


def _one_thread() -> None:
    """A pool process computes with one thread (the pool has a process per core)."""
    try:
        import torch
    except ImportError:  # pragma: no cover - a detector without torch
        return
    torch.set_num_threads(1)


MapFn = Callable[[list[Any]], list[Any]]


@contextmanager
def executor_map(
    workers: int = 1,
    dask: Any = None,
    *,
    fn: Callable[[Any], Any] = evaluate_task,
    on_result: Callable[[int, Any], None] | None = None,
) -> Iterator[MapFn]:
    """Yield ``map(tasks) -> results`` (in task order) for a local pool or a Dask cluster.

    Args:
        workers: Local processes (1: in this process).
        dask: A scheduler address (``tcp://HOST:8786``) or a ``distributed.Client``.
        fn: What each task runs (default: one context's evaluation, the search's task);
            module-level, for the processes and the cluster to run it.
        on_result: ``on_result(index, result)`` as each task's result comes back (on a
            cluster in the order they finish), e.g. for a progress line.

    """
    if dask is not None:
        try:
            from distributed import Client, as_completed
        except ImportError as exc:  # pragma: no cover - depends on the environment
            from anunnaki.errors import MissingExtraError

            raise MissingExtraError("distributed", "enlil") from exc
        client: Any = dask if isinstance(dask, Client) else Client(dask)  # type: ignore[no-untyped-call]

        def remote(tasks: list[Any]) -> list[Any]:
            futures = client.map(fn, tasks, pure=False)
            if on_result is not None:
                index = {f.key: i for i, f in enumerate(futures)}
                for future in as_completed(futures):  # type: ignore[no-untyped-call]
                    on_result(index[future.key], future.result())
            return list(client.gather(futures))

        try:
            yield remote
        finally:
            if client is not dask:
                client.close()
        return

    def report(results: Iterator[Any]) -> list[Any]:
        out = []
        for i, result in enumerate(results):
            if on_result is not None:
                on_result(i, result)
            out.append(result)
        return out

    if workers <= 1:
        yield lambda tasks: report(fn(t) for t in tasks)
        return
    # spawn, not fork: the parent has usually run torch already (the clean F1), and a child
    # forked from a process whose OpenMP pool is up hangs on its first parallel region.
    pool: Executor = ProcessPoolExecutor(
        max_workers=workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_one_thread,
    )
    try:
        yield lambda tasks: report(pool.map(fn, tasks))
    finally:
        pool.shutdown(cancel_futures=True)


@dataclass
class SearchOutcome:
    """What :func:`run_search` did."""

    archive: Archive
    resumed: int
    evaluated: int
    summary: dict[str, Any] = field(default_factory=dict)


def _replay(search: Search, stored: Archive, budget: int) -> tuple[int, int, list[Any]]:
    """Feed the stored rounds back; return (rounds done, evaluations done, pending round)."""
    done, it = 0, 0
    while done < len(stored):
        proposals = search.ask()
        rows = np.flatnonzero(stored.iterations == it)
        got = stored.params[rows]
        if not np.allclose(got, proposals[: len(rows)], atol=1e-9):
            raise EnlilError(
                f"round {it} of the archive does not match what the search proposes again; "
                "the archive was written by another version or settings — use a new --out"
            )
        done += len(rows)
        results = [
            ContextResult(
                stored.params[r],
                float(stored.f1[r]),
                float(stored.drop[r]),
                int(stored.categories[r]),
            )
            for r in rows
        ]
        if len(rows) < len(proposals):  # the round was cut by the budget or a kill
            return it, done, [proposals, results]
        search.tell(proposals, results)
        it += 1
    return it, done, []


def run_search(
    job: Job,
    out: str | Path,
    *,
    search: str = "enlil",
    budget: int,
    seed: int = 0,
    batch: int = 16,
    workers: int = 1,
    dask: Any = None,
    meta_extra: dict[str, Any] | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> SearchOutcome:
    """Run (or resume) a search of *budget* evaluations, writing each round to *out*.

    Each round is written as one archive part once all its evaluations are back, so a kill
    loses at most the round in flight, which is proposed again (the same contexts) on
    resume: no evaluation is lost from or repeated in the archive.
    """
    det_id, sha = _identity(job)
    meta = ArchiveMeta(
        model_id=det_id,
        sha256=sha,
        dataset=str(job.data) if isinstance(job.data, str) else "<in memory>",
        split=job.split,
        phenomenon=job.phenomenon,
        param_names=_param_names(job.phenomenon),
        seed=seed,
        thresholds=job.thresholds,
        budget=budget,
        search=search,
        batch_images=job.batch_images,
        clean_f1=clean_f1(job),
        extra=meta_extra or {},
        encoding=job.encoding,
    )
    writer = ArchiveWriter(out, meta)
    strategy = SEARCHES.create(
        search, dim=len(meta.param_names), seed=seed, batch=batch, thresholds=job.thresholds
    )
    it, done, pending = _replay(strategy, writer.existing, budget)
    resumed = done
    with executor_map(workers, dask) as run:
        while done < budget:
            if pending:
                proposals, results = pending
                pending = []
            else:
                proposals, results = strategy.ask(), []
            todo = proposals[len(results) : len(results) + budget - done]
            new = run([(job, row.tolist()) for row in todo])
            writer.append(done, it, new)
            done += len(new)
            results = results + new
            if progress is not None:
                progress(done, budget)
            if len(results) == len(proposals):
                strategy.tell(proposals, results)
                it += 1
    archive = read_archive(out)
    return SearchOutcome(archive, resumed, done - resumed, summarise(archive))


def _identity(job: Job) -> tuple[str, str]:
    if isinstance(job.model, str):
        from anunnaki.lec import resolve_model

        model = resolve_model(job.model, job.model_id)
        return model.model_id, model.sha256
    return str(getattr(job.model, "model_id", type(job.model).__name__)), ""


def _param_names(phenomenon: str) -> tuple[str, ...]:
    from anunnaki.phenomena import PHENOMENA

    return tuple(PHENOMENA.create(phenomenon).param_names)


def _cvt_centroids(dim: int, k: int = 256) -> npt.NDArray[np.float64]:
    """Fixed centroids of a CVT of ``[0, 1]^dim`` (k-means of 20,000 uniform points, seed 0)."""
    from scipy.cluster.vq import kmeans2

    points = np.random.default_rng(0).random((20_000, dim))
    centroids, _ = kmeans2(points, k, seed=0, minit="++")
    return np.asarray(centroids, np.float64)


def cell_ids(params: npt.NDArray[np.float64], cells_per_axis: int = 10) -> npt.NDArray[np.int64]:
    """The fixed grid's cell of each context (a 256-cell CVT above 3 parameters)."""
    _n, dim = params.shape
    if dim > 3:
        centroids = _cvt_centroids(dim)
        dist = ((params[:, None, :] - centroids[None, :, :]) ** 2).sum(-1)
        return np.asarray(dist.argmin(1), np.int64)
    idx = np.minimum((params * cells_per_axis).astype(np.int64), cells_per_axis - 1)
    return np.asarray(np.ravel_multi_index(idx.T, (cells_per_axis,) * dim), np.int64)


def occupied_cells(archive: Archive, upto: int | None = None) -> dict[int, int]:
    """Distinct occupied cells per category among the first *upto* evaluations."""
    n = len(archive) if upto is None else min(upto, len(archive))
    cells = cell_ids(archive.params[:n]) if n else np.zeros(0, np.int64)
    cats = archive.categories[:n]
    return {c: len(np.unique(cells[cats == c])) for c in (0, 1, 2)}


def summarise(archive: Archive, *, fraction_samples: Sequence[int] = ()) -> dict[str, Any]:
    """Evaluations, occupied cells per category and each category's share of the evaluations.

    The share of evaluations estimates the fraction of the space in each category only for
    the uniform strategies (``random``, ``sobol``); for ``enlil`` it says where the search
    spent its budget.
    """
    n = len(archive)
    counts = {c: int((archive.categories == c).sum()) for c in (0, 1, 2)}
    return {
        "search": archive.meta.search,
        "phenomenon": archive.phenomenon,
        "evaluations": n,
        "cells": occupied_cells(archive),
        "counts": counts,
        "fraction": {c: (counts[c] / n if n else 0.0) for c in (0, 1, 2)},
        "clean_f1": archive.meta.clean_f1,
    }
