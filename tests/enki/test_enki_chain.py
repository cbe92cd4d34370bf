"""``anunnaki robustify`` end to end on tiny data: JSON, sidecar, oracle, registry, resume."""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from enki_helpers import TINY as _TINY
from enki_helpers import argv

pytest.importorskip("torch")

from anunnaki.cli.main import build_parser, main
from anunnaki.enki import archive_sha256, robustify
from anunnaki.enlil import load_oracle, read_archive
from anunnaki.lec import (
    ModelRegistryError,
    load_detector,
    load_registry,
    read_card,
    register_model,
    sha256_file,
)

MODELS = Path(__file__).resolve().parents[2] / "examples" / "models"
ALL_STAGES = ["search", "select", "finetune", "measure", "assess", "oracle"]


def _run(args: list[str]) -> dict[str, Any]:
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main([*args, "--json"]) == 0
    result: dict[str, Any] = json.loads(printed.getvalue())
    return result


@pytest.fixture(scope="module")
def chain(rover_data: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """One chain run with --register into a copy of examples/models; hashes before and after.

    The new model (``low_light``) takes the place of ``rover-low_light``, whose entry the copy
    drops first: one model serves each domain.
    """
    tmp = tmp_path_factory.mktemp("chain")
    models = tmp / "models"
    shutil.copytree(MODELS, models)
    model = models / "rover-default.safetensors"
    before = {p.name: sha256_file(p) for p in (model, model.with_suffix(".json"))}
    reg = models / "rover.yaml"
    head, *entries = reg.read_text(encoding="utf-8").split("\n  - id: ")
    kept = [e for e in entries if not e.startswith("rover-low_light\n")]
    assert len(kept) == len(entries) - 1
    reg.write_text(head + "".join("\n  - id: " + e for e in kept), encoding="utf-8")
    registry_before = reg.read_text(encoding="utf-8")
    summary = _run(argv(model, rover_data, tmp / "work", "--register", str(reg)))
    after = {p.name: sha256_file(p) for p in (model, model.with_suffix(".json"))}
    return {"summary": summary, "before": before, "after": after, "tmp": tmp,
            "model": model, "registry": reg, "data": rover_data,
            "registry_before": registry_before}  # fmt: skip


def test_the_chain_makes_a_model_its_sidecar_and_its_oracle(chain: dict[str, Any]) -> None:
    s = chain["summary"]
    assert s["model"]["model_id"] == "rover-enki" and s["model"]["domain"] == "low_light"
    assert s["reused_stages"] == []
    file = Path(s["model"]["file"])
    assert sha256_file(file) == s["model"]["sha256"]
    det = load_detector(file)
    assert det.domain == "low_light" and det.model_id == "rover-enki"
    card = read_card(file)
    enki = card.training["enki"]
    assert enki["phenomenon"] == "brightness" and enki["domain"] == "low_light"
    assert enki["archive"]["sha256"] == archive_sha256(s["archive"]["path"])
    assert enki["from"]["sha256"] == chain["before"]["rover-default.safetensors"]
    # the budget: 8 train images in batches of 4, 2 epochs
    assert enki["budget"]["epochs"] == 2 and enki["budget"]["steps"] == 4 == s["finetune"]["steps"]
    assert set(enki["seeds"]) == {"search", "finetune", "measure", "assess", "oracle"}
    assert sum(enki["selection"]["counts"]) == 4
    measured = card.metrics["enki"]
    assert measured["clean"]["split"] == "test" and 0.0 <= measured["clean"]["new"] <= 1.0
    # 3 of the 6 contexts: the 2 not trained on, and 1 trained on
    assert measured["archive_contexts"]["contexts"] == 3
    assert measured["archive_contexts"]["used_in_training"] == 1
    assert measured == s["metrics"]
    # Enlil assessed the new model, and its oracle is of the new model's weights
    assessed = read_archive(s["assessment"]["path"])
    assert assessed.meta.model_id == "rover-enki" and assessed.meta.sha256 == s["model"]["sha256"]
    oracle = load_oracle(s["oracle"]["file"], sha256=s["oracle"]["sha256"])
    assert oracle.model_id == "rover-enki"
    assert oracle.card.model_sha256 == s["model"]["sha256"]
    # its network by the per-phenomenon rule (brightness names none: small_cnn), recorded
    assert oracle.card.architecture == "small_cnn" == s["oracle"]["architecture"]
    assert oracle.card.training["config"]["architecture_from"] == "measured choice"
    assert s["oracle"]["options"]["architecture"] == "small_cnn"


def test_the_input_model_is_never_modified(chain: dict[str, Any]) -> None:
    assert chain["after"] == chain["before"]


def test_register_adds_entries_a_registry_loads(chain: dict[str, Any]) -> None:
    s, reg = chain["summary"], chain["registry"]
    registry = load_registry(reg)
    assert registry.verify("rover-enki") == s["model"]["sha256"]
    spec = registry.get("rover-enki")
    assert spec.domain == "low_light" and spec.oracle is not None
    assert spec.oracle.sha256 == s["oracle"]["sha256"]
    load_oracle(spec.oracle.file, sha256=spec.oracle.sha256)
    text = reg.read_text()
    assert text.startswith(chain["registry_before"].rstrip("\n"))  # the rest is kept
    shipped = load_registry(MODELS / "rover.yaml")
    others = [m.id for m in shipped if m.domain != "low_light"]
    assert registry.ids() == [*others, "rover-enki"] and registry.for_domain("low_light") == spec
    with pytest.raises(ModelRegistryError, match="registered already"):
        register_model(reg, s["model"]["file"], model_id="rover-enki")
    assert reg.read_text() == text
    # a copy of the shipped registry has its low_light model: a second one is refused
    copy = chain["tmp"] / "shipped"
    shutil.copytree(MODELS, copy)
    unchanged = (copy / "rover.yaml").read_text()
    with pytest.raises(ModelRegistryError, match="'rover-low_light' serves domain 'low_light'"):
        register_model(copy / "rover.yaml", s["model"]["file"], model_id="rover-enki")
    assert (copy / "rover.yaml").read_text() == unchanged


def test_a_rerun_continues_and_a_changed_option_is_refused(
    chain: dict[str, Any], capsys: pytest.CaptureFixture[str]
) -> None:
    work = chain["tmp"] / "work"
    again = _run(argv(chain["model"], chain["data"], work, "--register", str(chain["registry"])))
    assert again["reused_stages"] == ALL_STAGES
    assert again["model"] == chain["summary"]["model"]
    capsys.readouterr()
    changed = argv(chain["model"], chain["data"], work)
    changed[changed.index("--epochs") + 1] = "3"
    assert main(changed) == 2
    err = capsys.readouterr().err
    assert "finetune" in err and "epochs" in err and "another --out" in err


def test_resume_after_an_interruption_mid_fine_tune(chain: dict[str, Any]) -> None:
    """Ctrl-C in the fine-tune's second epoch; the rerun ends with the same weights."""
    from anunnaki.cli._robustify import _config

    work = chain["tmp"] / "resumed"
    args = build_parser().parse_args(
        argv(chain["model"], chain["data"], work, "--archive", chain["summary"]["archive"]["path"])
    )
    config = _config(args)
    assert "--threads" in _TINY

    def interrupt(stage: str, done: int, total: int) -> None:
        if stage.startswith("fine-tune, epoch 2"):
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        robustify(chain["model"], chain["data"], work, config, progress=interrupt)
    assert [p.name for p in (work / "finetune").glob("epoch-*.pt")] == ["epoch-001.pt"]
    assert not (work / "stages" / "finetune.json").exists()
    summary = robustify(chain["model"], chain["data"], work, config)
    assert summary["reused_stages"] == ["search", "select"]
    assert summary["model"]["sha256"] == chain["summary"]["model"]["sha256"]
    assert summary["metrics"] == chain["summary"]["metrics"]


def test_the_recipe_options_parse_and_only_a_changed_recipe_is_recorded(tmp_path: Path) -> None:
    from anunnaki.cli._robustify import _config

    model = MODELS / "rover-default.safetensors"
    default = _config(build_parser().parse_args(argv(model, tmp_path, tmp_path / "w")))
    assert (default.source, default.k, default.consistency, default.finetune.ema) == (
        "archive", 1, 0.0, 0.0,
    )  # fmt: skip
    assert "recipe" not in default.options()  # folders made before the recipe continue
    assert "ema" not in default.options()["finetune"]
    more = ["--source", "archive_mix", "--k", "3", "--select", "random", "--share", "0.4",
            "--jitter", "0.05", "--consistency", "0.5", "--ema", "0.9"]  # fmt: skip
    config = _config(build_parser().parse_args(argv(model, tmp_path, tmp_path / "w", *more)))
    assert config.recipe() == {"source": "archive_mix", "k": 3, "select": "random",
                               "share": 0.4, "jitter": 0.05, "consistency": 0.5,
                               "ema": 0.9}  # fmt: skip
    assert config.options()["recipe"] == config.recipe()


def test_a_recipe_fine_tune_records_its_forward_passes(chain: dict[str, Any]) -> None:
    """archive_mix, worst-of-2, consistency and EMA: the fine-tune stage reports its spending."""
    from anunnaki.cli._robustify import _config

    work = chain["tmp"] / "recipe"
    more = ["--archive", chain["summary"]["archive"]["path"], "--source", "archive_mix",
            "--k", "2", "--consistency", "0.5", "--ema", "0.9", "--epochs", "1"]  # fmt: skip
    config = _config(build_parser().parse_args(argv(chain["model"], chain["data"], work, *more)))

    def stop(stage: str, done: int, total: int) -> None:
        if stage.startswith("measure"):
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        robustify(chain["model"], chain["data"], work, config, progress=stop)
    tuned = json.loads((work / "stages" / "finetune.json").read_text("utf-8"))
    assert tuned["steps"] == 2 and tuned["train_forwards"] == 8
    assert tuned["select_forwards"] == tuned["candidates"] > 0
    assert tuned["consistency_forwards"] > 0
    assert tuned["source"]["kind"] == "worst_of_k"
    assert tuned["source"]["inner"]["kind"] == "archive_mix"
    card = read_card(tuned["file"]).training
    assert card["enki"]["recipe"]["source"] == "archive_mix" and card["ema"] == 0.9
    assert card["enki"]["budget"]["select_forwards"] == tuned["select_forwards"]
    assert json.loads((work / "robustify.json").read_text("utf-8"))["options"]["recipe"]["k"] == 2


def test_kill_9_mid_fine_tune_then_the_same_command_continues(chain: dict[str, Any]) -> None:
    """kill -9 once a fine-tune checkpoint is on disk; the rerun matches a straight run."""

    def args(out: Path) -> list[str]:
        a = argv(
            chain["model"], chain["data"], out, "--archive", chain["summary"]["archive"]["path"]
        )
        a[a.index("--epochs") + 1] = "12"
        return a

    out = chain["tmp"] / "killed"
    cmd = [sys.executable, "-m", "anunnaki", *args(out), "--json"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while not list((out / "finetune").glob("epoch-*.pt")):
            assert proc.poll() is None, "robustify ended before it could be killed"
            assert time.monotonic() < deadline, "no fine-tune checkpoint in 120 s"
            time.sleep(0.05)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert not (out / "stages" / "finetune.json").exists()
    resumed = _run(args(out))
    assert resumed["reused_stages"] == ["search", "select"]
    straight = _run(args(chain["tmp"] / "straight"))
    assert resumed["model"]["sha256"] == straight["model"]["sha256"]
    assert resumed["finetune"]["steps"] == straight["finetune"]["steps"] == 24


def test_the_oracle_network_follows_the_per_phenomenon_rule(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from types import MappingProxyType

    from anunnaki.enki import RobustifyConfig
    from anunnaki.enlil import _oracle_choice, oracle_architecture

    # a measured choice in the table (today's is empty: every oracle small_cnn)
    table = MappingProxyType({"hsl": "patch_cnn"})
    monkeypatch.setattr(_oracle_choice, "PHENOMENON_ARCHITECTURES", table)

    for phenomenon in ("hsl", "raindrop+raindrop+raindrop", "fog", "brightness"):
        options = RobustifyConfig(phenomenon=phenomenon, domain="d").oracle_options()
        assert options["architecture"] == oracle_architecture([phenomenon])
    assert RobustifyConfig("hsl", "hsl").oracle_options()["architecture"] == "patch_cnn"
    assert RobustifyConfig("fog", "fog").oracle_options()["architecture"] == "small_cnn"
    # a model with a measured choice of its own gets it (an Enki model's id has none)
    fog = RobustifyConfig("fog", "fog")
    assert fog.oracle_options("rover-default")["architecture"] == "patch_cnn"
    assert fog.oracle_options("rover-fog-enki")["architecture"] == "small_cnn"
    given = RobustifyConfig("hsl", "hsl", oracle_architecture="small_cnn", oracle={"epochs": 2})
    assert given.oracle_options() == {"epochs": 2, "architecture": "small_cnn"}
    # the oracle's options are its stage's own, not the work folder's
    assert "oracle" not in given.options() and "oracle_architecture" not in given.options()


def test_another_oracle_network_trains_the_oracle_again_and_nothing_else(
    chain: dict[str, Any], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    work = tmp_path / "work"
    shutil.copytree(chain["tmp"] / "work", work)
    first = chain["summary"]
    again = _run([*argv(chain["model"], chain["data"], work), "--oracle-architecture", "patch_cnn"])
    assert again["rerun_stages"] == ["oracle"]
    assert again["reused_stages"] == ALL_STAGES[:-1]
    assert again["model"] == first["model"] and again["metrics"] == first["metrics"]
    assert again["assessment"] == first["assessment"]
    oracle = load_oracle(again["oracle"]["file"], sha256=again["oracle"]["sha256"])
    assert oracle.card.architecture == "patch_cnn" == again["oracle"]["architecture"]
    assert oracle.card.training["config"]["architecture_from"] == "--oracle-architecture"
    assert oracle.card.model_sha256 == first["model"]["sha256"]
    # the registration of the earlier oracle is stale: dropped, so --register adds afresh
    assert not list((work / "stages").glob("register-*.json"))
    # the same options again: everything reused
    same = _run([*argv(chain["model"], chain["data"], work), "--oracle-architecture", "patch_cnn"])
    assert same["reused_stages"] == ALL_STAGES and same["rerun_stages"] == []
    assert same["oracle"]["sha256"] == again["oracle"]["sha256"]
    # a network nobody registered fails before any work, naming the registered ones
    capsys.readouterr()
    bad = [*argv(chain["model"], chain["data"], tmp_path / "new"), "--oracle-architecture", "x"]
    assert main(bad) == 2
    err = capsys.readouterr().err
    assert "--oracle-architecture 'x'" in err and "small_cnn" in err and "patch_cnn" in err
    assert not (tmp_path / "new").exists()


def test_a_folder_from_before_the_oracle_options_were_the_stage_s_own(
    chain: dict[str, Any], tmp_path: Path
) -> None:
    """robustify.json held ``oracle`` and stages/oracle.json no options: reused, or re-run."""
    work = tmp_path / "old"
    shutil.copytree(chain["tmp"] / "work", work)
    marker = work / "robustify.json"
    old = json.loads(marker.read_text())
    old["options"]["oracle"] = {"epochs": 1, "frames": 24, "threads": 1, "val_frames": 12}
    marker.write_text(json.dumps(old))
    stage = work / "stages" / "oracle.json"
    record = json.loads(stage.read_text())
    for key in ("options", "architecture"):
        del record[key]
    stage.write_text(json.dumps(record))
    reused = _run(argv(chain["model"], chain["data"], work))
    assert reused["reused_stages"] == ALL_STAGES and reused["rerun_stages"] == []
    rerun = _run([*argv(chain["model"], chain["data"], work), "--oracle-architecture", "patch_cnn"])
    assert rerun["rerun_stages"] == ["oracle"]
    assert rerun["oracle"]["architecture"] == "patch_cnn"


def test_a_second_opinion_gives_the_learnability_cap_its_second_model(
    chain: dict[str, Any],
) -> None:
    """Only the contexts the input model fails are measured again; both below: left out."""
    from dataclasses import replace

    import numpy as np

    from anunnaki.cli._robustify import _config
    from anunnaki.enki import SelectionRule

    archive = read_archive(chain["summary"]["archive"]["path"])
    f1 = np.sort(np.unique(archive.f1))
    assert len(f1) > 1  # a floor between two F1s: some contexts below it, some above
    floor = float((f1[0] + f1[1]) / 2)
    below = np.flatnonzero(archive.f1 < floor)
    work = chain["tmp"] / "second"
    more = ["--archive", chain["summary"]["archive"]["path"], "--second-opinion",
            str(MODELS / "rover-default.safetensors")]  # fmt: skip
    config = _config(build_parser().parse_args(argv(chain["model"], chain["data"], work, *more)))
    assert config.options()["second_opinion"] == str(MODELS / "rover-default.safetensors")
    config = replace(config, rule=SelectionRule(contexts=4, weights=(1, 3, 3), learnable=floor))
    seen: list[str] = []

    def stop(stage: str, done: int, total: int) -> None:
        seen.append(stage)
        if stage.startswith("fine-tune"):
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        robustify(chain["model"], chain["data"], work, config, progress=stop)
    picked = json.loads((work / "stages" / "select.json").read_text("utf-8"))
    # the second model is the input model's own file: it fails exactly where the input does
    assert picked["second_opinion"]["model_id"] == "rover-default"
    assert picked["second_opinion"]["measured"] == len(below)
    assert picked["unlearnable"] == below.tolist() and picked["cap"] == "applied"
    assert "learnability: rover-default" in seen
    # without it: one model, nothing left out, and no option recorded
    plain = _config(build_parser().parse_args(argv(chain["model"], chain["data"], work)))
    assert plain.second_opinion is None and "second_opinion" not in plain.options()
