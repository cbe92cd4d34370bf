"""The benchmarks of the simulator, the LEC, model swaps, the whole loop and the dashboard run.

Each script runs with tiny parameters into a temporary file and must write the figures the docs
quote (``docs/results.md``), with the structure they are read in. The figures themselves are
not judged here: they are measured by hand on a quiet machine (no timed assertions in tests).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "benchmarks"


def run(script: str, *args: str, timeout: float = 240) -> None:
    result = subprocess.run(
        [sys.executable, str(BENCH / script), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
        cwd=ROOT,
    )
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-4000:]


def load(path: Path) -> Any:
    return json.loads(path.read_text(encoding="utf-8"))


@pytest.mark.slow
def test_sim_benchmark(tmp_path: Path) -> None:
    out = tmp_path / "sim.json"
    run("sim.py", "--frames", "4", "--repeats", "1", "--output", str(out))
    doc = load(out)
    assert doc["benchmark"] == "sim"
    assert set(doc["platforms"]) == {"rover", "uav"}
    for entry in doc["platforms"].values():
        assert entry["build_s"] > 0
        for size in ("128x128", "320x240"):
            assert entry[size]["render_fps"] > 0
            assert entry[size]["platform_fps"] > 0


@pytest.mark.slow
def test_lec_benchmark(tmp_path: Path) -> None:
    out = tmp_path / "lec.json"
    run("lec.py", "--runs", "2", "--warmup", "1", "--train-images", "8", "--output", str(out))
    doc = load(out)["detector"]
    for size in ("128x128", "320x240"):
        for batch in ("batch1", "batch8"):
            figures = doc["results"][size][batch]
            assert 0 < figures["min_ms_per_frame"] <= figures["median_ms_per_frame"]
    assert doc["training"]["images_per_second"] > 0


@pytest.mark.slow
def test_swap_benchmark(tmp_path: Path) -> None:
    out = tmp_path / "swap.json"
    run("swap.py", "--rounds", "2", "--output", str(out))
    doc = load(out)
    for mode in ("cold", "cached"):
        result = doc["results"][mode]
        assert result["swaps"] == 2
        assert result["frames"] == result["detections"] > 0
        assert result["every_frame_once_in_order"] is True
        assert result["monotone_switches"] is True
        assert result["first_detection_ms"]["n"] == 2


@pytest.mark.slow
def test_loop_benchmark(tmp_path: Path) -> None:
    out = tmp_path / "loop.json"
    run("loop.py", "--seconds", "1.5", "--repeats", "1", "--output", str(out))
    doc = load(out)
    stages = doc["stages"]
    assert list(stages) == ["platform", "detector", "oracle", "utu"]
    for entry in stages.values():
        assert entry["runs"][0]["frames"] == 15  # 10 Hz camera over 1.5 simulated seconds
        assert entry["fps_median"] > 0
    assert stages["platform"]["ratio_to_platform"] == 1.0
    assert doc["whole_loop_hz"] == stages["utu"]["fps_median"]
    assert doc["aim_met"] is (doc["whole_loop_hz"] >= doc["aim_hz"])


@pytest.mark.slow
def test_dashboard_benchmark(tmp_path: Path) -> None:
    chromium = os.environ.get("ANUNNAKI_CHROMIUM", "/usr/bin/chromium")
    if not Path(chromium).exists() and os.environ.get("ANUNNAKI_REQUIRE_BROWSER") != "1":
        pytest.skip(f"no Chromium at {chromium}: run scripts/setup-browser.sh")
    out = tmp_path / "dashboard.json"
    run("dashboard.py", "--seconds", "3", "--out", str(out))
    doc = load(out)
    assert doc["setup"]["goals"] == 300
    raf = doc["raf_interval_ms"]
    assert raf["n"] > 10 and 0 < raf["p50"] <= raf["p95"] <= raf["max"]
    assert doc["violation_to_red_ms"]["n"] >= 1
    assert doc["camera_frames_drawn_per_s"] > 0


@pytest.mark.slow
def test_oracle_benchmark_inference_part(tmp_path: Path) -> None:
    """The accuracy part needs datasets and oracles; its library is tested in tests/enlil."""
    out = tmp_path / "oracle.json"
    run("oracle.py", "--only-inference", "--frames", "5", "--output", str(out))
    doc = load(out)
    assert doc["inference_ms_per_frame_128"]["median"] > 0
    assert doc["inference_ms_per_frame_128"]["threads"] == 1 and "accuracy" not in doc
    assert doc["measured_elsewhere"]["ramps"].startswith("benchmarks/results/oracle_ramps.json")
    # --keep-inference keeps both figures of an earlier (quieter) run, the shipped one's too
    kept = {"median": 123.0, "p90": 456.0}
    doc["inference_ms_per_frame_128_shipped_rover_default"] = kept
    out.write_text(json.dumps(doc))
    run("oracle.py", "--only-inference", "--keep-inference", "--frames", "5", "--output", str(out))
    again = load(out)
    assert again["inference_ms_per_frame_128"] == doc["inference_ms_per_frame_128"]
    assert again["inference_ms_per_frame_128_shipped_rover_default"] == kept


@pytest.fixture(scope="module")
def tiny_rover(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A rendered rover dataset of 4 frames per split, for the Enlil benchmarks."""
    pytest.importorskip("pybullet")
    data = tmp_path_factory.mktemp("rover") / "data"
    subprocess.run(
        [
            sys.executable, "-m", "anunnaki", "make-dataset", "rover", "--out", str(data),
            "--train-layouts", "0", "--val-layouts", "1", "--test-layouts", "2",
            "--per-layout", "4", "--workers", "1",
        ],
        check=True, capture_output=True, cwd=ROOT, timeout=300,
    )  # fmt: skip
    return data


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_enlil_speed_benchmark(tmp_path: Path, tiny_rover: Path) -> None:
    data = tiny_rover
    out = tmp_path / "enlil_speed.json"
    args = ["--quick", "--data", str(data), "--output", str(out), "--evals", "2"]
    args += ["--frames", "32", "--fit-frames", "64"]
    args += ["--predict-calls", "20"]
    steps = "assess_fog,oracle_frames,oracle_fit,oracle_predict"
    run("enlil_speed.py", *args, "--steps", steps, timeout=600)
    doc = load(out)
    assert list(doc["steps"]) == ["assess_fog", "oracle_frames", "oracle_fit", "oracle_predict"]
    # the shipped oracle's predict: the same probabilities as before its speed-up
    assert doc["steps"]["oracle_predict"]["max_prob_diff"] < 1e-5
    assert doc["steps"]["oracle_predict"]["current_median_ms"] > 0
    # the baseline tree and this one compute the same archive figures and frames
    assert doc["steps"]["assess_fog"]["identical"] and doc["steps"]["oracle_frames"]["identical"]
    assert doc["steps"]["oracle_fit"]["fit_loss_max_rel_diff"] < 1e-3
    assert all(s["baseline_cpu_s"] > 0 and s["current_cpu_s"] > 0 for s in doc["steps"].values())


