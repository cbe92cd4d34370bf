"""Bad input to ``anunnaki robustify``: the error names the thing and the fix."""

from __future__ import annotations

from pathlib import Path

import pytest
from enki_helpers import argv

pytest.importorskip("torch")

import numpy as np

from anunnaki.cli.main import main
from anunnaki.enlil import ArchiveMeta, ArchiveWriter, ContextResult


def _fails(args: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    assert main(args) == 2
    return capsys.readouterr().err


def _archive(path: Path, *, phenomenon: str, params: tuple[str, ...], sha: str) -> Path:
    meta = ArchiveMeta(
        model_id="rover-default", sha256=sha, dataset="d", split="val", phenomenon=phenomenon,
        param_names=params, seed=0, thresholds=(0.05, 0.10), budget=2, search="sobol",
        batch_images=4, clean_f1=0.9,
    )  # fmt: skip
    writer = ArchiveWriter(path, meta)
    results = [ContextResult(np.full(len(params), v), 0.5, 0.4, 2) for v in (0.2, 0.8)]
    writer.append(0, 0, results)
    return path


def test_an_unknown_phenomenon(
    models: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = argv(models / "rover-default.safetensors", tmp_path, tmp_path / "w")
    args[args.index("brightness")] = "fgo"
    err = _fails(args, capsys)
    assert "--phenomenon fgo" in err and "fog" in err  # the valid names are listed


def test_missing_data(models: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    err = _fails(argv(models / "rover-default.safetensors", tmp_path / "nope", tmp_path / "w"),
                 capsys)  # fmt: skip
    assert f"--data {tmp_path / 'nope'}" in err and "make-dataset" in err
    (tmp_path / "empty").mkdir()
    err = _fails(argv(models / "rover-default.safetensors", tmp_path / "empty", tmp_path / "w"),
                 capsys)  # fmt: skip
    assert "no readable train split" in err


def test_an_archive_of_another_phenomenon_or_model(
    models: Path, rover_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from anunnaki.lec import sha256_file

    model = models / "rover-default.safetensors"
    fog = _archive(tmp_path / "fog", phenomenon="fog", params=("density",), sha=sha256_file(model))
    err = _fails([*argv(model, rover_data, tmp_path / "w1"), "--archive", str(fog)], capsys)
    assert f"--archive {fog}" in err and "search of fog, not of --phenomenon brightness" in err
    other = _archive(tmp_path / "other", phenomenon="brightness", params=("gain", "gamma"),
                     sha=sha256_file(models / "rover-fog-enki.safetensors"))  # fmt: skip
    err = _fails([*argv(model, rover_data, tmp_path / "w2"), "--archive", str(other)], capsys)
    assert f"--archive {other}" in err and "not " + str(model) in err
    assert "leave --archive out" in err
    err = _fails([*argv(model, rover_data, tmp_path / "w3"), "--archive", str(tmp_path / "x")],
                 capsys)  # fmt: skip
    assert str(tmp_path / "x") in err and "no archive here" in err


def test_a_registry_that_would_refuse_the_model_fails_before_any_work(
    models: Path, rover_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    reg = models / "rover.yaml"
    before = reg.read_text(encoding="utf-8")
    model = models / "rover-default.safetensors"
    # the copy of the shipped registry has a low_light model: one model per domain
    err = _fails([*argv(model, rover_data, tmp_path / "w1"), "--register", str(reg)], capsys)
    assert f"--register {reg}: 'rover-low_light' serves domain 'low_light' already" in err
    assert "remove that entry first to register 'rover-enki' in its place" in err
    taken = [*argv(model, rover_data, tmp_path / "w2"), "--register", str(reg)]
    taken[taken.index("low_light")] = "dusk"
    taken[taken.index("rover-enki")] = "rover-hsl"
    err = _fails(taken, capsys)
    assert "a model with id 'rover-hsl' is registered already" in err and "--id NAME" in err
    assert reg.read_text(encoding="utf-8") == before
    for work in (tmp_path / "w1", tmp_path / "w2"):  # no stage ran
        assert not list(work.glob("stages/*.json"))


#: Names that would put the new model's files elsewhere than the work folder (issue 34 item 1).
NO_NAMES = ["fog/../x y", "../x", "/tmp/x", "a/b", "a\\b", "a\x00b", "", ".."]


@pytest.mark.parametrize("option", ["--domain", "--id"])
@pytest.mark.parametrize("value", NO_NAMES)
def test_a_domain_or_an_id_that_is_no_name_is_refused_before_any_work(
    models: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], option: str, value: str
) -> None:
    """``--domain 'fog/../x y'`` ran the chain and wrote OUT/rover-fog/../x y.safetensors."""
    args = argv(models / "rover-default.safetensors", tmp_path / "data", tmp_path / "w")
    args[args.index(option) + 1] = value
    err = _fails(args, capsys)
    rule = "a domain must be an identifier" if option == "--domain" else "a name is 1 to 128"
    assert err.startswith(f"error: {option} {value!r} is not allowed: {rule}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["models"]  # nothing written


def test_an_id_made_from_the_models_own_id_is_checked_too(
    models: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Without --id the new id is MODEL_ID-DOMAIN, and a sidecar's id can be anything."""
    import json

    sidecar = models / "rover-default.json"
    card = json.loads(sidecar.read_text())
    sidecar.write_text(json.dumps(card | {"model_id": "../../evil"}))
    args = argv(models / "rover-default.safetensors", tmp_path / "data", tmp_path / "w")
    del args[args.index("--id") : args.index("--id") + 2]
    err = _fails(args, capsys)
    assert "the new model's id (from model '../../evil' and domain 'low_light') " in err
    assert "'../../evil-low_light' is not allowed" in err and "--id NAME" in err
    out = argv(models / "rover-default.safetensors", tmp_path / "data", tmp_path / "w")
    del out[out.index("--out") : out.index("--out") + 2]  # the default --out is robustify/ID
    del out[out.index("--id") : out.index("--id") + 2]
    assert "'../../evil-low_light' is not allowed" in _fails(out, capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["models"]


def test_the_library_refuses_them_as_the_command_does(models: Path, tmp_path: Path) -> None:
    from anunnaki.enki import EnkiError, RobustifyConfig, new_model_id, robustify

    for value in NO_NAMES:
        with pytest.raises(EnkiError, match=r"--domain .* is not allowed"):
            RobustifyConfig(phenomenon="fog", domain=value)
        with pytest.raises(EnkiError, match=r"--id .* is not allowed"):
            RobustifyConfig(phenomenon="fog", domain="fog", model_id=value)
        with pytest.raises(EnkiError, match=r"the new model's id .* is not allowed"):
            new_model_id(value, "fog")
    assert new_model_id("rover-default", "fog") == "rover-fog"
    config = RobustifyConfig(phenomenon="fog", domain="fog", model_id=None)
    text = (models / "rover-default.json").read_text()
    text = text.replace('"rover-default"', '"a/b"').replace("rover-default.", "x.")
    (models / "x.json").write_text(text)  # x.safetensors, whose own id is a/b
    (models / "x.safetensors").write_bytes((models / "rover-default.safetensors").read_bytes())
    with pytest.raises(EnkiError, match=r"'a/b-fog' is not allowed"):
        robustify(models / "x.safetensors", tmp_path / "data", tmp_path / "w", config)
    assert not (tmp_path / "w").exists()


def test_an_unknown_source_lists_the_valid_ones_before_any_work(
    models: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    work = tmp_path / "w"
    args = [*argv(models / "rover-default.safetensors", tmp_path, work), "--source", "archive-mix"]
    err = _fails(args, capsys)
    assert "--source archive-mix" in err
    assert "valid names: archive, archive_mix, corruption_mix, uniform" in err
    assert not work.exists()
    for bad, word in ((["--k", "0"], "--k"), (["--share", "2"], "--share"),
                      (["--ema", "1.5"], "ema")):  # fmt: skip
        err = _fails([*argv(models / "rover-default.safetensors", tmp_path, work), *bad], capsys)
        assert word in err
    with pytest.raises(SystemExit):  # argparse's own choices
        main([*argv(models / "rover-default.safetensors", tmp_path, work), "--select", "worst"])
    err = capsys.readouterr().err
    assert "--select: invalid choice: 'worst'" in err and "hardest" in err and "random" in err
