"""The model registry: entries per domain, resolution, files with line numbers, integrity."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

import pytest

from anunnaki.errors import AnunnakiError, ModelFileError
from anunnaki.lec import (
    DetectorLoadError,
    ModelIntegrityError,
    ModelLoadError,
    ModelRegistry,
    ModelRegistryError,
    ModelSpec,
    UnknownModelError,
    load_detector,
    load_registry,
    parse_registry,
    sha256_file,
)
from anunnaki.lec._detector import DetectionResult


class FakeDetector:
    """A detector double: what a model file (a small JSON file) describes."""

    def __init__(self, model_id: str, domain: str) -> None:
        self.model_id = model_id
        self.domain = domain
        self.classes = ("person", "car")

    def detect(self, images: Any) -> list[DetectionResult]:
        return [DetectionResult.empty() for _ in images]


def fake_loader(calls: list[Path] | None = None) -> Any:
    def load(path: Path) -> FakeDetector:
        if calls is not None:
            calls.append(path)
        data = json.loads(path.read_text(encoding="utf-8"))  # garbage raises: "corrupt"
        return FakeDetector(data["model_id"], data["domain"])

    return load


def write_model(folder: Path, model_id: str, domain: str) -> tuple[Path, str]:
    path = folder / f"{model_id}.model"
    path.write_text(json.dumps({"model_id": model_id, "domain": domain}), encoding="utf-8")
    return path, hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def models(tmp_path: Path) -> dict[str, tuple[Path, str]]:
    return {
        "det-default": write_model(tmp_path, "det-default", "default"),
        "det-fog": write_model(tmp_path, "det-fog", "fog"),
        "det-dark": write_model(tmp_path, "det-dark", "low_light"),
    }


@pytest.fixture
def registry(models: dict[str, tuple[Path, str]]) -> ModelRegistry:
    reg = ModelRegistry(loader=fake_loader())
    reg.add(id="det-default", domain="default", file=models["det-default"][0],
            sha256=models["det-default"][1], metrics={"f1": 0.96})  # fmt: skip
    reg.add({"id": "det-fog", "domain": "fog", "file": models["det-fog"][0], "sha256": None})
    reg.add(ModelSpec(id="det-dark", domain="low_light", file=models["det-dark"][0]))
    return reg


# -- built in code ----------------------------------------------------------------------------


def test_resolve_by_id_by_domain_and_default(registry: ModelRegistry) -> None:
    assert registry.ids() == ["det-default", "det-fog", "det-dark"]
    assert registry.domains() == ["default", "fog", "low_light"]
    assert registry.resolve("det-fog").domain == "fog"
    assert registry.resolve(domain="low_light").id == "det-dark"
    assert registry.resolve().id == registry.default.id == "det-default"
    assert registry.resolve("det-fog", "fog").id == "det-fog"
    assert len(registry) == 3 and "det-fog" in registry and "nope" not in registry
    assert [m.id for m in registry] == registry.ids()


def test_unknown_names_list_what_exists(registry: ModelRegistry) -> None:
    with pytest.raises(UnknownModelError, match="unknown model 'det-snow'") as info:
        registry.resolve("det-snow")
    assert "det-default (default), det-fog (fog), det-dark (low_light)" in str(info.value)
    with pytest.raises(UnknownModelError, match="no model for domain 'snow'") as info:
        registry.resolve(domain="snow")
    assert "default, fog, low_light" in str(info.value)
    with pytest.raises(ModelRegistryError, match="is for domain 'fog', not 'default'"):
        registry.resolve("det-fog", "default")
    assert isinstance(info.value, AnunnakiError) and isinstance(info.value, LookupError)
    with pytest.raises(UnknownModelError, match="domains with a model: none"):
        ModelRegistry().default  # noqa: B018


def test_bad_entries_in_code_are_refused(tmp_path: Path) -> None:
    reg = ModelRegistry()
    reg.add(id="a", domain="default", file=tmp_path / "a")
    with pytest.raises(ModelRegistryError, match="'a' is registered twice"):
        reg.add(id="a", domain="fog", file=tmp_path / "b")
    with pytest.raises(ModelRegistryError, match="domain"):
        reg.add(id="b", domain="heavy fog", file=tmp_path / "b")
    with pytest.raises(ModelRegistryError, match="sha256 must be 64"):
        reg.add(id="b", domain="fog", file=tmp_path / "b", sha256="abc")
    with pytest.raises(ModelRegistryError, match="model id"):
        reg.add(id="-b", domain="fog", file=tmp_path / "b")
    spec = reg.add(id="c", domain="fog", file=tmp_path / "c", sha256="AB" * 32)
    assert spec.sha256 == "ab" * 32  # normalised
    with pytest.raises(ModelRegistryError, match="'c' and 'd' both serve domain 'fog'"):
        reg.add(id="d", domain="fog", file=tmp_path / "d")  # a swap to fog would be ambiguous
    assert reg.ids() == ["a", "c"] and reg.for_domain("fog").id == "c"


@pytest.mark.parametrize(
    ("metrics", "expected"),
    [
        ({"f1": 0.9}, 0.9),
        ({"clean": {"f1": 0.8}, "test": {"f1": 0.7}}, 0.8),
        ({"test": {"f1": 0.7}, "val": {"f1": 0.6}}, 0.7),
        ({"val": {"f1": 0.6}}, 0.6),
        ({"f1": "high", "val": {"precision": 1.0}}, None),
        ({"f1": True}, None),
        ({}, None),
    ],
)
def test_clean_f1_lookup_order(tmp_path: Path, metrics: dict[str, Any], expected: Any) -> None:
    spec = ModelSpec(id="m", domain="default", file=tmp_path / "m", metrics=metrics)
    assert spec.clean_f1 == expected
    assert ModelRegistry([spec]).clean_f1("m") == expected
    assert ModelRegistry([spec]).clean_f1("other") is None


# -- integrity ------------------------------------------------------------------------------


def test_load_verifies_the_hash_before_the_loader_runs(
    registry: ModelRegistry, models: dict[str, tuple[Path, str]]
) -> None:
    calls: list[Path] = []
    registry._loader = fake_loader(calls)
    det = registry.load("det-default")
    assert det.model_id == "det-default" and calls == [models["det-default"][0]]
    # Same length, different bytes: refused before the loader sees the file.
    path = models["det-default"][0]
    path.write_text(path.read_text().replace("default", "defaulT"), encoding="utf-8")
    with pytest.raises(ModelIntegrityError, match="sha256 mismatch") as info:
        registry.load("det-default")
    assert "the registry says" in str(info.value) and len(calls) == 1


def test_missing_file_and_corrupt_file_are_refused(
    registry: ModelRegistry, models: dict[str, tuple[Path, str]]
) -> None:
    models["det-dark"][0].unlink()
    with pytest.raises(ModelIntegrityError, match="cannot read"):
        registry.load("det-dark")
    models["det-fog"][0].write_bytes(b"\x00garbage")  # no hash stated: the loader decides
    with pytest.raises(ModelLoadError, match="the loader refused") as info:
        registry.load("det-fog")
    assert isinstance(info.value.__cause__, ValueError)


def test_a_loader_that_returns_no_detector_is_refused(tmp_path: Path) -> None:
    path, digest = write_model(tmp_path, "m", "default")
    reg = ModelRegistry([{"id": "m", "domain": "default", "file": path, "sha256": digest}],
                        loader=lambda p: object())  # fmt: skip
    with pytest.raises(ModelLoadError, match="no detect"):
        reg.load("m")


# -- files ------------------------------------------------------------------------------------

REGISTRY = """\
anunnaki: models/1
lec: detector
description: Two models of the UAV's detector.
models:
  - id: det-default
    domain: default
    file: det-default.model
    sha256: {default_sha}
    metrics: {{f1: 0.96}}
  - id: det-fog
    domain: fog
    file: det-fog.model
    description: Robust to fog (Enki).