def test_goals_benchmark(tmp_path: Path) -> None:
    out = tmp_path / "goals.json"
    run("goals.py", "--updates", "200", "--messages", "50", "--repeat", "1", "--output", str(out))
    doc = load(out)
    assert doc["benchmark"] == "goals"
    assert doc["model"]["goals"] > 1000 and doc["model"]["depth"] == 5
    assert doc["runs"] == {"updates": 200, "messages": 50, "repeat": 1}
    rates = ("incremental_updates_per_s", "messages_per_s", "baseline_bare_minmax_updates_per_s")
    assert all(doc[key] > 0 for key in rates)
    assert doc["incremental_over_baseline"] > 0 and doc["aim_over_baseline"] == 0.6
    assert 0 < doc["full_evaluation_ms"]["min"] <= doc["full_evaluation_ms"]["median"]


@pytest.mark.slow
def test_enlil_search_benchmark(tmp_path: Path, tiny_rover: Path) -> None:
    out = tmp_path / "enlil_search.json"
    args = ["--data", str(tiny_rover), "--budget", "6", "--checkpoints", "3,6"]
    run("enlil_search.py", *args, "--batch-images", "2", "--workers", "1", "--out", str(out))
    doc = load(out)
    assert doc["budget"] == 6 and doc["phenomenon"] == "hsl" and doc["aim"] == 1.5
    assert set(doc["searches"]) == {"enlil", "random", "sobol"}
    for search in doc["searches"].values():
        assert set(search["cells"]) == {"3", "6"}
        assert sum(search["counts"].values()) == 6  # every evaluation has a category
    assert set(doc["enlil_over_random_category1_cells"]) == {"3", "6"}


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_oracle_ramps_benchmark(tmp_path: Path, tiny_rover: Path) -> None:
    """Its quick mode, every case (the scripted ramps, the dusk, the close pedestrians)."""
    out = tmp_path / "oracle_ramps.json"
    args = ["--quick", "--seeds", "1", "--loop-seconds", "2", "--threads", "1"]
    run("oracle_ramps.py", *args, "--data", str(tiny_rover), "--output", str(out), timeout=800)
    doc = load(out)
    assert doc["benchmark"] == "oracle_ramps" and doc["settings"]["quick"] is True
    assert doc["oracle"]["file"] == "examples/models/rover-default.oracle.safetensors"
    assert list(doc["ramps"]) == ["fog", "raindrop", "hsl", "dusk", "close", "demo_close"]
    runs = [r for case in doc["ramps"].values() for r in case["runs"]]
    assert all(r["assessed"] > 0 and r["clean_frames"] <= r["assessed"] for r in runs)
    (close,) = doc["ramps"]["close"]["runs"]
    assert close["event"] is None and close["clean_frames"] == close["assessed"]
    assert 0.3 <= close["distance_m"] <= 1.0 and 0 < close["in_view_frames"] < close["assessed"]
    assert len(close["categories"]) == close["assessed"]
    assert close["false_alarms"] == sum(c >= 1 for c in close["categories"])
    (demo,) = doc["ramps"]["demo_close"]["runs"]  # the demo's first 8 s, no phenomenon
    assert demo["event"] is None and demo["clean_frames"] == demo["assessed"] > 70
    assert demo["false_alarms"] == sum(c >= 1 for c in demo["categories"])
    dusk = doc["ramps"]["dusk"]["runs"][0]["event"]
    assert dusk["phenomenon"] == "brightness" and dusk["ramp"] == 2.0
    alarms = doc["false_alarms"]
    every, without = alarms["with_close_pedestrians"], alarms["without_close_pedestrians"]
    assert every["clean_frames"] == sum(r["clean_frames"] for r in runs)
    closes = alarms["close_pedestrians_only"]
    assert closes["clean_frames"] == close["clean_frames"] + demo["clean_frames"]
    assert every["clean_frames"] == without["clean_frames"] + closes["clean_frames"]
    assert every["false_alarms"] == sum(r["false_alarms"] for r in runs)
    onset = doc["onset_delay_frames"]
    assert {k: v["phenomenon"] for k, v in onset.items()} == {
        "fog": "fog", "raindrop": "raindrop", "hsl": "hsl", "dusk": "brightness"
    }  # fmt: skip
    for kind, entry in onset.items():
        assert entry["delays"] == [
            r["delay_frames"] for r in doc["ramps"][kind]["runs"] if r["delay_frames"] is not None
        ]
    assert set(doc["loop"]) == {"enlil", "ground_truth"}
    assert all(entry["frames"] > 0 for entry in doc["loop"].values())
