"""``anunnaki assess`` on a tiny rendered dataset with the shipped rover model; kill -9 resume."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from anunnaki.cli.main import main
from anunnaki.enlil import read_archive

MODEL = Path(__file__).resolve().parents[2] / "examples" / "models" / "rover-default.safetensors"


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    pytest.importorskip("pybullet")
    pytest.importorskip("ribs")
    out = tmp_path_factory.mktemp("assess") / "tiny"
    code = main(
        [
            "make-dataset", "rover", "--out", str(out), "--train-layouts", "0",
            "--val-layouts", "1", "--test-layouts", "2", "--per-layout", "4",
            "--width", "128", "--height", "128", "--workers", "1",
        ]
    )  # fmt: skip
    assert code == 0
    return out


def _args(tiny: Path, out: Path, budget: int) -> list[str]:
    return [
        "assess", str(MODEL), "--data", str(tiny), "--phenomenon", "brightness",
        "--budget", str(budget), "--search", "sobol", "--out", str(out), "--seed", "2",
        "--batch-images", "4", "--round", "2", "--workers", "1",
    ]  # fmt: skip


def test_assess_prints_a_summary_and_plots(
    tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("matplotlib")
    args = [*_args(tiny, tmp_path / "a", 6), "--json", "--plot", str(tmp_path / "png")]
    assert main(args) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["evaluations"] == 6 and summary["search"] == "sobol"
    assert sum(summary["counts"].values()) == 6
    assert all(Path(p).stat().st_size > 0 for p in summary["plots"])
    archive = read_archive(tmp_path / "a")
    assert archive.meta.model_id == "rover-default" and len(archive.meta.sha256) == 64


@pytest.mark.timeout(600)  # a new interpreter, torch and two rounds: minutes at load 25
def test_kill_9_then_resume_loses_and_repeats_nothing(tiny: Path, tmp_path: Path) -> None:
    out = tmp_path / "k"
    cmd = [sys.executable, "-m", "anunnaki", *_args(tiny, out, 40), "--json"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 300
        while len(list(out.glob("part-*.parquet"))) < 2:  # wait for two rounds on disk
            assert proc.poll() is None, "assess ended before it could be killed"
            assert time.monotonic() < deadline, "no round written in 300 s"
            time.sleep(0.05)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    partial = len(read_archive(out))
    assert 4 <= partial < 40
    assert main(_args(tiny, out, 40)) == 0
    resumed = read_archive(out)
    assert resumed.evals.tolist() == list(range(40))
    assert main(_args(tiny, tmp_path / "straight", 40)) == 0
    straight = read_archive(tmp_path / "straight")
    assert np.array_equal(resumed.params, straight.params)
    assert np.array_equal(resumed.f1, straight.f1)


def test_the_default_archive_folder_is_a_name_that_stays_in_assess(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Without --out the archive goes to assess/MODEL-P-SEARCH-sSEED: a --search (or a model
    file name) with '..' in it made that folder elsewhere (issue 34 item 1)."""
    from anunnaki.datasets import Dataset

    rng = np.random.default_rng(0)
    images = [rng.integers(0, 255, (64, 64, 3), dtype=np.uint8) for _ in range(2)]
    toy = Dataset.from_arrays(images, [[[8.0, 8.0, 30.0, 50.0]]] * 2, [[0]] * 2,
                              ("pedestrian", "deer"))  # fmt: skip
    toy.to_coco(tmp_path / "data" / "val.json")
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    before = sorted(str(p) for p in tmp_path.rglob("*"))
    capsys.readouterr()
    code = main(["assess", str(MODEL), "--data", str(tmp_path / "data"), "--phenomenon", "fog",
                 "--budget", "1", "--search", "../../../x"])  # fmt: skip
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith("error: the archive folder's name 'rover-default-fog-../../../x-s0' "
                          "is not allowed: a name is") and "--out DIR" in err  # fmt: skip
    assert sorted(str(p) for p in tmp_path.rglob("*")) == before  # nothing written anywhere


def test_a_misspelt_model_is_named_not_its_sidecar(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 34 item 12: 'rover-defualt.json: model sidecar not found' for a typo'd model."""
    typo = MODEL.with_name("rover-defualt.safetensors")
    capsys.readouterr()
    code = main(["assess", str(typo), "--data", str(tmp_path), "--phenomenon", "fog",
                 "--budget", "1", "--out", str(tmp_path / "out")])  # fmt: skip
    assert code == 2
    assert capsys.readouterr().err.strip() == (
        f"error: {typo}: model file not found (hint: did you mean {MODEL}?)"
    )
    assert not (tmp_path / "out").exists()


def test_assess_through_the_cameras_encoding_and_train_through_the_same(
    tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 34 item 8: a camera that sends JPEG is assessed through it (``--encoding``), the
    archive says so, and ``oracle train`` follows it or refuses frames of another encoding."""
    args = [*_args(tiny, tmp_path / "j", 2), "--encoding", "jpeg", "--json"]
    assert main(args) == 0
    assert json.loads(capsys.readouterr().out)["encoding"] == "jpeg:90"
    assert read_archive(tmp_path / "j").meta.encoding == "jpeg:90"
    train = ["oracle", "train", "--models", str(MODEL), "--data", str(tiny),
             "--archive", str(tmp_path / "j"), "--out", str(tmp_path / "o")]  # fmt: skip
    assert main([*train, "--encoding", "none"]) == 2
    err = capsys.readouterr().err
    assert "was assessed through jpeg:90" in err and "--encoding none" in err
    assert not list(tmp_path.glob("o*"))
    assert main([*_args(tiny, tmp_path / "bad", 2), "--encoding", "png"]) == 2
    assert "PNG is lossless" in capsys.readouterr().err
