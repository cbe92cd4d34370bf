"""The behavior oracle: training on contexts, the model file, the enlil plugin per model."""

from __future__ import annotations

import numpy as np
import pytest
from enlil_helpers import tiny_data

pytest.importorskip("torch")

from anunnaki.enlil import (
    ContextSet,
    EnlilOracle,
    OracleTrainConfig,
    load_oracle,
    train_oracle,
)
from anunnaki.errors import ModelFileError
from anunnaki.oracles import ORACLES


def _fog_contexts() -> ContextSet:
    density = np.linspace(0.0, 1.0, 12)
    units = np.stack([density, np.full(12, 0.5)], axis=1)
    cats = np.asarray([0] * 4 + [1] * 3 + [2] * 5)
    return ContextSet("fog", ("density", "intensity"), units, cats, "test")


@pytest.fixture(scope="module")
def oracle_file(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    data = tiny_data(16)
    cfg = OracleTrainConfig(frames=96, val_frames=48, epochs=3, batch_size=32, input_size=(64, 64))
    oracle = train_oracle(data, data, [_fog_contexts()], model_id="colour", config=cfg)
    path = tmp_path_factory.mktemp("oracle") / "colour.oracle"
    digest = oracle.save(path)
    return path, digest, oracle


def test_trained_oracle_round_trips_without_pickle(oracle_file) -> None:  # type: ignore[no-untyped-def]
    path, digest, oracle = oracle_file
    loaded = load_oracle(path, sha256=digest)
    frame = tiny_data(1).image(0)
    assert loaded.card.model_id == "colour"
    assert 0.2 <= loaded.card.temperature <= 10.0
    assert set(loaded.card.metrics["val"]) >= {"accuracy", "macro_f1", "ece"}
    a, b = oracle.logits([frame])[0], loaded.logits([frame])[0]
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-5)
    with pytest.raises(ModelFileError, match="sha256 mismatch"):
        load_oracle(path, sha256="0" * 64)


def test_trained_network_is_saved_in_the_usual_layout(oracle_file) -> None:  # type: ignore[no-untyped-def]
    # trained and run channels-last for speed; the file holds each tensor's values in the
    # usual index order (raw channels-last memory would scramble the convolutions' weights)
    from safetensors.numpy import load_file

    from anunnaki.enlil._oracle_net import oracle_paths

    path, _digest, oracle = oracle_file
    weights = oracle.net.state_dict()
    assert not all(t.is_contiguous() for t in weights.values())  # channels-last in memory
    saved = load_file(str(oracle_paths(path)[0]))
    for name, tensor in weights.items():
        np.testing.assert_array_equal(saved[name], tensor.numpy())
    assert not oracle.net.training


def test_uint8_frames_are_the_float_frames_exactly() -> None:
    from anunnaki.enlil._oracle_net import frames_to_tensor, frames_to_uint8

    levels = np.arange(256, dtype=np.uint8).reshape(16, 16, 1).repeat(3, axis=2)
    frames = [levels, tiny_data(1).image(0)]  # 16 x 16 kept, 64 x 64 resized
    small = frames_to_uint8(frames, (16, 16))
    assert small.dtype.is_floating_point is False and tuple(small.shape) == (2, 3, 16, 16)
    exact = frames_to_tensor(frames, (16, 16))
    reference = np.stack([np.asarray(small[i]).astype(np.float32) for i in range(2)])
    reference /= 255.0  # the float path before frames were held as uint8
    np.testing.assert_array_equal(exact.numpy(), reference)
    assert exact.is_contiguous()


def test_enlil_plugin_is_per_model(oracle_file, caplog) -> None:  # type: ignore[no-untyped-def]
    path, _, _ = oracle_file
    plugin = ORACLES.create("enlil", oracles={"colour": path})
    assert isinstance(plugin, EnlilOracle)
    frame = tiny_data(1).image(0)
    first = plugin.assess(frame, seq=3, model_id="colour")
    assert first is not None
    assert first.assessor == "enlil" and first.model_id == "colour" and first.frame_seq == 3
    assert 0 <= first.category <= 2
    with caplog.at_level("WARNING", logger="anunnaki.enlil"):
        assert plugin.assess(frame, seq=4, model_id="other") is None
        assert plugin.assess(frame, seq=5, model_id="other") is None
    assert sum("no behavior oracle covers model 'other'" in r.message for r in caplog.records) == 1
    assert plugin.assess(frame, seq=6, model_id="colour") is not None


