"""``register_model``: an entry appended as text, hashes checked, the file kept or restored."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from anunnaki.errors import ModelFileError
from anunnaki.lec import (
    ModelRegistryError,
    load_registry,
    read_card,
    register_model,
    sha256_file,
)

MODELS = Path(__file__).resolve().parents[2] / "examples" / "models"
FOG = "rover-fog-enki"  # the rover's shipped fog model


def _model(folder: Path, name: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for suffix in (".safetensors", ".json"):
        shutil.copy(MODELS / f"{name}{suffix}", folder / f"{name}{suffix}")
    return folder / f"{name}.safetensors"


def test_an_entry_goes_at_the_end_of_the_models_block_and_the_rest_is_kept(
    tmp_path: Path,
) -> None:
    default = _model(tmp_path / "reg", "rover-default")
    reg = tmp_path / "reg" / "models.yaml"
    text = (
        "# my registry\nanunnaki: models/1\nlec: detector\nmodels:\n"
        "    - id: rover-default   # the start\n      domain: default\n"
        f"      file: rover-default.safetensors\n      sha256: {sha256_file(default)}\n"
        "\n# the end\ndescription: kept after the list\n"
    )
    reg.write_text(text)
    fog = _model(tmp_path / "elsewhere", FOG)
    oracle = _model(tmp_path / "elsewhere", f"{FOG}.oracle")
    spec = register_model(reg, fog, oracle=oracle, description='fog: "thick"')
    assert spec.id == FOG == read_card(fog).model_id and spec.domain == "fog"
    assert (tmp_path / "reg" / f"{FOG}.safetensors").is_file()  # copied in, sidecar too
    assert (tmp_path / "reg" / f"{FOG}.oracle.json").is_file()
    new = reg.read_text()
    assert new.startswith(
        text.split("\n# the end", maxsplit=1)[0].rstrip("\n") + f"\n    - id: {FOG}\n"
    )
    assert new.endswith("\n# the end\ndescription: kept after the list\n")
    registry = load_registry(reg)
    assert registry.verify(FOG) == sha256_file(fog)
    assert registry.get(FOG).oracle is not None
    assert registry.get(FOG).description == 'fog: "thick"'


def test_a_new_registry_starts_from_its_default_model(tmp_path: Path) -> None:
    reg = tmp_path / "new" / "reg.yaml"
    fog = _model(tmp_path / "m", FOG)
    with pytest.raises(ModelRegistryError, match="no model registry there"):
        register_model(reg, fog)
    with pytest.raises(ModelFileError, match="no model for the domain 'default'"):
        register_model(reg, fog, create=True)
    assert not reg.exists()  # nothing half-written stays
    register_model(reg, _model(tmp_path / "m", "rover-default"), create=True)
    register_model(reg, fog)
    assert load_registry(reg).ids() == ["rover-default", FOG]


def test_refusals_leave_the_registry_as_it_was(tmp_path: Path) -> None:
    reg = tmp_path / "reg" / "r.yaml"
    register_model(reg, _model(tmp_path / "m", "rover-default"), create=True)
    before = reg.read_text()
    with pytest.raises(ModelRegistryError, match=r"r\.yaml:4: a model with id 'rover-default'"):
        register_model(reg, _model(tmp_path / "m", "rover-default"))
    # another file of the same name already in the registry's folder
    other = _model(tmp_path / "m2", FOG)
    (tmp_path / "reg" / f"{FOG}.safetensors").write_bytes(b"not this one")
    with pytest.raises(ModelRegistryError, match="another model file of this name"):
        register_model(reg, other)
    inline = tmp_path / "reg" / "inline.yaml"
    sha = sha256_file(tmp_path / "reg" / "rover-default.safetensors")
    entry = (
        f"{{id: rover-default, domain: default, file: rover-default.safetensors, sha256: {sha}}}"
    )
    inline.write_text(f"anunnaki: models/1\nlec: detector\nmodels: [{entry}]\n")
    with pytest.raises(ModelRegistryError, match="written inline"):
        register_model(inline, _model(tmp_path / "m3", "rover-low_light"))
    assert not (tmp_path / "reg" / "rover-low_light.safetensors").exists()  # nothing copied
    assert reg.read_text() == before


def test_a_second_model_for_a_served_domain_is_refused(tmp_path: Path) -> None:
    reg = tmp_path / "reg" / "r.yaml"
    register_model(reg, _model(tmp_path / "m", "rover-default"), create=True)
    register_model(reg, _model(tmp_path / "m", FOG))
    before = reg.read_text()
    with pytest.raises(ModelRegistryError, match=f"'{FOG}' serves domain 'fog' already") as info:
        register_model(reg, _model(tmp_path / "m", "rover-hsl"), domain="fog")
    assert "remove that entry first" in str(info.value)
    assert reg.read_text() == before
    assert not (tmp_path / "reg" / "rover-hsl.safetensors").exists()  # nothing copied
    register_model(reg, _model(tmp_path / "m", "rover-hsl"))  # its own domain: welcome
    assert load_registry(reg).for_domain("hsl").id == "rover-hsl"


@pytest.mark.parametrize(
    ("field", "value"),
    [("model_id", "../x"), ("model_id", "a\nb"), ("model_id", "/tmp/x"), ("model_id", "a\\b"),
     ("model_id", "a\x00b"), ("domain", "fog/../x y"), ("domain", "heavy-fog")],
)  # fmt: skip
def test_an_id_or_domain_that_is_no_name_is_refused_before_the_registry_is_touched(
    tmp_path: Path, field: str, value: str
) -> None:
    """An id becomes an entry's text and a file name: a line break would even add an entry."""
    reg = tmp_path / "reg" / "r.yaml"
    register_model(reg, _model(tmp_path / "m", "rover-default"), create=True)
    before = reg.read_text()
    what = "model id" if field == "model_id" else "domain"
    with pytest.raises(ModelRegistryError, match=f"^{what} .* is not allowed"):
        register_model(reg, _model(tmp_path / "m", FOG), **{field: value})
    assert reg.read_text() == before
    assert sorted(p.name for p in (tmp_path / "reg").iterdir()) == [
        "r.yaml", "rover-default.json", "rover-default.safetensors"]  # fmt: skip
