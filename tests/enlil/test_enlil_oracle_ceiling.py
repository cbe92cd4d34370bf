"""Figures beside their ceiling, a predicted F1 drop, steady training (issue 22, items 1, 2, 4)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from enlil_helpers import ColourDetector, tiny_data

pytest.importorskip("torch")

from anunnaki.enlil import (
    ContextSet,
    ContextSpec,
    EnlilError,
    EnlilOracle,
    OracleTrainConfig,
    box_stability,
    cohen_kappa,
    draw_contexts,
    evaluate_oracles,
    held_out_frames,
    interior_mask,
    label_ceiling,
    load_oracle,
    of_ceiling,
    oracle_predictions,
    parse_contexts,
    retest_contexts,
    score_predictions,
    seed_spread,
    spearman,
    train_oracle,
    train_oracle_seeds,
)
from anunnaki.enlil._oracle_eval import _matched_iou, drop_curve
from anunnaki.enlil._oracle_metrics import regression_metrics
from anunnaki.enlil._oracle_train import choice_split
from anunnaki.lec import DetectionResult, evaluate_detector
from anunnaki.messages import Assessment

FOG = "fog"


def _fog_contexts(drops: bool = True) -> ContextSet:
    density = np.linspace(0.0, 1.0, 12)
    units = np.stack([density, np.full(12, 0.5)], axis=1)
    cats = np.asarray([0] * 4 + [1] * 3 + [2] * 5)
    drop = np.linspace(0.0, 0.6, 12) if drops else None
    return ContextSet(FOG, ("density", "intensity"), units, cats, "test", drop)


CFG = OracleTrainConfig(frames=64, val_frames=40, epochs=2, batch_size=32, input_size=(64, 64))


@pytest.fixture(scope="module")
def oracle():  # type: ignore[no-untyped-def]
    data = tiny_data(16)
    return train_oracle(data, data, [_fog_contexts()], model_id="colour", config=CFG)


def test_kappa_spearman_and_regression_figures() -> None:
    assert cohen_kappa([0, 1, 2, 2], [0, 1, 2, 2]) == pytest.approx(1.0)
    # agreement no better than chance: both say 0 half the time, independently
    assert cohen_kappa([0, 0, 1, 1], [0, 1, 0, 1]) == pytest.approx(0.0)
    assert cohen_kappa([0, 1], [1, 0]) < 0
    assert cohen_kappa([2, 2], [2, 2]) == 1.0 and math.isnan(cohen_kappa([], []))
    assert spearman([1, 2, 3, 4], [10, 20, 30, 400]) == pytest.approx(1.0)
    assert spearman([1, 2, 3], [3, 2, 1]) == pytest.approx(-1.0)
    assert spearman([1, 1, 2], [5, 5, 9]) == pytest.approx(1.0)  # ties at mean rank
    assert math.isnan(spearman([1, 1, 1], [1, 2, 3]))
    figures = regression_metrics([0.1, 0.2], [0.1, 0.4])
    assert figures["rmse"] == pytest.approx(math.sqrt(0.02)) and figures["mae"] == pytest.approx(
        0.1
    )


def test_interior_and_fractions_of_the_ceiling() -> None:
    drops = np.asarray([0.0, 0.045, 0.075, 0.095, 0.3])
    assert interior_mask(drops, (0.05, 0.10), 0.01).tolist() == [True, False, True, False, True]
    assert interior_mask(drops, (0.05, 0.10), 0.0).all()
    assert of_ceiling({"macro_f1": 0.6, "kappa": 0.3}, {"macro_f1": 0.8, "kappa": 0.6}) == {
        "macro_f1": pytest.approx(0.75),
        "kappa": pytest.approx(0.5),
    }
    assert of_ceiling({"macro_f1": 0.6, "kappa": 0.3}, {"macro_f1": 0.0, "kappa": math.nan}) == {
        "macro_f1": None,
        "kappa": None,
    }


def test_the_retest_measures_each_context_on_a_disjoint_batch() -> None:
    det, data = ColourDetector(), tiny_data(12, seed=5)
    held = held_out_frames(
        det, data, FOG, ContextSpec("random", 5), per_context=2, batch_images=6, seed=1
    )
    again = retest_contexts(det, data, held, batch_images=6, seed=1)
    assert again.retest is not None and again.retest.batch_images == 6
    ceiling = label_ceiling(again)
    first, second = np.asarray([r.drop for r in held.contexts]), again.retest.drops
    noise_all = math.sqrt(float(np.mean((first - second) ** 2)) / 2)
    assert ceiling["drop_noise_all"] == pytest.approx(noise_all)
    assert ceiling["drop"]["rmse"] == pytest.approx(noise_all * math.sqrt(2))
    # the noise that decides the interior: contexts near the band (mean drop <= 0.2)
    near = (first + second) / 2 <= 0.2
    use = near if near.sum() >= 2 else np.ones_like(near)
    noise = math.sqrt(float(np.mean((first[use] - second[use]) ** 2)) / 2)
    assert ceiling["drop_noise"] == pytest.approx(noise)
    assert ceiling["drop_noise_contexts"] == int(use.sum())
    assert ceiling["kappa"] == pytest.approx(
        cohen_kappa([r.category for r in held.contexts], again.retest.categories)
    )
    # a context restricted set keeps its frames, labels and retest in step
    keep = np.asarray([True, False, True, False, True])
    part = again.only(keep)
    assert len(part.contexts) == 3 and len(part.frames) == 6 and part.labels.shape == (6,)
    assert (
        part.retest is not None and part.retest.drops.tolist() == again.retest.drops[keep].tolist()
    )
    with pytest.raises(EnlilError, match="label_ceiling"):
        label_ceiling(held)
    with pytest.raises(EnlilError, match="none left for a second label batch"):
        retest_contexts(det, data, held, batch_images=12, seed=1)


def test_interior_contexts_lie_away_from_the_band_edges() -> None:
    det, data = ColourDetector(), tiny_data(12, seed=5)
    clean = evaluate_detector(det, data).f1
    spec = parse_contexts("interior:6", ("random", "balanced", "interior"))
    assert spec == ContextSpec("interior", 6)
    drawn = draw_contexts(det, data, FOG, spec, clean_f1=clean, seed=2, margin=0.02)
    assert drawn.results
    for r in drawn.results:
        assert abs(r.drop - 0.05) > 0.02 and abs(r.drop - 0.10) > 0.02
    # no margin: the balanced set itself
    plain = draw_contexts(det, data, FOG, ContextSpec("balanced", 6), clean_f1=clean, seed=2)
    same = draw_contexts(
        det, data, FOG, ContextSpec("balanced", 6), clean_f1=clean, seed=2, margin=0.02
    )
    assert [r.params.tolist() for r in plain.results] == [r.params.tolist() for r in same.results]


def test_evaluate_reports_the_ceiling_and_an_interior_set(oracle) -> None:  # type: ignore[no-untyped-def]
    report = evaluate_oracles(
        ColourDetector(), tiny_data(12, seed=3), FOG, ContextSpec("balanced", 3),
        oracles={"enlil": oracle}, baselines=("max-score",), val=tiny_data(12, seed=4),
        per_context=5, batch_images=6,
    )  # fmt: skip
    for part in (report, report["interior"]):
        assert {"kappa", "macro_f1", "drop_noise"} <= set(part["ceiling"])
        for figures in part["predictors"].values():
            assert "of_ceiling" in figures and figures["drop"] is not None
    assert report["interior"]["margin"] == report["ceiling"]["drop_noise"]
    assert report["interior"]["test"]["spec"] == "interior:3"
    quiet = evaluate_oracles(
        ColourDetector(), tiny_data(12, seed=3), FOG, ContextSpec("balanced", 3),
        oracles={"enlil": oracle}, per_context=5, batch_images=6, ceiling=False,
    )  # fmt: skip
    assert "ceiling" not in quiet and "interior" not in quiet


def test_the_drop_head_is_trained_calibrated_and_saved(oracle, tmp_path) -> None:  # type: ignore[no-untyped-def]
    card = oracle.card
    assert card.options["drop_head"] is True and card.drop is not None
    val = card.metrics["val"]
    assert set(val["drop"]) == {"rmse", "mae", "spearman"} and "drop_category_macro_f1" in val
    assert card.training["val_choice_frames"] == 20 and val["frames"] == 20
    frame = tiny_data(1).image(0)
    (pred,) = oracle.predict([frame])
    raw = oracle.outputs([frame]).drop
    assert pred.drop == pytest.approx(card.drop.scale * float(raw[0]) + card.drop.offset)
    digest = oracle.save(tmp_path / "o")
    loaded = load_oracle(tmp_path / "o", sha256=digest)
    assert loaded.card.drop == card.drop
    assert loaded.predict([frame])[0].drop == pytest.approx(pred.drop, abs=1e-6)
    held = held_out_frames(
        ColourDetector(), tiny_data(8, seed=5), FOG, ContextSpec("random", 2), per_context=5,
        batch_images=8, seed=1,
    )  # fmt: skip
    figures = score_predictions(held, oracle_predictions(oracle, held))
    assert figures["drop"]["rmse"] >= 0 and "category_macro_f1" in figures["drop"]


def test_without_drops_no_drop_head_and_old_files_load(tmp_path) -> None:  # type: ignore[no-untyped-def]
    data = tiny_data(16)
    plain = train_oracle(data, data, [_fog_contexts(drops=False)], model_id="colour", config=CFG)
    assert "drop_head" not in plain.card.options and plain.card.drop is None
    assert plain.card.output_temperature == 1.0  # no lookup: nothing to re-calibrate
    frame = tiny_data(1).image(0)
    assert plain.predict([frame])[0].drop is None
    plain.save(tmp_path / "p")
    assert load_oracle(tmp_path / "p").card.drop is None


def test_the_assessment_carries_the_drop_and_a_goal_relaxes_on_it(oracle) -> None:  # type: ignore[no-untyped-def]
    from anunnaki.goals import Evaluator, parse_goal_model

    plugin = EnlilOracle(oracles={"colour": oracle})
    assessment = plugin.assess(tiny_data(1).image(0), seq=0, model_id="colour")
    assert assessment is not None and assessment.drop is not None
    # an older message without the field still loads
    old = Assessment.model_validate(
        {"category": 0, "confidence": 0.9, "model_id": "m", "assessor": "enlil"}
    )
    assert old.drop is None
    model = parse_goal_model(
        """\
