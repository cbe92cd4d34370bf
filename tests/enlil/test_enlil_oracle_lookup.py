"""The perceived-context lookup of a behavior oracle: vote, scales, mix, file round trip."""

from __future__ import annotations

import json

import numpy as np
import pytest
from enlil_helpers import tiny_data

from anunnaki.enlil import ContextLookup, ContextSet, EnlilError, merge_context_sets
from anunnaki.enlil._oracle_lookup import (
    boosted,
    choose_mix,
    fit_kernel,
    lookup_probabilities,
    mixed_probabilities,
)


def _step_contexts(n: int = 200, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Drops set by the first parameter alone: 0 below 0.4, rising to 1 at 0.6."""
    units = np.random.default_rng(seed).random((n, 2))
    drops = np.clip((units[:, 0] - 0.4) / 0.2, 0.0, 1.0) ** 2
    return units, drops


def test_the_surrogate_gives_the_category_of_the_smooth_drop() -> None:
    units, drops = _step_contexts()
    lookup = ContextLookup.from_contexts({"fog": (units, drops)})
    probs = lookup.vote("fog", [[0.1, 0.5], [0.455, 0.2], [0.9, 0.9]])
    assert probs.shape == (3, 3)
    np.testing.assert_allclose(probs.sum(axis=1), 1.0)
    assert list(probs.argmax(axis=1)) == [0, 1, 2]  # drops 0, 0.076, 1
    kernel = lookup.kernels["fog"]
    assert kernel.lengthscales[0] < kernel.lengthscales[1]  # the second does not matter


def test_noisy_measurements_are_smoothed() -> None:
    units, drops = _step_contexts(300)
    noisy = drops.copy()
    inner = (units[:, 0] > 0.1) & (units[:, 0] < 0.3) & (np.abs(units[:, 1] - 0.5) < 0.3)
    flipped = np.flatnonzero(inner)[:5]
    noisy[flipped] = 0.5  # five stray category-2 measurements deep in category 0
    lookup = ContextLookup.from_contexts({"fog": (units, noisy)})
    assert (lookup.vote("fog", units[flipped]).argmax(axis=1) == 0).all()


def _exact(lookup: ContextLookup, name: str, query: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The textbook predictive mean and standard deviation, from the full float64 inverse."""
    x, kernel = lookup.params[name], lookup.kernels[name]
    ls = np.asarray(kernel.lengthscales)

    def rbf(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return kernel.signal * np.exp(-0.5 * ((((a[:, None] - b[None]) / ls) ** 2).sum(axis=2)))

    inverse = np.linalg.inv(rbf(x, x) + (kernel.noise + 1e-6) * np.eye(len(x)))
    k = rbf(query, x)
    mean = kernel.mean + k @ inverse @ (lookup.targets[name] - kernel.mean)
    var = kernel.signal + kernel.noise - np.einsum("ij,ij->i", k @ inverse, k)
    return mean, np.sqrt(var)


@pytest.mark.parametrize(("noise", "dtype"), [(0.3, np.float32), (0.0, np.float64)])
def test_a_lookup_predicts_in_float32_only_where_float64_would_agree(
    noise: float, dtype: type
) -> None:
    units, drops = _step_contexts(300)
    rng = np.random.default_rng(1)
    noisy = np.clip(drops + noise * rng.standard_normal(len(drops)) * drops, 0.0, 1.0)
    lookup = ContextLookup.from_contexts({"fog": (units, noisy)})
    assert lookup._process("fog").whiten.dtype == dtype  # noisy: float32; exact drops: 64
    query = np.vstack([units[:20], rng.random((200, 2))])
    mean, std = lookup.predict("fog", query)
    exact_mean, exact_std = _exact(lookup, "fog", query)
    np.testing.assert_allclose(mean, exact_mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(std, exact_std, rtol=2e-4)
    for i in (0, 7, 150):  # one query at a time (a frame at run time: the triangular product)
        m1, s1 = lookup.predict("fog", query[i])
        np.testing.assert_allclose([m1[0], s1[0]], [exact_mean[i], exact_std[i]], rtol=2e-4)


def test_exclude_leaves_a_row_out_of_its_own_prediction() -> None:
    units, drops = _step_contexts(60)
    lookup = ContextLookup.from_contexts({"fog": (units, drops)})
    query = units[:4]
    _, std = lookup.predict("fog", query)
    loo_mean, loo_std = lookup.predict("fog", query, exclude=[0, 1, 2, 3])
    assert (loo_std > std).all()  # its own measurement no longer pins it
    # the closed form equals refitting the process without the row (same kernel)
    rest = ContextLookup(
        {"fog": lookup.params["fog"][1:]},
        {"fog": lookup.targets["fog"][1:]},
        dict(lookup.kernels),
    )
    m1, s1 = rest.predict("fog", query[:1])
    np.testing.assert_allclose([loo_mean[0], loo_std[0]], [m1[0], s1[0]], rtol=1e-6)


def test_lookup_probabilities_weigh_phenomena_and_clear() -> None:
    units, drops = _step_contexts()
    lookup = ContextLookup.from_contexts({"fog": (units, drops), "hsl": (units, 1.0 - drops)})
    params = np.asarray([[0.9, 0.5], [0.9, 0.5], [0.9, 0.5]])
    phen = np.asarray([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])  # clear, fog, hsl
    probs = lookup_probabilities(lookup, ["fog", "hsl"], params, phen)
    assert list(probs.argmax(axis=1)) == [0, 2, 0]
    np.testing.assert_allclose(probs[0], [1.0, 0.0, 0.0])


def test_choose_mix_prefers_what_predicts_val() -> None:
    labels = np.asarray([0, 1, 2] * 20)
    right = np.eye(3)[labels]
    wrong = np.eye(3)[(labels + 1) % 3]
    weight, boost, f1 = choose_mix(wrong, right, labels)
    assert weight < 0.5 and boost == 0.0 and f1 == 1.0
    weight, boost, f1 = choose_mix(right, wrong, labels)
    assert weight == 1.0 and f1 == 1.0
    np.testing.assert_allclose(mixed_probabilities(right, wrong, 0.25).sum(axis=1), 1.0)
    # category 1 never wins on its own here; a boost makes it
    shy = np.where(labels[:, None] == 1, [0.45, 0.35, 0.2], np.eye(3)[labels] * 0.9 + 0.05)
    weight, boost, f1 = choose_mix(shy, shy, labels)
    assert boost > 0.0 and f1 == 1.0
    np.testing.assert_allclose(boosted(shy, boost).sum(axis=1), 1.0)


def test_bad_lookups_are_refused() -> None:
    units, drops = _step_contexts(20)
    lookup = ContextLookup.from_contexts({"fog": (units, drops)})
    with pytest.raises(EnlilError, match="must be"):
        ContextLookup({"fog": units}, {"fog": drops[:3]}, dict(lookup.kernels))
    with pytest.raises(EnlilError, match="no measured contexts of 'hsl'"):
        lookup.vote("hsl", units)
    with pytest.raises(EnlilError, match="N >= 3"):
        fit_kernel(units[:2], drops[:2])


def test_merge_context_sets_joins_one_phenomenon() -> None:
    units, drops = _step_contexts(10)
    cats = (drops > 0.05).astype(np.int64) + (drops > 0.10)
    a = ContextSet("fog", ("density", "intensity"), units, cats, "archive:a", drops)
    b = ContextSet("fog", ("density", "intensity"), units[:4], cats[:4], "archive:b", drops[:4])
    c = ContextSet("hsl", ("hue", "saturation"), units, cats, "archive:c")
    merged = merge_context_sets([a, c, b])
    assert [m.phenomenon for m in merged] == ["fog", "hsl"]
    assert len(merged[0].params) == 14 and merged[0].source == "archive:a+archive:b"
    assert merged[0].drops is not None and len(merged[0].drops) == 14
    assert merge_context_sets([a, ContextSet("fog", a.param_names, units, cats)])[0].drops is None
    other = ContextSet("fog", ("density", "x"), units, cats, "archive:d")
    with pytest.raises(EnlilError, match="give archives of one phenomenon"):
        merge_context_sets([a, other])


torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    from anunnaki.enlil import OracleTrainConfig, train_oracle

    density = np.linspace(0.0, 1.0, 24)
    units = np.stack([density, np.full(24, 0.5)], axis=1)
    drops = np.clip((density - 0.25) / 0.4, 0.0, 1.0)
    cats = (drops > 0.05).astype(np.int64) + (drops > 0.10)
    sets = [ContextSet("fog", ("density", "intensity"), units, cats, "test", drops)]
    data = tiny_data(16)
    out = {}
    for lookup in (True, False):
        cfg = OracleTrainConfig(
            frames=96, val_frames=60, epochs=2, batch_size=32, input_size=(64, 64),
            lookup=lookup,
        )  # fmt: skip
        oracle = train_oracle(data, data, sets, model_id="colour", config=cfg)
        path = tmp_path_factory.mktemp("lookup") / f"colour-{lookup}.oracle"
        out[lookup] = (oracle, path, oracle.save(path))
    return out


def test_a_trained_lookup_round_trips_in_the_oracle_file(trained) -> None:  # type: ignore[no-untyped-def]
    from anunnaki.enlil import load_oracle

    oracle, path, digest = trained[True]
    spec = oracle.card.lookup
    assert spec is not None and 0.0 <= spec.weight <= 1.0 and spec.boost >= 0.0
    assert spec.rows == {"fog": 24} and spec.chosen_on["split"] == "val"
    assert oracle.card.training["soft_labels"] is True
    assert oracle.card.format == "anunnaki-oracle/2"
    assert "head_macro_f1" in oracle.card.metrics["val"]
    loaded = load_oracle(path, sha256=digest)
    assert loaded.lookup is not None
    np.testing.assert_array_equal(loaded.lookup.targets["fog"], oracle.lookup.targets["fog"])
    frames = [tiny_data(3, seed=5).image(i) for i in range(3)]
    a = [p.probs for p in oracle.predict(frames)]
    b = [p.probs for p in loaded.predict(frames)]
    np.testing.assert_allclose(a, b, atol=1e-6)


def test_an_oracle_without_lookup_keeps_format_1(trained) -> None:  # type: ignore[no-untyped-def]
    from anunnaki.enlil import load_oracle

    oracle, path, digest = trained[False]
    assert oracle.card.lookup is None and oracle.card.format == "anunnaki-oracle/1"
    assert oracle.card.training["soft_labels"] is False
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


def test_the_plugin_loads_its_oracles_when_built(trained, tmp_path) -> None:  # type: ignore[no-untyped-def]
    from anunnaki.enlil import EnlilOracle
    from anunnaki.errors import ModelFileError

    _, path, _ = trained[True]
    plugin = EnlilOracle(oracles={"colour": path})
    assert plugin._loaded["colour"] is not None  # no frame waits for the file
    missing = tmp_path / "missing.oracle"
    with pytest.raises(ModelFileError):
        EnlilOracle(oracles={"colour": missing})
    lazy = EnlilOracle(oracles={"colour": missing}, preload=False)
    with pytest.raises(ModelFileError):
        lazy.assess(tiny_data(1).image(0), seq=0, model_id="colour")
