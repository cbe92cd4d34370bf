"""The adaptive sources: the archive as a distribution, worst-of-k, and sources by name."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from anunnaki.enki import (
    CONTEXT_SOURCES,
    ArchiveContexts,
    ArchiveMix,
    ContextSource,
    CorruptionMix,
    EnkiError,
    MixedContexts,
    SourceSpec,
    UniformContexts,
    WorstOfK,
    make_source,
)

ELITES = [[0.5, 0.5, 0.5], [0.2, 0.7, 0.4]]


def _image() -> Any:
    return np.full((8, 8, 3), 128, np.uint8)


class Counter(ContextSource):
    """Fills the frame with a running count: each rendered candidate is told apart."""

    kind = "counter"

    def __init__(self) -> None:
        super().__init__(clean=0.0)
        self.n = 0

    def perturb(self, image: Any, rng: np.random.Generator) -> Any:
        self.n += 1
        return np.full_like(image, self.n % 256)


def test_archive_mix_draws_its_share_from_the_elites_and_the_rest_uniformly() -> None:
    mix = ArchiveMix("hsl", ELITES, share=0.3, jitter=0.0, clean=0.0)
    rng = np.random.default_rng(0)
    draws = [mix.draw(rng) for _ in range(4000)]
    from_elites = [u for u, e in draws if e]
    uniform = [u for u, e in draws if not e]
    assert len(from_elites) / len(draws) == pytest.approx(0.3, abs=0.03)
    # without jitter an elite draw is an elite, exactly; a uniform one never is
    elites = np.asarray(ELITES)
    assert all(np.any(np.all(u == elites, axis=1)) for u in from_elites)
    assert not any(np.any(np.all(u == elites, axis=1)) for u in uniform)
    grid = np.asarray(uniform)
    assert grid.min() >= 0 and grid.max() <= 1
    assert grid.mean(axis=0) == pytest.approx([0.5, 0.5, 0.5], abs=0.03)  # spread over [0,1]^d
    half = ArchiveMix("hsl", ELITES)  # the default: half and half
    assert half.share == 0.5 and half.jitter == 0.1


def test_archive_mix_jitters_the_elites_and_clips_to_the_unit_box() -> None:
    mix = ArchiveMix("hsl", [[0.5, 0.5, 0.99]], share=1.0, jitter=0.05, clean=0.0)
    rng = np.random.default_rng(1)
    units = np.asarray([mix.draw(rng)[0] for _ in range(3000)])
    assert units[:, 0].std() == pytest.approx(0.05, rel=0.1)  # the noise's spread
    assert units[:, 0].mean() == pytest.approx(0.5, abs=0.01)
    assert units[:, 2].max() <= 1.0 and (units[:, 2] == 1.0).mean() > 0.3  # clipped at 1


def test_archive_mix_never_draws_in_an_excluded_box() -> None:
    box = [[0.0, 1.0], [0.0, 1.0], [0.4, 0.6]]
    mix = ArchiveMix("hsl", ELITES, share=0.5, jitter=0.1, clean=0.0, exclude=box)
    rng = np.random.default_rng(2)
    units = np.asarray([mix.draw(rng)[0] for _ in range(2000)])
    assert not np.any((units[:, 2] >= 0.4) & (units[:, 2] <= 0.6))
    assert mix.describe()["excluded_box"] == box
    full = ArchiveMix("hsl", ELITES, exclude=[[0, 1]] * 3)
    with pytest.raises(EnkiError, match="excluded box"):
        full.draw(rng)
    with pytest.raises(EnkiError, match=r"\[d, 2\]"):
        ArchiveMix("hsl", ELITES, exclude=[[0, 1]])
    with pytest.raises(EnkiError, match="share"):
        ArchiveMix("hsl", ELITES, share=1.5)


def test_worst_of_k_offers_k_candidates_of_the_inner_source_or_the_clean_frame() -> None:
    from anunnaki.lec import CandidatePerturb

    inner = Counter()
    worst = WorstOfK(inner, k=3, clean=0.25)
    assert isinstance(worst, CandidatePerturb) and worst.select == "hardest"
    rng = np.random.default_rng(3)
    offered = [worst.candidates(_image(), rng) for _ in range(2000)]
    clean = [c for c in offered if len(c) == 1]
    assert len(clean) / len(offered) == pytest.approx(0.25, abs=0.03)
    assert all(np.array_equal(c[0], _image()) for c in clean)
    assert {len(c) for c in offered} == {1, 3}
    assert inner.n == 3 * (len(offered) - len(clean))  # k renders per perturbed frame
    first = next(c for c in offered if len(c) == 3)
    assert len({int(x[0, 0, 0]) for x in first}) == 3  # k different frames
    # without a network: k rendered, one kept
    before = inner.n
    assert int(worst.perturb(_image(), rng)[0, 0, 0]) in {(before + i) % 256 for i in (1, 2, 3)}
    assert inner.n == before + 3
    d = WorstOfK(UniformContexts("fog"), k=2, select="random").describe()
    assert d == {"kind": "worst_of_k", "clean": 0.3, "k": 2, "select": "random",
                 "inner": {"kind": "uniform", "clean": 0.3, "phenomenon": "fog"}}  # fmt: skip
    with pytest.raises(EnkiError, match="k >= 2"):
        WorstOfK(inner, k=1)
    with pytest.raises(EnkiError, match="select"):
        WorstOfK(inner, select="softest")  # type: ignore[arg-type]


def test_sources_by_name() -> None:
    assert {"archive", "archive_mix", "uniform", "corruption_mix"} <= set(CONTEXT_SOURCES.names())
    spec = SourceSpec("hsl", ELITES, clean=0.2, share=0.4, jitter=0.05)
    assert isinstance(make_source("archive", spec), ArchiveContexts)
    mix = make_source("archive_mix", spec)
    assert isinstance(mix, ArchiveMix) and (mix.share, mix.jitter, mix.clean) == (0.4, 0.05, 0.2)
    assert isinstance(make_source("uniform", spec), UniformContexts)
    assert isinstance(make_source("corruption_mix", spec), CorruptionMix)
    worst = make_source("archive_mix", spec, k=4, select="random")
    assert isinstance(worst, WorstOfK) and worst.k == 4 and worst.select == "random"
    assert worst.clean == 0.2 and isinstance(worst.inner, ArchiveMix)
    with pytest.raises(EnkiError, match="valid names: archive, archive_mix, corruption_mix"):
        make_source("archive-mix", spec)
    with pytest.raises(EnkiError, match="contexts selected"):
        make_source("archive_mix", SourceSpec("hsl"))
    with pytest.raises(EnkiError, match="at least 1"):
        make_source("uniform", spec, k=0)


def test_a_fine_tune_with_worst_of_k_consistency_and_ema_reports_its_forward_passes(
    rover_data: Path, models: Path, tmp_path: Path
) -> None:
    pytest.importorskip("torch")
    from anunnaki.datasets import load_split
    from anunnaki.enki import Budget, finetune

    train, val = load_split(rover_data, "train"), load_split(rover_data, "val")
    model = models / "rover-default.safetensors"
    source = make_source("archive_mix", SourceSpec("hsl", ELITES, clean=0.25), k=2)
    budget = Budget(epochs=1, batch_size=4, threads=1, ema=0.9)
    result = finetune(model, train, val, source, budget=budget, seed=1, consistency=0.5,
                      checkpoints=tmp_path / "c")  # fmt: skip
    t = result.detector.training
    assert t["steps"] == 2 and t["train_forwards"] == 8
    assert t["select_forwards"] == t["candidates"] > 0 and t["candidates"] % 2 == 0
    assert 0 < t["consistency_forwards"] <= 8 and t["consistency"] == 0.5 and t["ema"] == 0.9
    assert t["source"]["kind"] == "worst_of_k" and t["budget"]["ema"] == 0.9
    assert result.counts["select_forwards"] == t["select_forwards"]
    with pytest.raises(EnkiError, match="consistency"):  # the folder is of this fine-tune
        finetune(model, train, val, source, budget=budget, seed=1, consistency=0.0,
                 checkpoints=tmp_path / "c")  # fmt: skip


def test_every_source_returns_the_occlusion_mask_of_its_very_draw() -> None:
    """A raindrop hides what is behind it: the frame comes with its mask (ignore boxes)."""
    from anunnaki.enlil import to_phenomenon_vector
    from anunnaki.lec import Augmenter
    from anunnaki.phenomena import PHENOMENA

    image = np.full((32, 32, 3), 128, np.uint8)
    drop = PHENOMENA.create("raindrop")
    # the mask is the phenomenon's own for the context and seed the source drew
    rng, again = np.random.default_rng(7), np.random.default_rng(7)
    for _ in range(5):
        out, mask = UniformContexts("raindrop", clean=0.0).perturb(image, rng)
        params = drop.from_vector(to_phenomenon_vector(drop, again.random(4)))
        seed = int(again.integers(2**31 - 1))
        assert np.array_equal(out, drop.apply(image, params, seed=seed))
        assert np.array_equal(mask, drop.occlusion(image.shape, params, seed))
    assert mask.shape == (32, 32) and mask.dtype == np.float32
    elites = [[0.5, 0.5, 0.9, 0.5]]
    for source in (ArchiveContexts("raindrop", elites), ArchiveMix("raindrop", elites),
                   MixedContexts([UniformContexts("raindrop")]),
                   WorstOfK(UniformContexts("raindrop"), k=2)):  # fmt: skip
        out, mask = source.perturb(image, np.random.default_rng(1))
        assert out.shape == image.shape and mask.shape == (32, 32) and mask.max() > 0
    # worst-of-k: every candidate with its own mask, the clean frame alone
    offered = [WorstOfK(UniformContexts("raindrop"), k=3, clean=0.5).candidates(image, rng)
               for _ in range(20)]  # fmt: skip
    assert {len(c) for c in offered} == {1, 3}
    for found in offered:
        if len(found) == 1:
            assert found[0] is image
        else:
            assert all(isinstance(c, tuple) and c[1].shape == (32, 32) for c in found)
    # the corruption mix: the Augmenter's occluded path, the same draws
    mixed = CorruptionMix(["raindrop"], clean=0.0).perturb(image, np.random.default_rng(3))
    aug = Augmenter(["raindrop"], probability=1.0).occluded(image, np.random.default_rng(3))
    assert np.array_equal(mixed[0], aug[0]) and np.array_equal(mixed[1], aug[1])
    # a phenomenon without a mask: the frame alone, as before
    assert isinstance(UniformContexts("hsl").perturb(image, rng), np.ndarray)
    assert isinstance(CorruptionMix(["fog"]).perturb(image, rng), np.ndarray)
