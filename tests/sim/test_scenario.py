"""Scenario files: ramps, faults, the ground truth of what was applied, errors with lines."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sim_helpers import rover_scenario

from anunnaki import topics
from anunnaki.errors import ModelFileError
from anunnaki.phenomena import PHENOMENA
from anunnaki.sim import RoverSim, Timeline, load_scenario, parse_scenario

EXAMPLES = Path(__file__).parents[2] / "examples"


def test_ramps_give_the_right_params_at_the_right_times() -> None:
    sc = parse_scenario(
        rover_scenario(
            phenomena=[
                {"at": 2, "phenomenon": "brightness", "strength": 0.8, "ramp": 4},
                {"at": 10, "phenomenon": "brightness", "strength": 0.2, "ramp": 2},
                {
                    "at": 5,
                    "phenomenon": "fog",
                    "params": {"density": 6, "intensity": 0.4},
                    "until": 9,
                },
            ]
        )
    )
    tl = Timeline(sc)
    bright = PHENOMENA.create("brightness")
    assert tl.phenomena(1.9) == []
    assert tl.phenomena(2.0) == [("brightness", bright.identity_params())]
    assert tl.phenomena(4.0) == [("brightness", bright.strength_params(0.4))]  # half-way
    assert dict(tl.phenomena(6.0))["brightness"] == bright.strength_params(0.8)
    at7 = dict(tl.phenomena(7.0))
    assert list(at7) == ["brightness", "fog"]
    assert at7["fog"] == {"density": 6.0, "intensity": 0.4}
    assert "fog" not in dict(tl.phenomena(9.0))  # until
    # a later event of the same phenomenon ramps from where the earlier one had got to
    at11 = dict(tl.phenomena(11.0))["brightness"]
    s8, s2 = bright.strength_params(0.8), bright.strength_params(0.2)
    assert at11["gain"] == pytest.approx((s8["gain"] + s2["gain"]) / 2)
    assert dict(tl.phenomena(20.0))["brightness"] == s2


def test_faults_in_force() -> None:
    sc = parse_scenario(
        rover_scenario(
            faults=[
                {"at": 3, "fault": "rate", "sensor": "ultrasonic", "rate": 4.8},
                {"at": 6, "fault": "rate", "sensor": "ultrasonic", "rate": 3.0},
                {"at": 4, "fault": "dropout", "sensor": "camera", "duration": 1},
            ]
        )
    )
    tl = Timeline(sc)
    assert [tl.rate("ultrasonic", 10.0, t) for t in (0, 3, 5.9, 6)] == [10.0, 4.8, 4.8, 3.0]
    assert not tl.silent("camera", 3.99) and tl.silent("camera", 4.5)
    assert not tl.silent("camera", 5.0)
    assert {f["fault"] for f in tl.faults(4.5)} == {"rate", "dropout"}
    assert {f["fault"] for f in tl.faults(5.5)} == {"rate"}


def test_the_rover_applies_and_reports_the_phenomena(bus) -> None:
    sc = rover_scenario(
        phenomena=[{"at": 1.0, "phenomenon": "brightness", "strength": 1.0, "ramp": 1.0}],
        faults=[
            {"at": 1.0, "fault": "rate", "sensor": "ultrasonic", "rate": 4.8},
            {"at": 2.0, "fault": "rate", "sensor": "ultrasonic", "rate": 3.0},
            {"at": 2.5, "fault": "dropout", "sensor": "camera", "duration": 0.5},
        ],
    )
    with RoverSim(bus, sc, clear_layout=True) as rover:
        truth = bus.subscribe(topics.PHENOMENA, queue=256)
        ranges = bus.subscribe("/rover/ultrasonic", queue=256)
        means: dict[float, float] = {}
        rover.frame_hook = lambda sim, frame, image: means.__setitem__(
            round(frame.t, 3), float(image.mean())
        )
        stamps = []
        for _ in range(35):
            start = rover.t
            rover.step(0.1)  # publishes what falls due in [start, start + 0.1)
            while ranges.try_recv() is not None:
                stamps.append(round(start, 3))
        msgs = []
        while (sample := truth.try_recv()) is not None:
            msgs.append(sample.message.data)
        by_t = {round(m["t"], 3): m for m in msgs}
        assert by_t[0.5]["phenomena"] == []
        bright = PHENOMENA.create("brightness")
        half = by_t[1.5]["phenomena"]
        assert half == [{"name": "brightness", "params": bright.strength_params(0.5)}]
        assert by_t[2.5]["phenomena"][0]["params"] == bright.strength_params(1.0)
        assert {f["fault"] for f in by_t[2.5]["faults"]} == {"rate", "dropout"}
        assert means[2.5] < 0.3 * means[0.5]  # the dimmed frame is what was published
        # rates: 10 Hz, then 4.8 Hz from t = 1, 3 Hz from t = 2
        per_window = [sum(a <= s < b for s in stamps) for a, b in ((0, 1), (1, 2), (2, 3))]
        assert per_window == [10, 5, 3]
        # the camera dropout silences the image topic for 0.5 s
        assert rover.published["/rover/camera/image"] == rover.frames - 5


def test_a_bad_field_fails_with_file_and_line(tmp_path) -> None:
    path = tmp_path / "scenario.yaml"
    path.write_text(
        "anunnaki: scenario/1\n"
        "platform: rover\n"
        "phenomena:\n"
        "  - {at: 20, phenomenon: brightness, strength: 0.8, ramp: 5}\n"
        "  - {at: 40, phenomenon: fog, strenght: 0.5}\n"
    )
    with pytest.raises(ModelFileError) as err:
        load_scenario(path)
    assert f"{path}:5" in str(err.value) and "strenght" in str(err.value)
    path.write_text("platform: rover\nphenomena:\n  - {at: 1, phenomenon: smog, strength: 1}\n")
    with pytest.raises(ModelFileError, match=r":3: .*unknown phenomenon 'smog'; known: "):
        load_scenario(path)
    path.write_text("platform: uav\nfaults:\n  - {at: 1, fault: dropout, sensor: ultrasonic}\n")
    with pytest.raises(ModelFileError, match="dropout"):
        load_scenario(path)


@pytest.mark.parametrize("platform", ["rover", "uav"])
def test_example_scenarios_are_valid(platform) -> None:
    sc = load_scenario(EXAMPLES / platform / "scenario.yaml")
    assert sc.platform == platform and sc.phenomena and sc.faults
    assert Timeline(sc).phenomena(sc.duration)


def test_same_phenomena_seed_gives_same_bytes(bus) -> None:
    sc = rover_scenario(phenomena=[{"at": 0, "phenomenon": "noise", "strength": 0.5}])
    images = []
    for _ in range(2):
        with RoverSim(bus, sc, clear_layout=True) as rover:
            rover.step(0.35)
            assert rover.last_image is not None
            images.append(rover.last_image.copy())
    assert np.array_equal(images[0], images[1])


# -- seeded draws (vary:) ------------------------------------------------------------------------
def _varied() -> object:
    return parse_scenario(
        rover_scenario(
            objects=[
                {"kind": "pedestrian", "x": 7, "y": -2, "walk_to": [7, 2], "speed": 0.4, "start": 1}
            ],
            phenomena=[
                {"at": 8, "phenomenon": "fog", "strength": 1.0, "ramp": 1, "until": 18},
                {"at": 8, "phenomenon": "brightness", "strength": 0.8, "ramp": 1},
                {
                    "at": 24,
                    "phenomenon": "hsl",
                    "params": {"hue": 90, "saturation": 0, "lightness": -0.3},
                },
            ],
            vary={"timing": 1.5, "placement": 1.0, "strength": 0.3},
        )
    )


def test_a_draw_moves_phases_objects_and_strengths_within_the_bounds() -> None:
    from anunnaki.sim import Scenario, draw_scenario

    sc = _varied()
    assert isinstance(sc, Scenario)
    for seed in range(20):
        d = draw_scenario(sc, seed)
        assert d.seed == seed and d.vary is None
        fog, dim, hsl = d.phenomena
        assert fog.at == dim.at and abs(fog.at - 8) <= 1.5  # events starting together move together
        assert fog.until == pytest.approx(fog.at + 10)  # a phase keeps its length
        assert abs(hsl.at - 24) <= 1.5
        assert 0.7 - 1e-9 <= fog.strength <= 1.0 and 0.56 - 1e-9 <= dim.strength <= 0.8
        assert fog.strength / 1.0 == pytest.approx(dim.strength / 0.8)  # one draw per phase
        assert hsl.params is not None and -0.3 <= hsl.params["lightness"] <= -0.21 + 1e-9
        (p,) = d.objects
        assert abs(p.x - 7) <= 1.0 and p.walk_to == (p.x, 2.0)
        assert 0.0 <= p.start <= 2.5
    assert draw_scenario(sc, 4) == draw_scenario(sc, 4)
    assert draw_scenario(sc, 4) != draw_scenario(sc, 5)


def test_a_draw_moves_each_sensors_faults_together_and_scales_the_battery_drain() -> None:
    from anunnaki.sim import draw_scenario

    sc = parse_scenario(
        {
            "platform": "uav",
            "phenomena": [{"at": 16, "phenomenon": "fog", "strength": 0.7, "ramp": 4}],
            "faults": [
                {"at": 21, "fault": "rate", "sensor": "gps", "rate": 4},
                {"at": 25, "fault": "rate", "sensor": "gps", "rate": 10},
                {"at": 30, "fault": "dropout", "sensor": "link", "duration": 6},
                {"at": 1, "fault": "battery_drain", "rate": 1.0},
            ],
            "vary": {"timing": 2, "strength": 0.3, "fault_timing": 2, "drain": 0.25},
        }
    )
    shifts = set()
    for seed in range(20):
        d = draw_scenario(sc, seed)
        (fog,) = d.phenomena
        assert abs(fog.at - 16) <= 2 and 0.49 - 1e-9 <= (fog.strength or 0) <= 0.7
        slow, back, link, drain = d.faults
        assert abs(slow.at - 21) <= 2 and back.at - slow.at == pytest.approx(4)  # one sensor
        assert abs(link.at - 30) <= 2 and link.duration == 6  # a dropout keeps its length
        assert 0.0 <= drain.at <= 3 and 0.75 - 1e-9 <= (drain.rate or 0) <= 1.25 + 1e-9
        assert (slow.rate, back.rate) == (4, 10)  # only battery drains are scaled
        shifts.add((round(slow.at - 21, 6), round(link.at - 30, 6)))
    assert len(shifts) == 20 and all(a != b for a, b in shifts)  # a draw per sensor, per seed
    # the faults' draws come after the rest: the phases are drawn as without them
    assert sc.vary is not None
    plain = sc.model_copy(
        update={"vary": sc.vary.model_copy(update={"fault_timing": 0.0, "drain": 0.0})}
    )
    assert draw_scenario(plain, 3).phenomena == draw_scenario(sc, 3).phenomena
    assert draw_scenario(plain, 3).faults == sc.faults


def test_without_vary_a_draw_only_sets_the_seed() -> None:
    from anunnaki.sim import draw_scenario

    sc = parse_scenario(rover_scenario())
    assert draw_scenario(sc, 7) == sc.model_copy(update={"seed": 7})


def test_a_bad_vary_names_its_line(tmp_path) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text("anunnaki: scenario/1\nplatform: rover\nvary:\n  timing: -1\n")
    with pytest.raises(ModelFileError, match=r"bad.yaml:4: vary.timing"):
        load_scenario(path)
