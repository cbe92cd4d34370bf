"""Enlil's archive on disk: every evaluated context, as Parquet, with what it is about.

An archive is a folder of Parquet parts (``part-000000.parquet``, ...), one per batch of
evaluations, each written to a temporary name and renamed into place, so a search killed at
any moment (Ctrl-C, ``kill -9``) leaves only whole parts behind and resumes from them. Every
part carries the same metadata (JSON under the schema key ``anunnaki.enlil``). Columns:

========== ================ ==========================================================
column     type             meaning
========== ================ ==========================================================
eval       int64            evaluation index, 0, 1, 2, ... in the order the search asked
iteration  int32            the search step (ask/tell round) that proposed it
params     list<double>     the context, normalised to ``[0, 1]^d`` (``param_names`` order)
f1         double           the model's F1 on the fixed batch under the context
drop       double           relative F1 drop against the clean batch
category   int8             behavior category (0, 1, 2)
========== ================ ==========================================================

:func:`read_archive` also reads a single Parquet file with these columns (e.g. a folder
compacted with ``pyarrow.parquet.write_table``).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from anunnaki.enlil._context import ContextResult, EnlilError
from anunnaki.errors import MissingExtraError

__all__ = ["Archive", "ArchiveMeta", "ArchiveWriter", "read_archive"]

META_KEY = b"anunnaki.enlil"
FORMAT = "anunnaki-enlil-archive/1"
#: Fields that must agree for a search to resume into an existing archive.
RESUME_KEYS = (
    "model_id",
    "sha256",
    "dataset",
    "split",
    "phenomenon",
    "param_names",
    "seed",
    "thresholds",
    "search",
    "batch_images",
    "encoding",
)


def _pyarrow() -> Any:
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise MissingExtraError("pyarrow", "enlil") from exc
    return pa, pq


@dataclass(frozen=True)
class ArchiveMeta:
    """What an archive is about (stored with every part).

    Attributes:
        model_id: The assessed model's id.
        sha256: The model's weights sha256 (empty when unknown).
        dataset: The dataset folder (as given).
        split: The split of the fixed batch (``val`` for searches).
        phenomenon: Phenomenon or composition name (``rain+brightness``).
        param_names: Parameter names in vector order.
        seed: The search's seed (contexts, batch and phenomenon seeds derive from it).
        thresholds: Relative drops for categories 1 and 2.
        budget: Evaluations asked for (the last run's; a resumed run may raise it).
        search: The strategy (``enlil``, ``random``, ``sobol``).
        batch_images: Images in the fixed batch.
        clean_f1: The model's F1 on the clean batch.
        extra: Anything else a strategy records (JSON-safe).
        encoding: The camera encoding every frame went through after the phenomenon, the
            clean batch's too (``jpeg:90``; ``""``: none, the frames as stored;
            :class:`anunnaki.phenomena.CameraEncoding`).

    """

    model_id: str
    sha256: str
    dataset: str
    split: str
    phenomenon: str
    param_names: tuple[str, ...]
    seed: int
    thresholds: tuple[float, float]
    budget: int
    search: str
    batch_images: int
    clean_f1: float
    extra: Mapping[str, Any] = field(default_factory=dict)
    encoding: str = ""

    def as_dict(self) -> dict[str, Any]:
        """JSON-safe dict (tuples become lists)."""
        data = asdict(self)
        data["param_names"] = list(self.param_names)
        data["thresholds"] = list(self.thresholds)
        data["extra"] = dict(self.extra)
        return data

    def __getitem__(self, key: str) -> Any:
        """``meta["model_id"]`` works as well as ``meta.model_id``."""
        return self.as_dict()[key]

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, source: str = "<archive>") -> ArchiveMeta:
        """Build from :meth:`as_dict` output.

        Raises:
            EnlilError: A field is missing or has the wrong type; names the file.

        """
        try:
            return cls(
                model_id=str(data["model_id"]),
                sha256=str(data["sha256"]),
                dataset=str(data["dataset"]),
                split=str(data["split"]),
                phenomenon=str(data["phenomenon"]),
                param_names=tuple(str(n) for n in data["param_names"]),
                seed=int(data["seed"]),
                thresholds=(float(data["thresholds"][0]), float(data["thresholds"][1])),
                budget=int(data["budget"]),
                search=str(data["search"]),
                batch_images=int(data["batch_images"]),
                clean_f1=float(data["clean_f1"]),
                extra=dict(data.get("extra") or {}),
                encoding=str(data.get("encoding") or ""),
            )
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise EnlilError(
                f"{source}: archive metadata is incomplete or invalid ({exc!r}); "
                "it was not written by anunnaki assess — rerun the search"
            ) from exc


@dataclass(frozen=True)
class Archive:
    """An archive read back (:func:`read_archive`), rows sorted by evaluation index.

    Attributes:
        meta: What the archive is about.
        evals: ``[N]`` evaluation indices.
        iterations: ``[N]`` search step of each row.
        params: ``[N, d]`` contexts normalised to ``[0, 1]``.
        f1: ``[N]`` F1 under each context.
        drop: ``[N]`` relative F1 drop.
        categories: ``[N]`` behavior categories.

    """

    meta: ArchiveMeta
    evals: npt.NDArray[np.int64]
    iterations: npt.NDArray[np.int32]
    params: npt.NDArray[np.float64]
    f1: npt.NDArray[np.float64]
    drop: npt.NDArray[np.float64]
    categories: npt.NDArray[np.int64]

    @property
    def phenomenon(self) -> str:
        """The phenomenon (or composition) name."""
        return self.meta.phenomenon

    @property
    def param_names(self) -> tuple[str, ...]:
        """Parameter names, in the column order of :attr:`params`."""
        return self.meta.param_names

    def __len__(self) -> int:
        return int(self.evals.shape[0])


def _parts(path: Path) -> list[Path]:
    return sorted(p for p in path.glob("part-*.parquet") if p.is_file())


def _read_table(file: Path) -> tuple[Any, ArchiveMeta]:
    _, pq = _pyarrow()
    try:
        table = pq.read_table(file)
    except Exception as exc:  # pyarrow raises several kinds for a damaged file
        raise EnlilError(
            f"{file}: not a readable Parquet file ({exc}); delete it and resume"
        ) from exc
    raw = (table.schema.metadata or {}).get(META_KEY)
    if raw is None:
        raise EnlilError(
            f"{file}: Parquet file without Enlil metadata (key {META_KEY.decode()}); "
            "read_archive reads archives written by anunnaki assess"
        )
    try:
        data = json.loads(raw)
    except ValueError as exc:
        raise EnlilError(f"{file}: archive metadata is not JSON ({exc})") from exc
    if data.get("format") != FORMAT:
        raise EnlilError(f"{file}: archive format {data.get('format')!r}, expected {FORMAT!r}")
    return table, ArchiveMeta.from_dict(data["meta"], source=str(file))


def _empty(meta: ArchiveMeta) -> Archive:
    d = len(meta.param_names)
    return Archive(
        meta=meta,
        evals=np.zeros(0, np.int64),
        iterations=np.zeros(0, np.int32),
        params=np.zeros((0, d), np.float64),
        f1=np.zeros(0, np.float64),
        drop=np.zeros(0, np.float64),
        categories=np.zeros(0, np.int64),
    )


def read_archive(path: str | Path) -> Archive:
    """Read an archive folder (or one Parquet file) written by :class:`ArchiveWriter`.

    Raises:
        EnlilError: Nothing there, a part is damaged, parts disagree on the metadata, or an
            evaluation index appears twice.

    """
    pa, _ = _pyarrow()
    root = Path(path)
    files = [root] if root.is_file() else _parts(root) if root.is_dir() else []
    if not files:
        raise EnlilError(
            f"{root}: no archive here (expected a folder of part-*.parquet files or one "
            "Parquet file); run anunnaki assess ... --out " + str(root)
        )
    tables, meta = [], None
    for file in files:
        table, part_meta = _read_table(file)
        if meta is None:
            meta = part_meta
        elif part_meta.param_names != meta.param_names or part_meta.phenomenon != meta.phenomenon:
            raise EnlilError(f"{file}: part is about {part_meta.phenomenon}, not {meta.phenomenon}")
        else:
            meta = part_meta if part_meta.budget > meta.budget else meta
        tables.append(table.replace_schema_metadata(None))
    assert meta is not None
    table = pa.concat_tables(tables)
    if table.num_rows == 0:
        return _empty(meta)
    evals = np.asarray(table.column("eval").to_numpy(), dtype=np.int64)
    order = np.argsort(evals, kind="stable")
    evals = evals[order]
    if np.any(np.diff(evals) == 0):
        dup = int(evals[np.flatnonzero(np.diff(evals) == 0)[0]])
        raise EnlilError(f"{root}: evaluation {dup} is stored twice; the archive is inconsistent")
    params = np.asarray(table.column("params").to_pylist(), dtype=np.float64)
    params = params.reshape(-1, len(meta.param_names))[order]
    return Archive(
        meta=meta,
        evals=evals,
        iterations=np.asarray(table.column("iteration").to_numpy(), dtype=np.int32)[order],
        params=params,
        f1=np.asarray(table.column("f1").to_numpy(), dtype=np.float64)[order],
        drop=np.asarray(table.column("drop").to_numpy(), dtype=np.float64)[order],
        categories=np.asarray(table.column("category").to_numpy(), dtype=np.int64)[order],
    )


class ArchiveWriter:
    """Appends evaluations to an archive folder, one atomically written part per call.

    Opening a folder that already holds parts resumes it: the metadata must agree on
    :data:`RESUME_KEYS` (a different model, seed or phenomenon is an error naming the field),
    and :attr:`done` is the number of evaluations already stored.

    Raises:
        EnlilError: The folder holds an archive about something else.

    """

    def __init__(self, path: str | Path, meta: ArchiveMeta) -> None:
        self.path = Path(path)
        self.meta = meta
        if self.path.exists() and not self.path.is_dir():
            raise EnlilError(f"{self.path}: is a file; give a folder for the archive")
        self.path.mkdir(parents=True, exist_ok=True)
        for stale in self.path.glob(".tmp-*"):
            stale.unlink()  # a part killed mid-write never became visible
        parts = _parts(self.path)
        self._next_part = len(parts)
        self.existing = read_archive(self.path) if parts else _empty(meta)
        if parts:
            self._check_resume(self.existing.meta)

    @property
    def done(self) -> int:
        """Evaluations already stored when the writer was opened."""
        return len(self.existing)

    def _check_resume(self, old: ArchiveMeta) -> None:
        mine, theirs = self.meta.as_dict(), old.as_dict()
        for key in RESUME_KEYS:
            if mine[key] != theirs[key]:
                raise EnlilError(
                    f"{self.path}: cannot resume, the archive has {key}={theirs[key]!r} but this "
                    f"run has {key}={mine[key]!r}; use another --out folder or the same settings"
                )
        if len(self.existing) and not np.array_equal(
            self.existing.evals, np.arange(len(self.existing))
        ):
            raise EnlilError(
                f"{self.path}: evaluations are not numbered 0..N-1; the archive is damaged"
            )

    def append(self, first_eval: int, iteration: int, results: Sequence[ContextResult]) -> Path:
        """Write *results* as evaluations ``first_eval, first_eval + 1, ...``; return the part."""
        pa, pq = _pyarrow()
        n = len(results)
        d = len(self.meta.param_names)
        for r in results:
            if r.params.shape != (d,):
                raise EnlilError(
                    f"{self.path}: result with {r.params.shape} parameters, archive has {d}"
                )
        table = pa.table(
            {
                "eval": pa.array(np.arange(first_eval, first_eval + n), pa.int64()),
                "iteration": pa.array(np.full(n, iteration), pa.int32()),
                "params": pa.array([r.params.tolist() for r in results], pa.list_(pa.float64())),
                "f1": pa.array([r.f1 for r in results], pa.float64()),
                "drop": pa.array([r.drop for r in results], pa.float64()),
                "category": pa.array([r.category for r in results], pa.int8()),
            }
        )
        payload = json.dumps({"format": FORMAT, "meta": self.meta.as_dict()}).encode()
        table = table.replace_schema_metadata({META_KEY: payload})
        final = self.path / f"part-{self._next_part:06d}.parquet"
        tmp = self.path / f".tmp-{self._next_part:06d}.parquet"
        pq.write_table(table, tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, final)
        self._next_part += 1
        return final
