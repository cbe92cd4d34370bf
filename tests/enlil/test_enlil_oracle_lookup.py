"""The perceived-context lookup of a behavior oracle: vote, scales, mix, file round trip."""

from __future__ import annotations

import json

import numpy as np
import pytest
from enlil_helpers import tiny_data

from anunnaki.enlil import ContextLookup, ContextSet, EnlilError, merge_context_sets
from anunnaki.enlil._oracle_lookup import (
    choose_mix,
    fit_scales,
    lookup_probabilities,
    mixed_probabilities,
)


def _step_contexts(n: int = 200, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Category set by the first parameter alone (0 below 0.4, 1 up to 0.5, 2 above)."""
    units = np.random.default_rng(seed).random((n, 2))
    cats = np.where(units[:, 0] < 0.4, 0, np.where(units[:, 0] < 0.5, 1, 2))
    return units, cats


def test_vote_follows_the_nearest_measured_contexts() -> None:
    units, cats = _step_contexts()
    lookup = ContextLookup.from_contexts({"fog": (units, cats)}, k=7)
    probs = lookup.vote("fog", [[0.1, 0.5], [0.45, 0.2], [0.9, 0.9]])
    assert probs.shape == (3, 3)
    np.testing.assert_allclose(probs.sum(axis=1), 1.0)
    assert list(probs.argmax(axis=1)) == [0, 1, 2]
    assert (probs > 0).all()  # a pseudo-count keeps every category possible


def test_exclude_leaves_a_row_out_of_its_own_vote() -> None:
    units = np.asarray([[0.0, 0.0], [1.0, 1.0], [1.0, 0.9]])
    cats = np.asarray([0, 2, 2])
    lookup = ContextLookup.from_contexts({"fog": (units, cats)}, k=1, scales={"fog": [1, 1]})
    assert lookup.vote("fog", [[0.0, 0.0]]).argmax() == 0
    assert lookup.vote("fog", [[0.0, 0.0]], exclude=[0]).argmax() == 2


def test_fit_scales_shrinks_a_parameter_that_does_not_matter() -> None:
    units, cats = _step_contexts(300)
    scale = fit_scales(units, cats, k=9)
    assert scale[0] > scale[1]


def test_lookup_probabilities_weigh_phenomena_and_clear() -> None:
    units, cats = _step_contexts()
    lookup = ContextLookup.from_contexts({"fog": (units, cats), "hsl": (units, 2 - cats)}, k=5)
    params = np.asarray([[0.9, 0.5], [0.9, 0.5], [0.9, 0.5]])
    phen = np.asarray([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])  # clear, fog, hsl
    probs = lookup_probabilities(lookup, ["fog", "hsl"], params, phen)
    assert list(probs.argmax(axis=1)) == [0, 2, 0]
    np.testing.assert_allclose(probs[0], [1.0, 0.0, 0.0])


def test_choose_mix_prefers_what_predicts_val() -> None:
    labels = np.asarray([0, 1, 2] * 20)
    right = np.eye(3)[labels]
    wrong = np.eye(3)[(labels + 1) % 3]
    k, weight, f1 = choose_mix(wrong, {5: right, 10: wrong}, labels)
    assert k == 5 and weight < 0.5 and f1 == 1.0  # the largest weight that still works
    k, weight, f1 = choose_mix(right, {5: wrong}, labels)
    assert weight == 1.0 and f1 == 1.0
    mixed = mixed_probabilities(right, wrong, 0.25)
    np.testing.assert_allclose(mixed.sum(axis=1), 1.0)


def test_bad_lookups_are_refused() -> None:
    with pytest.raises(EnlilError, match="must be"):
        ContextLookup({"fog": np.zeros((3, 2), np.float32)}, {"fog": np.zeros(2, np.int64)},
                      {"fog": np.ones(2)})  # fmt: skip
    units, cats = _step_contexts(20)
    lookup = ContextLookup.from_contexts({"fog": (units, cats)})
    with pytest.raises(EnlilError, match="no measured contexts of 'hsl'"):
        lookup.vote("hsl", units)


def test_merge_context_sets_joins_one_phenomenon() -> None:
    units, cats = _step_contexts(10)
    a = ContextSet("fog", ("density", "intensity"), units, cats, "archive:a")
    b = ContextSet("fog", ("density", "intensity"), units[:4], cats[:4], "archive:b")
    c = ContextSet("hsl", ("hue", "saturation"), units, cats, "archive:c")
    merged = merge_context_sets([a, c, b])
    assert [m.phenomenon for m in merged] == ["fog", "hsl"]
    assert len(merged[0].params) == 14 and merged[0].source == "archive:a+archive:b"
    other = ContextSet("fog", ("density", "x"), units, cats, "archive:d")
    with pytest.raises(EnlilError, match="give archives of one phenomenon"):
        merge_context_sets([a, other])


torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    from anunnaki.enlil import OracleTrainConfig, train_oracle

    density = np.linspace(0.0, 1.0, 24)
    units = np.stack([density, np.full(24, 0.5)], axis=1)
    cats = np.where(density < 0.3, 0, np.where(density < 0.5, 1, 2))
    sets = [ContextSet("fog", ("density", "intensity"), units, cats, "test")]
    data = tiny_data(16)
    out = {}
    for lookup in (True, False):
        cfg = OracleTrainConfig(
            frames=96, val_frames=60, epochs=2, batch_size=32, input_size=(64, 64),
            lookup=lookup, lookup_k=(3, 6),
        )  # fmt: skip
        oracle = train_oracle(data, data, sets, model_id="colour", config=cfg)
        path = tmp_path_factory.mktemp("lookup") / f"colour-{lookup}.oracle"
        out[lookup] = (oracle, path, oracle.save(path))
    return out


def test_a_trained_lookup_round_trips_in_the_oracle_file(trained) -> None:  # type: ignore[no-untyped-def]
    from anunnaki.enlil import load_oracle

    oracle, path, digest = trained[True]
    spec = oracle.card.lookup
    assert spec is not None and spec.k in (3, 6) and 0.0 <= spec.weight <= 1.0
    assert spec.rows == {"fog": 24} and spec.chosen_on["split"] == "val"
    assert oracle.card.format == "anunnaki-oracle/2"
    assert "head_macro_f1" in oracle.card.metrics["val"]
    loaded = load_oracle(path, sha256=digest)
    assert loaded.lookup is not None
    np.testing.assert_array_equal(loaded.lookup.categories["fog"], oracle.lookup.categories["fog"])
    frames = [tiny_data(3, seed=5).image(i) for i in range(3)]
    a = [p.probs for p in oracle.predict(frames)]
    b = [p.probs for p in loaded.predict(frames)]
    np.testing.assert_allclose(a, b, atol=1e-6)


def test_an_oracle_without_lookup_keeps_format_1(trained) -> None:  # type: ignore[no-untyped-def]
    from anunnaki.enlil import load_oracle

    oracle, path, digest = trained[False]
    assert oracle.card.lookup is None and oracle.card.format == "anunnaki-oracle/1"
    loaded = load_oracle(path, sha256=digest)
    assert loaded.lookup is None
    cat, params, phen = loaded.logits([tiny_data(1).image(0)])
    np.testing.assert_allclose(
        loaded.category_probabilities(cat, params, phen), loaded.probabilities(cat)
    )


def test_a_lookup_named_but_missing_from_the_weights_is_refused(trained, tmp_path) -> None:  # type: ignore[no-untyped-def]
    from safetensors.numpy import load_file, save_file

    from anunnaki.enlil import load_oracle
    from anunnaki.enlil._oracle_net import oracle_paths
    from anunnaki.errors import ModelFileError

    _, path, _ = trained[True]
    weights, sidecar = oracle_paths(path)
    arrays = {k: v for k, v in load_file(str(weights)).items() if not k.startswith("lookup.")}
    bad = tmp_path / "bad.oracle"
    bad_weights, bad_sidecar = oracle_paths(bad)
    save_file(arrays, str(bad_weights))
    card = json.loads(sidecar.read_text())
    card["weights_sha256"] = ""
    bad_sidecar.write_text(json.dumps(card))
    with pytest.raises(ModelFileError, match=r"lookup\.fog\.params"):
        load_oracle(bad)
