"""The search: strategies, determinism, resume without loss or repeat, the Dask path."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from enlil_helpers import ColourDetector, tiny_data

from anunnaki.enlil import read_archive
from anunnaki.enlil._run import Job, occupied_cells, run_search
from anunnaki.enlil._search import SEARCHES

pytest.importorskip("pyarrow")
pytest.importorskip("ribs")


@pytest.fixture(scope="module")
def job() -> Job:
    return Job(ColourDetector(), tiny_data(10), "brightness", batch_images=10, seed=0)


def test_the_strategies_are_registered_plugins() -> None:
    assert {"enlil", "random", "sobol"} <= set(SEARCHES.names())
    for name in ("enlil", "random", "sobol"):
        s = SEARCHES.create(name, dim=3, seed=4, batch=8)
        p = s.ask()
        assert p.shape[1] == 3 and np.all((p >= 0) & (p <= 1))


@pytest.mark.parametrize("search", ["enlil", "random", "sobol"])
def test_resume_equals_one_run(job: Job, tmp_path: Path, search: str) -> None:
    whole = run_search(job, tmp_path / "a", search=search, budget=45, seed=3, batch=10)
    assert len(whole.archive) == 45 and whole.archive.evals.tolist() == list(range(45))
    run_search(job, tmp_path / "b", search=search, budget=23, seed=3, batch=10)
    again = run_search(job, tmp_path / "b", search=search, budget=45, seed=3, batch=10)
    assert again.resumed == 23 and again.evaluated == 22
    assert np.array_equal(again.archive.params, whole.archive.params)
    assert np.array_equal(again.archive.categories, whole.archive.categories)
    done = run_search(job, tmp_path / "b", search=search, budget=45, seed=3, batch=10)
    assert done.evaluated == 0


def test_a_fog_search_draws_its_noise_layers_once(tmp_path: Path) -> None:
    from anunnaki.enlil._run import _LOADED, evaluate_task

    fog = Job(ColourDetector(), tiny_data(6), "fog", batch_images=6, seed=2)
    out = run_search(fog, tmp_path / "f", search="random", budget=12, seed=0, batch=6)
    kept = _LOADED[fog.key()][3]  # this process's state for the job (workers=1)
    # one field per (image seed, layer, size), kept for the whole search: at most 6 x 10
    assert 0 < len(kept) <= 60 and {k[0] for k in kept} <= set(range(2, 8))
    assert {k[2:] for k in kept} == {(64, 64)}
    fields = dict(kept)
    again = evaluate_task((fog, out.archive.params[0].tolist()))
    assert all(kept[k] is v for k, v in fields.items())  # reused, not drawn again
    assert again.f1 == float(out.archive.f1[0])


def test_summary_counts_cells_per_category(job: Job, tmp_path: Path) -> None:
    out = run_search(job, tmp_path / "r", search="random", budget=30, seed=1, batch=10)
    s = out.summary
    assert s["evaluations"] == 30 and sum(s["counts"].values()) == 30
    assert s["cells"] == occupied_cells(read_archive(tmp_path / "r"))
    assert s["counts"][2] > 0 and s["counts"][0] > 0  # dark gains break the colour detector


def test_dask_local_cluster_gives_the_local_pools_archive(job: Job, tmp_path: Path) -> None:
    distributed = pytest.importorskip("distributed")
    local = run_search(
        job, tmp_path / "pool", search="enlil", budget=20, seed=5, batch=10, workers=2
    )
    # ":0": the scheduler's web server on a free port. None does not turn it off (distributed
    # 2026.8 serves it on 8787 anyway, and warns — an error here — when 8787 is taken).
    cluster = distributed.LocalCluster(n_workers=1, processes=False, dashboard_address=":0")
    with cluster, distributed.Client(cluster) as client:
        remote = run_search(
            job, tmp_path / "dask", search="enlil", budget=20, seed=5, batch=10, dask=client
        )
    assert np.array_equal(local.archive.params, remote.archive.params)
    assert np.array_equal(local.archive.f1, remote.archive.f1)
