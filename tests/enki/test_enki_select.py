"""Enki's selection rule on synthetic archives: quotas by weight, spread, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from anunnaki.enki import (
    LEARNABLE_F1,
    EnkiError,
    Selection,
    SelectionRule,
    select_contexts,
    unlearnable_rows,
)
from anunnaki.enlil import Archive, ArchiveMeta


def _archive(params: np.ndarray, cats: np.ndarray, drops: np.ndarray | None = None) -> Archive:
    n, d = params.shape
    meta = ArchiveMeta(
        model_id="m", sha256="", dataset="d", split="val", phenomenon="hsl",
        param_names=("hue", "saturation", "lightness")[:d], seed=0, thresholds=(0.05, 0.1),
        budget=n, search="enlil", batch_images=4, clean_f1=0.9,
    )  # fmt: skip
    drops = drops if drops is not None else cats * 0.1
    return Archive(meta, np.arange(n), np.zeros(n, np.int32), params, 1 - drops, drops, cats)


def _grid_archive() -> Archive:
    """A 2-D grid: category 2 in the corner x, y < 0.3, 1 in a band around it, else 0."""
    g = np.linspace(0, 1, 20)
    params = np.array([(x, y) for x in g for y in g])
    r = np.maximum(params[:, 0], params[:, 1])
    cats = np.where(r < 0.3, 2, np.where(r < 0.45, 1, 0))
    return _archive(params, cats, drops=np.clip(1 - r, 0, 1))


def test_quotas_follow_the_weights_and_the_counts() -> None:
    archive = _grid_archive()
    counts = [int((archive.categories == c).sum()) for c in range(3)]
    sel = select_contexts(archive, SelectionRule(contexts=40, weights=(1, 3, 3)))
    got = sel.counts()
    assert sum(got) == 40
    total = counts[0] + 3 * counts[1] + 3 * counts[2]
    for c, w in enumerate((1, 3, 3)):
        assert abs(got[c] - 40 * w * counts[c] / total) <= 1
    # categories 1 and 2 over-represented against their share of the archive
    assert (got[1] + got[2]) / 40 > (counts[1] + counts[2]) / len(archive)


def test_the_picks_are_spread_and_the_first_is_the_largest_drop() -> None:
    archive = _grid_archive()
    sel = select_contexts(archive, SelectionRule(contexts=30))
    assert sel.rows[0] == int(np.argmax(archive.drop))
    assert len(set(sel.rows.tolist())) == 30
    # category-0 picks cover the space the hard ones leave: every quadrant of the square
    zero = sel.params[sel.categories == 0]
    for qx in (0, 1):
        for qy in (0, 1):
            if qx == qy == 0:
                continue
            inside = ((zero[:, 0] >= 0.5) == qx) & ((zero[:, 1] >= 0.5) == qy)
            assert inside.any()
    # far apart: the closest pair of category-2 picks is no closer than a grid step
    two = sel.params[sel.categories == 2]
    dist = np.sqrt(((two[:, None] - two[None]) ** 2).sum(-1)) + np.eye(len(two)) * 9
    assert dist.min() >= 1 / 19 - 1e-9


def test_deterministic_small_archives_whole_and_a_round_trip() -> None:
    archive = _grid_archive()
    a = select_contexts(archive, SelectionRule(contexts=25))
    b = select_contexts(archive, SelectionRule(contexts=25))
    assert np.array_equal(a.rows, b.rows)
    back = Selection.from_dict(a.as_dict())
    assert np.array_equal(back.params, a.params) and back.counts() == a.counts()
    small = _archive(np.array([[0.1], [0.5], [0.9]]), np.array([0, 2, 1]))
    assert sorted(select_contexts(small, SelectionRule(contexts=10)).rows.tolist()) == [0, 1, 2]
    # a category of weight 0 is never picked while others have room
    only_hard = select_contexts(archive, SelectionRule(contexts=20, weights=(0, 1, 1)))
    assert only_hard.counts()[0] == 0


def test_bad_rules_and_empty_archives() -> None:
    with pytest.raises(EnkiError, match="--contexts"):
        SelectionRule(contexts=0)
    with pytest.raises(EnkiError, match="--weights"):
        SelectionRule(weights=(0, 0, 0))
    with pytest.raises(EnkiError, match="holds no contexts"):
        select_contexts(_archive(np.zeros((0, 1)), np.zeros(0, np.int64)))
    zeros = _archive(np.array([[0.1], [0.5]]), np.array([0, 0]))
    with pytest.raises(EnkiError, match="weight 0"):
        select_contexts(zeros, SelectionRule(weights=(0, 1, 1)))


# -- the learnability cap ---------------------------------------------------------------------


def _with_black_frames() -> tuple[Archive, np.ndarray]:
    """The grid archive, its corner x, y < 0.1 a black frame: F1 0 for its model."""
    archive = _grid_archive()
    black = np.flatnonzero(np.maximum(archive.params[:, 0], archive.params[:, 1]) < 0.1)
    f1 = archive.f1.copy()
    f1[black] = 0.0
    drop = archive.drop.copy()
    drop[black] = 1.0  # the largest drops: the first pick without a cap
    archive = Archive(
        archive.meta, archive.evals, archive.iterations, archive.params, f1, drop,
        archive.categories,
    )  # fmt: skip
    return archive, black


def test_a_context_every_model_fails_is_dropped() -> None:
    archive, black = _with_black_frames()
    assert LEARNABLE_F1 == 0.05
    uncapped = select_contexts(archive, SelectionRule(contexts=40))
    assert np.isin(uncapped.rows, black).any()  # without a second opinion: kept
    assert uncapped.cap == "one model" and len(uncapped.unlearnable) == 0
    other = np.full(len(archive), 0.8)
    other[black] = 0.01  # another model fails there too: unlearnable
    capped = select_contexts(archive, SelectionRule(contexts=40), others=[other])
    assert not np.isin(capped.rows, black).any()
    assert sorted(capped.unlearnable.tolist()) == sorted(black.tolist())
    assert capped.cap == "applied" and capped.models == 2 and sum(capped.counts()) == 40
    back = Selection.from_dict(capped.as_dict())
    assert np.array_equal(back.unlearnable, capped.unlearnable) and back.cap == "applied"


def test_a_context_one_model_learns_is_kept() -> None:
    archive, black = _with_black_frames()
    learnt = np.full(len(archive), 0.8)
    learnt[black[1:]] = 0.0
    learnt[black[0]] = 0.78  # the dark hsl context: 0 for the default, 0.78 for another
    np.testing.assert_array_equal(unlearnable_rows(archive, [learnt]), black[1:])
    unmeasured = np.full(len(archive), np.nan)  # a model not measured there has no say
    np.testing.assert_array_equal(unlearnable_rows(archive, [learnt, unmeasured]), black[1:])
    off = select_contexts(archive, SelectionRule(contexts=40, learnable=0.0), others=[learnt])
    assert off.cap == "off" and len(off.unlearnable) == 0


def test_cap_errors() -> None:
    archive, _ = _with_black_frames()
    with pytest.raises(EnkiError, match="learnability floor"):
        SelectionRule(learnable=1.0)
    with pytest.raises(EnkiError, match="one per archive row"):
        unlearnable_rows(archive, [np.zeros(3)])
    black_only = _archive(np.array([[0.1], [0.5]]), np.array([2, 2]), drops=np.ones(2))
    with pytest.raises(EnkiError, match="nothing is learnable"):
        select_contexts(black_only, others=[np.zeros(2)])
