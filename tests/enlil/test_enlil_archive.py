"""The Parquet archive: round trip, resume checks, damage and foreign files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from anunnaki.enlil import ArchiveMeta, ArchiveWriter, ContextResult, EnlilError, read_archive

pytest.importorskip("pyarrow")


def meta(**kw: object) -> ArchiveMeta:
    base: dict[str, object] = dict(
        model_id="m",
        sha256="ab" * 32,
        dataset="data/rover",
        split="val",
        phenomenon="fog",
        param_names=("density", "intensity"),
        seed=1,
        thresholds=(0.05, 0.1),
        budget=10,
        search="random",
        batch_images=8,
        clean_f1=0.9,
    )
    base.update(kw)
    return ArchiveMeta(**base)  # type: ignore[arg-type]


def results(n: int, start: float = 0.0) -> list[ContextResult]:
    return [
        ContextResult(np.array([start + i / 10, 0.5]), 0.9 - i / 20, i / 20, min(i, 2))
        for i in range(n)
    ]


def test_round_trip_and_resume(tmp_path: Path) -> None:
    out = tmp_path / "arch"
    w = ArchiveWriter(out, meta())
    assert w.done == 0
    w.append(0, 0, results(3))
    w.append(3, 1, results(2, 0.3))
    a = read_archive(out)
    assert len(a) == 5 and a.phenomenon == "fog" and a.param_names == ("density", "intensity")
    assert a.params.shape == (5, 2) and a.categories.tolist() == [0, 1, 2, 0, 1]
    assert a.iterations.tolist() == [0, 0, 0, 1, 1]
    assert a.meta.sha256 == "ab" * 32 and a.meta["budget"] == 10
    assert ArchiveWriter(out, meta(budget=20)).done == 5  # a larger budget resumes
    with pytest.raises(EnlilError, match="seed=1"):
        ArchiveWriter(out, meta(seed=2))


def test_damage_is_reported_with_the_file(tmp_path: Path) -> None:
    with pytest.raises(EnlilError, match="no archive here"):
        read_archive(tmp_path / "none")
    (tmp_path / "part-000000.parquet").write_bytes(b"not parquet")
    with pytest.raises(EnlilError, match=r"part-000000\.parquet"):
        read_archive(tmp_path)


def test_a_killed_write_leaves_no_part(tmp_path: Path) -> None:
    w = ArchiveWriter(tmp_path, meta())
    w.append(0, 0, results(2))
    (tmp_path / ".tmp-000001.parquet").write_bytes(b"half")
    w2 = ArchiveWriter(tmp_path, meta())
    assert w2.done == 2 and not list(tmp_path.glob(".tmp-*"))