def test_registry_names_each_models_oracle(oracle_file, tmp_path) -> None:  # type: ignore[no-untyped-def]
    import shutil
    from pathlib import Path

    from anunnaki.errors import ModelFileError as RegistryFileError
    from anunnaki.lec import load_registry, sha256_file

    path, digest, _ = oracle_file
    models = Path(__file__).resolve().parents[2] / "examples" / "models"
    for name in ("rover-default", "rover-fog-enki"):  # a registry's files sit in its folder
        for suffix in (".safetensors", ".json"):
            shutil.copy(models / f"{name}{suffix}", tmp_path / f"{name}{suffix}")
    for suffix in (".safetensors", ".json"):
        shutil.copy(f"{path}{suffix}", tmp_path / f"{path.name}{suffix}")  # NAME.oracle + suffix
    path = tmp_path / path.name
    pin = {
        n: sha256_file(tmp_path / f"{n}.safetensors") for n in ("rover-default", "rover-fog-enki")
    }
    registry = tmp_path / "models.yaml"
    body = (
        "anunnaki: models/1\nmodels:\n"
        "  - id: colour\n    domain: default\n    file: rover-default.safetensors\n"
        f"    sha256: {pin['rover-default']}\n"
        f"    oracle: {{file: {path}.safetensors, sha256: {digest}}}\n"
        "  - id: rover-fog-enki\n    domain: fog\n    file: rover-fog-enki.safetensors\n"
        f"    sha256: {pin['rover-fog-enki']}\n"
    )
    registry.write_text(body)
    spec = load_registry(registry).get("colour")
    assert spec.oracle is not None and spec.oracle.sha256 == digest
    assert load_registry(registry).get("rover-fog-enki").oracle is None  # old entries still load
    plugin = EnlilOracle(registry)
    assert plugin.covered == ["colour"]
    assert plugin.assess(tiny_data(1).image(0), seq=0, model_id="colour") is not None
    assert plugin.assess(tiny_data(1).image(0), seq=1, model_id="rover-fog-enki") is None
    registry.write_text(body.replace(f"{path}.safetensors", "missing.safetensors"))
    with pytest.raises(RegistryFileError, match=r"oracle file 'missing\.safetensors' not found"):
        load_registry(registry)


def _blas_threads() -> set[int]:
    from threadpoolctl import threadpool_info  # type: ignore[import-untyped]

    return {int(lib["num_threads"]) for lib in threadpool_info() if lib["user_api"] == "blas"}


def test_enlil_plugin_assesses_on_one_blas_thread(oracle_file, monkeypatch, request) -> None:  # type: ignore[no-untyped-def]
    # A frame's lookup is a few small BLAS calls; idle OpenBLAS workers spun between frames
    # (23–34 ms of CPU a frame against 8–9 on one thread, docs/whole-loop.md). The process's own
    # setting is restored after each frame, and the figures are those of the default threads.
    from threadpoolctl import threadpool_limits

    path, _, _ = oracle_file
    # The process's threads are 2 here (the suite's processes compute on one, tests/conftest.py).
    limits = threadpool_limits(2, user_api="blas")
    request.addfinalizer(limits.restore_original_limits)
    threaded = EnlilOracle(oracles={"colour": path}, blas_threads=None)
    single = EnlilOracle(oracles={"colour": path})
    assert single.blas_threads == 1
    from anunnaki.enlil import OracleModel

    seen: list[set[int]] = []
    probabilities = OracleModel.category_probabilities

    def recording(self, *args, **kwargs):  # type: ignore[no-untyped-def]
        seen.append(_blas_threads())
        return probabilities(self, *args, **kwargs)

    monkeypatch.setattr(OracleModel, "category_probabilities", recording)
    before = _blas_threads()
    frames = tiny_data(3)
    for i in range(3):
        a = threaded.assess(frames.image(i), seq=i, model_id="colour")
        b = single.assess(frames.image(i), seq=i, model_id="colour")
        assert a is not None and b is not None
        assert (a.category, a.context["phenomenon"]) == (b.category, b.context["phenomenon"])
        probs = [np.asarray(x.context["probs"], dtype=float) for x in (a, b)]
        np.testing.assert_allclose(probs[0], probs[1], atol=1e-4)
        assert _blas_threads() == before  # restored
    assert before == {2}
    assert seen[0::2] == [before] * 3  # blas_threads=None: the process's threads
    assert seen[1::2] == [{1}] * 3  # the default: one


def test_enlil_plugin_refuses_bad_blas_threads(oracle_file) -> None:  # type: ignore[no-untyped-def]
    from anunnaki.oracles import OracleError

    path, _, _ = oracle_file
    with pytest.raises(OracleError, match="blas_threads"):
        EnlilOracle(oracles={"colour": path}, blas_threads=0)
