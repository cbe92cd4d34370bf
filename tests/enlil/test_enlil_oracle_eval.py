"""Scoring oracles and detector-output baselines on held-out frames (issue 13, items 4-5)."""

from __future__ import annotations

import numpy as np
import pytest
from enlil_helpers import ColourDetector, tiny_data

pytest.importorskip("torch")

from anunnaki.enlil import (
    ContextSet,
    ContextSpec,
    EnlilError,
    HeldOut,
    OracleTrainConfig,
    Predictions,
    baseline_predictions,
    draw_contexts,
    evaluate_oracles,
    fit_baseline,
    held_out_frames,
    oracle_predictions,
    parse_contexts,
    score_predictions,
    train_oracle,
)
from anunnaki.enlil._oracle_eval import _fit_thresholds
from anunnaki.lec import evaluate_detector

FOG = "fog"


@pytest.fixture(scope="module")
def held() -> HeldOut:
    return held_out_frames(
        ColourDetector(), tiny_data(12, seed=5), FOG, ContextSpec("random", 6),
        per_context=5, batch_images=12, seed=1,
    )  # fmt: skip


@pytest.fixture(scope="module")
def oracle():  # type: ignore[no-untyped-def]
    density = np.linspace(0.0, 1.0, 12)
    units = np.stack([density, np.full(12, 0.5)], axis=1)
    cats = np.asarray([0] * 4 + [1] * 3 + [2] * 5)
    contexts = ContextSet(FOG, ("density", "intensity"), units, cats, "test")
    cfg = OracleTrainConfig(frames=64, val_frames=32, epochs=2, batch_size=32, input_size=(64, 64))
    data = tiny_data(16)
    return train_oracle(data, data, [contexts], model_id="colour", config=cfg)


def test_parse_contexts() -> None:
    assert parse_contexts("balanced:30") == ContextSpec("balanced", 30)
    assert str(parse_contexts(" random:5 ")) == "random:5"
    for bad in ("random", "uniform:3", "random:0", "random:x"):
        with pytest.raises(EnlilError, match="write random:N or balanced:N"):
            parse_contexts(bad)


def test_held_out_frames_carry_their_measured_category(held: HeldOut) -> None:
    assert len(held.contexts) == 6 and len(held.frames) == 30
    assert held.per_context == 5 and held.labels.shape == (30,)
    for c, result in enumerate(held.contexts):
        assert (held.labels[c * 5 : c * 5 + 5] == result.category).all()
    # the label is the category the detector really gets under that context
    det, data = ColourDetector(), tiny_data(12, seed=5)
    clean = evaluate_detector(det, data).f1
    assert held.clean_f1 == pytest.approx(clean)
    np.testing.assert_allclose(held.units()[5], held.contexts[1].params)
    assert held.windows(5).tolist()[:2] == [[0, 1, 2, 3, 4], [5, 6, 7, 8, 9]]
    with pytest.raises(EnlilError, match="frames per context"):
        held.windows(6)


def test_balanced_contexts_fill_each_category() -> None:
    det, data = ColourDetector(), tiny_data(12, seed=5)
    clean = evaluate_detector(det, data).f1
    drawn = draw_contexts(det, data, FOG, ContextSpec("balanced", 6), clean_f1=clean, seed=2)
    counts = drawn.counts()
    missing = sum(drawn.short.values())
    assert sum(counts) + missing == 6
    assert all(counts[c] + drawn.short.get(c, 0) == 2 for c in range(3))
    assert counts[0] == 2 and counts[2] == 2  # the common ones are always found
    assert drawn.evaluations >= 6


def test_a_perfect_predictor_scores_one(held: HeldOut) -> None:
    rows = held.windows(5)
    probs = np.eye(3)[held.labels]
    perfect = Predictions(
        "truth", held.labels, held.labels[rows[:, 0]], probs, probs[rows].mean(axis=1),
        held.units(),
    )  # fmt: skip
    figures = score_predictions(held, perfect)
    assert figures["accuracy"] == 1.0 and figures["macro_f1"] == 1.0
    assert figures["ece"] == pytest.approx(0.0) and figures["context_error"] == 0.0
    assert figures["window"]["accuracy"] == 1.0 and figures["window"]["windows"] == 6
    assert sum(map(sum, figures["confusion"])) == 30


def test_oracle_predictions_are_scored(held: HeldOut, oracle) -> None:  # type: ignore[no-untyped-def]
    preds = oracle_predictions(oracle, held)
    assert preds.probs is not None and preds.probs.shape == (30, 3)
    np.testing.assert_allclose(preds.probs.sum(axis=1), 1.0, rtol=1e-6)
    figures = score_predictions(held, preds)
    assert 0.0 <= figures["accuracy"] <= 1.0 and 0.0 <= figures["ece"] <= 1.0
    assert set(figures["context_error_per_param"]) == {"density", "intensity"}
    assert figures["temperature"] == oracle.card.temperature
    expected = (preds.category == held.labels).mean()
    assert figures["accuracy"] == pytest.approx(expected)


def test_an_oracle_of_another_phenomenon_is_refused(oracle) -> None:  # type: ignore[no-untyped-def]
    other = held_out_frames(
        ColourDetector(), tiny_data(6), "raindrop", ContextSpec("random", 1), per_context=1,
        batch_images=6,
    )  # fmt: skip
    with pytest.raises(EnlilError, match=r"covers \['fog'\], not 'raindrop'"):
        oracle_predictions(oracle, other, window=1)


def test_fitted_thresholds_separate_a_monotone_statistic() -> None:
    labels = np.asarray([0] * 5 + [1] * 5 + [2] * 5)
    stat = np.asarray([0.9] * 5 + [0.5] * 5 + [0.1] * 5)
    t0, t1 = _fit_thresholds(stat, labels)
    assert 0.5 <= t0 < 0.9 and 0.1 <= t1 < 0.5


def test_baselines_read_the_detectors_outputs(held: HeldOut) -> None:
    det = ColourDetector()
    val = held_out_frames(
        det, tiny_data(12, seed=9), FOG, ContextSpec("random", 6), per_context=5,
        batch_images=12, seed=4,
    )  # fmt: skip
    clean = [tiny_data(12, seed=9).image(i) for i in range(12)]
    for kind in ("atc", "max-score"):
        fit = fit_baseline(kind, det, clean, 1.0, val)  # type: ignore[arg-type]
        assert fit.frame_thresholds[0] >= fit.frame_thresholds[1]
        figures = score_predictions(held, baseline_predictions(fit, det, held))
        assert figures["ece"] is None and figures["context_error"] is None
        assert 0.0 <= figures["macro_f1"] <= 1.0
    assert "atc_threshold" in figures or kind == "max-score"


def test_evaluate_oracles_scores_everyone_on_the_same_frames(oracle) -> None:  # type: ignore[no-untyped-def]
    report = evaluate_oracles(
        ColourDetector(), tiny_data(10, seed=3), FOG, ContextSpec("random", 2),
        oracles={"enlil": oracle}, baselines=("max-score",), val=tiny_data(10, seed=4),
        fit_spec=ContextSpec("random", 2), per_context=5, batch_images=5,
    )  # fmt: skip
    assert set(report["predictors"]) == {"enlil", "max-score"}
    assert report["test"]["frames"] == 10 and report["fit"]["contexts"] == 2
    assert all(f["frames"] == 10 for f in report["predictors"].values())
    with pytest.raises(EnlilError, match="fitted on val"):
        evaluate_oracles(
            ColourDetector(), tiny_data(4), FOG, ContextSpec("random", 1), oracles={},
            baselines=("atc",),
        )  # fmt: skip
