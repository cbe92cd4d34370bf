"""benchmarks/uav_oracle.py in its quick mode: 6 s of the UAV demo's launch, climbing into fog.

The quick flight climbs at 10 m/s into the demo's fog at 2 s: the recording must be what the
live scorer heard (replayed exactly), the clean renders must come with every frame, and the
figures the docs quote (docs/uav.md, "The oracle against the ground truth") must be there:
the agreement before and after, per phase and per model, with the F1 on the perturbed and the
clean frames. The numbers themselves are measured by the full run, not judged here.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from bench_helpers import load, run


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_uav_oracle_benchmark(tmp_path: Path) -> None:
    out = tmp_path / "uav-oracle.json"
    # the shipped uav-fog oracle replayed offline beside itself: the replay is the live node's
    shipped = str(Path(__file__).parents[2] / "examples" / "models" / "uav-fog.oracle")
    run("uav_oracle.py", "--quick", "--output", str(out), "--oracle", f"uav-fog={shipped}",
        "--views", "2", timeout=540)  # fmt: skip
    doc = load(out)
    assert doc["benchmark"] == "uav_oracle" and doc["settings"]["scenario"] == "quick"
    assert doc["scorer"]["options"]["reference"] == "paired"  # the demo's scorer, as shipped
    assert doc["scorer"]["before"] == {"reference": "clean_f1", "sparse": "nominal"}
    checks = doc["checks"]
    assert checks["offline_vs_live_detections_mismatched"] == 0
    assert checks["replayed_scorer_mismatched"] == 0
    assert checks["clean_frames"] == doc["frames"] > 0
    assert checks["replayed_oracle_mismatched"] == 0 and checks["replayed_oracle_unrecorded"] <= 1
    assert doc["oracles"]["replayed"]["uav-fog"] == doc["oracles"]["live"]["uav-fog"]
    assert set(doc["clean_f1"]) == {"uav-default", "uav-fog", "uav-rain_brightness"}
    for part in ("all", "airborne"):
        assert set(doc["overall"][part]) == {"before", "after", "after_x_before", "split_half",
                                             "replayed_oracle"}  # fmt: skip
        assert doc["overall"][part]["replayed_oracle"] == doc["overall"][part]["after"]
    assert [p["label"] for p in doc["phases"]] == ["clear", "fog", "fog"]
    fog = doc["phases"][-1]["airborne"]["uav-fog"]  # swapped in for the fog
    assert fog["after"]["frames"] > 0 and len(fog["after"]["confusion"]) == 3
    assert fog["f1"]["perturbed"]["f1"] is not None and fog["f1"]["clean"]["f1"] is not None
    assert fog["f1"]["registry_clean"] == pytest.approx(0.894, abs=0.001)
    assert set(fog["f1"]["every_model"]) == set(doc["clean_f1"])
    # uav-fog under the scenario's fog on views of its town: the datasets' camera and the
    # UAV's in flight, each as rendered and through the camera's JPEG
    views = doc["views"]
    assert views["model"] == "uav-fog" and views["views"] == 2
    for camera in ("dataset", "flight"):
        got = views["cameras"][camera]
        assert got["rendered"]["encoding"] == "none"
        assert got["through_camera"]["encoding"] == "jpeg:90"
        assert got["through_camera"]["perturbed"]["f1"] is not None
