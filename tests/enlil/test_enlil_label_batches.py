"""How far held-out categories reproduce per label batch size (benchmarks/oracle.py, issue 13)."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from enlil_helpers import ColourDetector, tiny_data

pytest.importorskip("torch")

from anunnaki.enlil import ContextSpec, HeldOut, evaluate_context, held_out_frames
from anunnaki.lec import evaluate_detector

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bench() -> Any:
    spec = importlib.util.spec_from_file_location("oracle_bench", ROOT / "benchmarks" / "oracle.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def held() -> HeldOut:
    return held_out_frames(
        ColourDetector(), tiny_data(12, seed=5), "fog", ContextSpec("random", 5),
        per_context=1, batch_images=6, seed=1,
    )  # fmt: skip


def test_each_size_measures_the_same_contexts_on_two_disjoint_batches(
    bench: Any, held: HeldOut
) -> None:
    test = tiny_data(20, seed=9)
    out = bench.label_reproducibility(ColourDetector(), test, held, [4, 10, 11], seed=3)
    assert list(out) == ["4", "10"]  # 11 + 11 images do not fit in 20: skipped
    # the figures are those of the two halves of the seed's permutation, measured directly
    order = np.random.default_rng([3, 3]).permutation(len(test))
    drops, cats = [], []
    for k in range(2):
        batch = test.subset(np.sort(order[k * 10 : (k + 1) * 10])).in_memory()
        clean = float(evaluate_detector(ColourDetector(), batch).f1)
        rows = [
            evaluate_context(ColourDetector(), batch, "fog", r.params, clean_f1=clean, seed=3)
            for r in held.contexts
        ]
        drops.append(np.asarray([r.drop for r in rows]))
        cats.append([r.category for r in rows])
    ten = out["10"]
    assert ten["drop_sd"] == pytest.approx(float(np.sqrt(np.mean((drops[0] - drops[1]) ** 2) / 2)))
    assert ten["agreement"] == pytest.approx(np.mean(np.asarray(cats[0]) == np.asarray(cats[1])))
    assert sum(map(sum, ten["confusion"])) == len(held.contexts)
    assert 0.0 <= ten["macro_f1"] <= 1.0