anunnaki: goal-model/1
name: drop
root: G1
agents:
  - {id: A4, topics: [{topic: /utu/oracle/output, attributes: [category, drop]}]}
goals:
  - id: G1
    description: The detector loses at most 5 % of its F1, relaxed up to 10 %
    utility: A4.drop
    relax: {operator: as_close_as_possible_to_quantity, target: 0.0, tolerance: 0.1, side: at_most}
    threshold: 0.5
    agents: [A4]
""",
        strict=False,
    )
    ev = Evaluator(model)
    seen = []
    for t, drop in enumerate((0.02, 0.045, 0.08, float(assessment.drop))):
        message = assessment.model_copy(update={"drop": drop}).model_dump(mode="json")
        ev.observe("/utu/oracle/output", message, float(t))
        ev.tick(float(t))
        seen.append((ev.state("G1").utility, ev.satisfied_for_tactics("G1")))
    assert seen[0][0] == pytest.approx(0.8) and seen[0][1] is True
    assert seen[1][0] == pytest.approx(0.55) and seen[1][1] is True
    assert seen[2][0] == pytest.approx(0.2) and seen[2][1] is False
    expected = min(1.0, max(0.0, 1.0 - max(float(assessment.drop), 0.0) / 0.1))
    assert seen[3][0] == pytest.approx(expected)


def test_baseline_drop_curve_and_box_matching() -> None:
    knots, values = drop_curve(
        np.asarray([0.9, 0.8, 0.2, 0.1]), np.asarray([0.0, 0.0, 0.4, 0.6]), 2
    )
    assert knots == pytest.approx((0.15, 0.85)) and values == pytest.approx((0.5, 0.0))
    box = np.asarray([[0.0, 0.0, 10.0, 10.0]])
    same = DetectionResult(box, [0], [0.9])
    moved = DetectionResult(box + np.asarray([5.0, 0.0, 5.0, 0.0]), [0], [0.9])
    none = DetectionResult(np.zeros((0, 4)), np.zeros(0), np.zeros(0))
    assert _matched_iou(same, same) == pytest.approx(1.0)
    assert _matched_iou(same, moved) == pytest.approx(50.0 / 150.0)
    assert _matched_iou(same, none) == 0.0 and _matched_iou(none, none) == 1.0
    with pytest.raises(EnlilError, match="no 'network' module"):
        box_stability(ColourDetector(), [tiny_data(1).image(0)])


def test_box_stability_reads_a_torch_detector() -> None:
    from pathlib import Path

    from anunnaki.lec import load_detector, predict
    from anunnaki.phenomena import PHENOMENA

    models = Path(__file__).resolve().parents[2] / "examples" / "models"
    det = load_detector(models / "rover-default.safetensors")
    frames = [tiny_data(2).image(i) for i in range(2)]
    fog = PHENOMENA.create("fog")
    frames.append(fog.apply(frames[0], fog.from_vector(np.asarray([1.0, 1.0])), seed=0))
    first = box_stability(det, frames)
    assert first.shape == (3,) and ((first >= 0) & (first <= 1)).all()
    assert box_stability(det, frames).tolist() == first.tolist()  # a fixed dropout seed
    # the dropout hooks are gone afterwards
    again = predict(det, frames)
    plain = predict(det, frames)
    assert [len(d) for d in again] == [len(d) for d in plain]


def test_choice_split_and_seed_spread() -> None:
    pick, rest = choice_split(10, 0.5, seed=0)
    assert len(pick) == 5 and sorted([*pick, *rest]) == list(range(10))
    with pytest.raises(EnlilError, match=r"in \(0, 1\)"):
        choice_split(10, 1.0)
    spread = seed_spread([0.5, 0.7, 0.6])
    assert spread["mean"] == pytest.approx(0.6) and spread["spread"] == pytest.approx(0.2)
    assert spread["sd"] == pytest.approx(0.1)


def test_several_seeds_give_mean_and_spread() -> None:
    data = tiny_data(12)
    cfg = OracleTrainConfig(frames=32, val_frames=20, epochs=1, batch_size=32, input_size=(32, 32))
    oracles, figures = train_oracle_seeds(
        data, data, [_fog_contexts()], [0, 1], model_id="colour", config=cfg
    )
    assert [o.card.training["config"]["seed"] for o in oracles] == [0, 1]
    assert set(figures) == {"accuracy", "macro_f1", "ece", "drop_rmse"}
    values = [o.card.metrics["val"]["macro_f1"] for o in oracles]
    assert figures["macro_f1"]["spread"] == pytest.approx(max(values) - min(values))


def test_a_margin_of_half_the_band_leaves_category_1_short() -> None:
    det, data = ColourDetector(), tiny_data(12, seed=5)
    clean = evaluate_detector(det, data).f1
    spec = ContextSpec("interior", 6)
    drawn = draw_contexts(det, data, FOG, spec, clean_f1=clean, seed=2, margin=0.03)
    assert drawn.counts()[1] == 0 and drawn.short[1] == 2
    assert drawn.evaluations <= 3 * 6 + (6 + 2) * 8