"""


def test_load_a_registry_file(tmp_path: Path, models: dict[str, tuple[Path, str]]) -> None:
    path = tmp_path / "registry.yaml"
    path.write_text(REGISTRY.format(default_sha=models["det-default"][1].upper()))
    reg = load_registry(path, loader=fake_loader())
    assert reg.lec == "detector" and reg.ids() == ["det-default", "det-fog"]
    default = reg.resolve()
    assert default.file == models["det-default"][0]  # relative to the registry file
    assert default.sha256 == models["det-default"][1]
    assert default.clean_f1 == 0.96
    assert reg.get("det-fog").description == "Robust to fog (Enki)."
    assert reg.load(domain_spec := reg.resolve(domain="fog")).model_id == domain_spec.id


@pytest.mark.parametrize(
    ("edit", "line", "message"),
    [
        (lambda t: t.replace("models/1", "models/2"), 1, "not a model registry"),
        (lambda t: t.replace("    domain: fog\n", "    domain: fog\n    colour: red\n"), 12,
         "unknown field 'colour'"),
        (lambda t: t.replace("file: det-fog.model", "file: nowhere.model"), 12,
         "model file 'nowhere.model' not found"),
        (lambda t: t.replace("id: det-fog", "id: det-default"), 10, "used twice"),
        (lambda t: t.replace("domain: fog", "domain: default"), 11,
         r"models\[0\] \('det-default'\) and models\[1\] \('det-fog'\) both serve domain "
         "'default'"),
        (lambda t: t.replace("domain: default", "domain: clear"), 4, "no model for the domain"),
        (lambda t: t.replace("domain: fog", "domain: heavy-fog"), 11, "must be an identifier"),
        (lambda t: t.replace("domain: fog", "domain: fog/../x"), 11,
         r"domain 'fog/\.\./x' is not allowed: a domain must be an identifier"),
        (lambda t: t.replace("id: det-fog", "id: ../det-fog"), 10,
         r"model id '\.\./det-fog' is not allowed: a name is 1 to 128 characters"),
        (lambda t: t.replace("id: det-fog", "id: /tmp/det-fog"), 10, "is not allowed: a name"),
        (lambda t: t.replace("id: det-fog", 'id: "det\\\\fog"'), 10, "is not allowed: a name"),
        (lambda t: t.replace("id: det-fog", 'id: "det\\0fog"'), 10, "is not allowed: a name"),
        (lambda t: t.replace("    domain: fog\n", ""), 10, "missing required field 'domain'"),
        (lambda t: t.replace("- id: det-fog", "- id:"), 10, "missing required field 'id'"),
        (lambda t: t.replace("metrics: {f1: 0.96}", "metrics: [1]"), 9, "valid dictionary"),
        (lambda t: t.replace("lec: detector", "lec: detector\nx: 1"), 3, "unknown field 'x'"),
        (lambda t: t.replace("lec: detector", "lec: [detector]"), 2, "valid string"),
    ],
)  # fmt: skip
def test_registry_file_errors_name_file_and_line(
    tmp_path: Path, models: dict[str, tuple[Path, str]], edit: Any, line: int, message: str
) -> None:
    text = edit(REGISTRY.format(default_sha=models["det-default"][1]))
    path = tmp_path / "registry.yaml"
    path.write_text(text)
    with pytest.raises(ModelFileError, match=message) as info:
        load_registry(path, loader=fake_loader())
    assert info.value.path == str(path)
    assert info.value.line == line, str(info.value)


def test_parse_registry_resolves_against_base(
    tmp_path: Path, models: dict[str, tuple[Path, str]]
) -> None:
    text = REGISTRY.format(default_sha=models["det-default"][1])
    reg = parse_registry(text, source="mem.yaml", base=tmp_path, loader=fake_loader())
    assert reg.source == "mem.yaml" and reg.get("det-fog").file == tmp_path / "det-fog.model"
    with pytest.raises(ModelFileError, match="YAML anchor"):
        parse_registry("anunnaki: models/1\nmodels: &a [*a]\n", base=tmp_path)


# -- real model files ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def real_models(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from anunnaki.lec._centernet import CenterNetDetector
    from anunnaki.lec._detector import save_detector

    folder = tmp_path_factory.mktemp("models")
    for model_id, domain, f1 in (("uav-default", "default", 0.93), ("uav-fog", "fog", 0.88)):
        det = CenterNetDetector.create(
            ("person", "car"), input_size=(64, 64), width=8, model_id=model_id, domain=domain
        )
        det.metrics = {"test": {"f1": f1, "precision": 0.9}}
        save_detector(det, folder / f"{model_id}.safetensors")
    return folder


def test_real_models_take_id_domain_and_metrics_from_their_sidecar(real_models: Path) -> None:
    pins = {n: sha256_file(real_models / f"{n}.safetensors") for n in ("uav-default", "uav-fog")}
    (real_models / "registry.yaml").write_text(
        "anunnaki: models/1\nmodels:\n"
        f"  - file: uav-default.safetensors\n    sha256: {pins['uav-default']}\n"
        f"  - file: uav-fog.safetensors\n    sha256: {pins['uav-fog']}\n    metrics: {{f1: 0.9}}\n"
    )
    reg = load_registry(real_models / "registry.yaml")
    assert [(m.id, m.domain) for m in reg] == [("uav-default", "default"), ("uav-fog", "fog")]
    assert reg.clean_f1("uav-default") == 0.93  # test.f1 from the sidecar
    assert reg.clean_f1("uav-fog") == 0.9  # the registry overrides
    det = reg.load("uav-fog")  # the default loader: anunnaki.lec.load_detector
    assert det.domain == "fog" and det.classes == ("person", "car")
    assert callable(det.detect)


def test_tampered_weights_are_refused_by_registry_and_by_sidecar(
    real_models: Path, tmp_path: Path
) -> None:
    import shutil

    for name in ("uav-default.safetensors", "uav-default.json"):
        shutil.copy(real_models / name, tmp_path / name)
    weights = tmp_path / "uav-default.safetensors"
    digest = hashlib.sha256(weights.read_bytes()).hexdigest()
    registry = tmp_path / "registry.yaml"
    registry.write_text(
        f"anunnaki: models/1\nmodels:\n  - file: uav-default.safetensors\n    sha256: {digest}\n"
    )
    pinned = load_registry(registry)
    data = bytearray(weights.read_bytes())
    data[-1] ^= 0xFF
    weights.write_bytes(bytes(data))
    with pytest.raises(ModelIntegrityError, match="sha256 mismatch"):
        pinned.load("uav-default")
    registry.write_text("anunnaki: models/1\nmodels:\n  - file: uav-default.safetensors\n")
    with pytest.raises(ModelFileError, match="missing sha256") as info:
        load_registry(registry)  # a registry pins what it loads; the hint gives the digest
    assert info.value.line == 3 and sha256_file(weights) in str(info.value)
    with pytest.raises(DetectorLoadError, match="sha256 mismatch"):
        load_detector(weights)  # and the sidecar's own hash catches it too


def test_a_pinned_file_whose_sidecar_names_other_weights_is_refused(
    real_models: Path, tmp_path: Path
) -> None:
    """Issue 34 item 2: the registry pins uav-default.safetensors, and its sidecar, edited,
    names uav-fog.safetensors (with that file's hash): the unpinned file was loaded."""
    import json
    import shutil

    for name in ("uav-default", "uav-fog"):
        for suffix in (".safetensors", ".json"):
            shutil.copy(real_models / f"{name}{suffix}", tmp_path / f"{name}{suffix}")
    pinned = tmp_path / "uav-default.safetensors"
    (tmp_path / "registry.yaml").write_text(
        "anunnaki: models/1\nmodels:\n  - file: uav-default.safetensors\n"
        f"    sha256: {sha256_file(pinned)}\n"
    )
    card = json.loads((tmp_path / "uav-default.json").read_text())
    card.update(weights="uav-fog.safetensors", sha256=sha256_file(tmp_path / "uav-fog.safetensors"))
    (tmp_path / "uav-default.json").write_text(json.dumps(card))
    reg = load_registry(tmp_path / "registry.yaml")
    with pytest.raises(ModelLoadError, match=r"names the weights 'uav-fog\.safetensors', not "
                       r"'uav-default\.safetensors'") as info:  # fmt: skip
        reg.load("uav-default")
    assert "uav-default.json" in str(info.value)


def test_a_bad_sidecar_is_reported_at_the_registry_line(real_models: Path, tmp_path: Path) -> None:
    (tmp_path / "m.safetensors").write_bytes(b"weights")
    (tmp_path / "m.json").write_text("{not json")
    (tmp_path / "r.yaml").write_text(
        "anunnaki: models/1\nmodels:\n  - id: m\n    domain: default\n    file: m.safetensors\n"
    )
    with pytest.raises(ModelFileError, match="sidecar is unreadable") as info:
        load_registry(tmp_path / "r.yaml")
    assert info.value.line == 5
    # A third-party loader may keep its own .json next to the weights.
    reg = load_registry(tmp_path / "r.yaml", loader=fake_loader())
    assert reg.ids() == ["m"]


@pytest.mark.parametrize("where", ["dotdot", "absolute", "symlink"])
def test_a_registry_refuses_model_files_outside_its_folder(
    real_models: Path, tmp_path: Path, where: str
) -> None:
    folder = tmp_path / "registry"
    folder.mkdir()
    outside = real_models / "uav-default.safetensors"
    named = {
        "dotdot": os.path.relpath(outside, folder),
        "absolute": str(outside),
        "symlink": "linked.safetensors",
    }[where]
    if where == "symlink":
        (folder / "linked.safetensors").symlink_to(outside)
        (folder / "linked.json").symlink_to(outside.with_suffix(".json"))
    (folder / "r.yaml").write_text(
        f"anunnaki: models/1\nmodels:\n  - file: {named}\n    sha256: {sha256_file(outside)}\n"
    )
    with pytest.raises(ModelFileError, match="outside the registry's folder") as info:
        load_registry(folder / "r.yaml")
    assert info.value.line == 3 and "models[0].file" in str(info.value)


def test_non_finite_weights_are_refused(real_models: Path, tmp_path: Path) -> None:
    import json

    import numpy as np
    from safetensors.numpy import load_file, save_file

    tensors = load_file(str(real_models / "uav-default.safetensors"))
    name = next(k for k, v in tensors.items() if v.dtype.kind == "f")
    tensors[name] = np.full_like(tensors[name], np.nan)
    weights = tmp_path / "uav-default.safetensors"
    save_file(tensors, str(weights))
    card = json.loads((real_models / "uav-default.json").read_text())
    card["sha256"] = sha256_file(weights)  # a consistent pair: only the values are wrong
    (tmp_path / "uav-default.json").write_text(json.dumps(card))
    with pytest.raises(DetectorLoadError, match="non-finite") as info:
        load_detector(weights)
    assert name in str(info.value)


def test_an_over_deep_sidecar_is_a_clean_error(real_models: Path, tmp_path: Path) -> None:
    weights = tmp_path / "m.safetensors"
    weights.write_bytes((real_models / "uav-default.safetensors").read_bytes())
    for depth in (100, 100_000):  # within and beyond the JSON parser's own recursion limit
        (tmp_path / "m.json").write_text("[" * depth + "]" * depth)
        with pytest.raises(DetectorLoadError, match="nested"):
            load_detector(weights)
