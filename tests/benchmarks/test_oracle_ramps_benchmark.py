"""benchmarks/oracle_ramps.py in its quick mode: every ramp, the dusk and the close pedestrians."""

from __future__ import annotations

from pathlib import Path

import pytest
from bench_helpers import load, run


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_oracle_ramps_benchmark(tmp_path: Path, tiny_rover: Path) -> None:
    """Its quick mode, every case (the scripted ramps, the dusk, the close pedestrians)."""
    out = tmp_path / "oracle_ramps.json"
    # 2 s of clear weather and 2-s ramps (quick: 5 and 5): every case still runs and is scored
    args = ["--quick", "--seeds", "1", "--clean", "2", "--ramp", "2", "--loop-seconds", "2"]
    args += ["--threads", "1"]
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
