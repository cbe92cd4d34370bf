"""A simulated run as data and as a picture: windowed F1, tactic events, JSON, the plot."""

from __future__ import annotations

import builtins
import json
import math
import struct
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from anunnaki.cli.main import main
from anunnaki.errors import AnunnakiError, MissingExtraError
from anunnaki.sim import (
    FrameScore,
    RunReport,
    TacticEvent,
    compare_assessors,
    draw_report,
    f1_score,
    load_report,
    plot_report,
    rolling_f1,
    tactic_events,
)

EXAMPLES = Path(__file__).parents[2] / "examples"


def frames(*rows: tuple[float, int, int, int]) -> list[FrameScore]:
    return [FrameScore(t, tp, fp, fn, "m") for t, tp, fp, fn in rows]


def test_rolling_f1_pools_the_window() -> None:
    fs = frames((0.0, 2, 0, 0), (0.5, 0, 0, 2), (1.0, 0, 0, 0), (1.6, 1, 1, 0), (5.0, 0, 0, 0))
    f1 = rolling_f1(fs, window=1.0)
    assert f1[0] == 1.0  # 2·2 / (2·2)
    assert f1[1] == pytest.approx(4 / 6)  # tp 2, fn 2
    assert f1[2] == pytest.approx(0.0)  # (0.0, 1.0]: the frame at 0.5 only → tp 0, fn 2
    assert f1[3] == pytest.approx(2 / 3)  # (0.6, 1.6]: tp 1, fp 1
    assert f1[4] is None  # nothing to score in (4.0, 5.0]
    assert rolling_f1(fs, window=100.0)[-1] == pytest.approx(6 / 9)  # tp 3, fp 1, fn 2
    with pytest.raises(ValueError, match="window"):
        rolling_f1(fs, window=0)


def test_tactic_events_pair_starts_with_outcomes() -> None:
    d = [
        SimpleNamespace(t=1.0, kind="selected", tactic="a"),
        SimpleNamespace(t=1.0, kind="started", tactic="a"),
        SimpleNamespace(t=2.0, kind="started", tactic="b"),
        SimpleNamespace(t=3.0, kind="postcondition_failed", tactic="a"),
        SimpleNamespace(t=4.0, kind="started", tactic="a"),
        SimpleNamespace(t=5.0, kind="postcondition_ok", tactic="a"),
        SimpleNamespace(t=5.0, kind="paused", tactic=None),
    ]
    assert tactic_events(d) == [
        TacticEvent(1.0, "a", "failed", 3.0),
        TacticEvent(2.0, "b", None, None),
        TacticEvent(4.0, "a", "ok", 5.0),
    ]


def sample_report() -> RunReport:
    return RunReport(
        name="t",
        platform="rover",
        duration=4.0,
        frames=[FrameScore(0.1 * k, 1, 0, k % 2, "rover-default") for k in range(40)],
        assessments=[(1.0, 0), (2.0, 2), (3.0, 0)],
        tactics=[TacticEvent(2.0, "swap-to-fog-model", "ok", 2.5)],
        collisions=[3.5],
        phases=[
            {"start": 0.0, "end": 2.0, "label": "clear"},
            {"start": 2.0, "end": 4.0, "label": "fog"},
        ],
    )


def png_size(path: Path) -> tuple[int, int]:
    head = path.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", head[16:24])
    return width, height


def test_report_round_trip_and_plot(tmp_path: Path) -> None:
    report = sample_report()
    path = report.write(tmp_path / "sub" / "run.json")
    assert load_report(path) == report
    out = plot_report(load_report(path), tmp_path / "run.png")
    width, height = png_size(out)
    assert width > 800 and height > 500


def test_bad_report_files_are_named(tmp_path: Path) -> None:
    wrong = tmp_path / "wrong.json"
    wrong.write_text(json.dumps({"anunnaki": "trace/1"}))
    with pytest.raises(AnunnakiError, match=r"wrong\.json: not a simulation report"):
        load_report(wrong)
    broken = tmp_path / "broken.json"
    doc = sample_report().as_dict()
    del doc["frames"]
    broken.write_text(json.dumps(doc))
    with pytest.raises(AnunnakiError, match=r"broken\.json: malformed simulation report"):
        load_report(broken)
    (tmp_path / "text.json").write_text("{")
    with pytest.raises(AnunnakiError, match=r"text\.json: cannot read"):
        load_report(tmp_path / "text.json")


def test_plot_without_matplotlib_names_the_extra(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    real_import = builtins.__import__

    def no_matplotlib(name: str, *args: Any, **kwargs: Any) -> Any:
        if name.startswith("matplotlib"):
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_matplotlib)
    with pytest.raises(MissingExtraError, match=r"anunnaki\[plot\]"):
        plot_report(sample_report(), tmp_path / "x.png")
    assert not (tmp_path / "x.png").exists()


def test_report_and_plot_need_the_detector(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "rover", "--until", "1", "--report", "r.json"]) == 2
    assert "give --models too" in capsys.readouterr().err
    assert main(["run", str(EXAMPLES / "rover" / "utu.yaml"), "--plot", "p.png"]) == 2
    assert "need a simulated managed system" in capsys.readouterr().err


def test_compare_assessors_gives_agreement_and_signed_delays() -> None:
    """An oracle that goes up 2 frames after the scorer and down 3 frames before it."""
    scorer = [(s, 0) for s in range(0, 10)] + [(s, 2) for s in range(10, 30)]
    scorer += [(s, 0) for s in range(30, 40)]
    oracle = [(s, 0) for s in range(0, 12)] + [(s, 2) for s in range(12, 27)]
    oracle += [(s, 0) for s in range(27, 40)] + [(40, 1)]  # frame 40: the scorer said nothing
    out = compare_assessors(list(reversed(oracle)), scorer, rate=10.0)
    assert out["frames"] == 40
    assert out["agreement"] == pytest.approx(35 / 40)  # 2 frames late up, 3 frames early down
    assert out["confusion"] == [[20, 0, 0], [0, 0, 0], [5, 0, 15]]  # scorer row, oracle column
    assert out["changes"] == 2 and out["delays_frames"] == [2, -3]
    assert out["median_delay_frames"] == -0.5 and out["median_delay_s"] == -0.05
    assert out["unmatched"] == 0
    never = compare_assessors([(s, 0) for s in range(40)], scorer, rate=10.0)
    assert never["unmatched"] == 2 and never["median_delay_frames"] is None
    assert compare_assessors([], scorer, rate=10.0)["agreement"] is None


def test_report_keeps_the_scoring(tmp_path: Path) -> None:
    scoring = {"oracle": "enlil", "scorer": "ground_truth", "agreement": 0.9}
    run = RunReport("s", "rover", 1.0, frames=frames((0.0, 1, 0, 0)), scoring=scoring)
    assert load_report(run.write(tmp_path / "r.json")).scoring == scoring
    plain = RunReport("s", "rover", 1.0)
    assert "scoring" not in plain.as_dict()
    assert load_report(plain.write(tmp_path / "p.json")).scoring is None


# -- issue 34 item 5: F1 is undefined where there is no ground-truth object ------------------
def test_a_window_without_ground_truth_has_no_f1() -> None:
    """One false positive and nothing to find: no F1 (not 0), so the plot leaves a gap."""
    fs = frames((0.0, 1, 0, 1), (0.5, 0, 1, 0), (2.0, 0, 1, 0), (3.0, 0, 0, 2))
    f1 = rolling_f1(fs, window=1.0)
    assert f1[0] == pytest.approx(2 / 3)
    assert f1[1] == pytest.approx(2 / 4)  # (−0.5, 0.5]: tp 1, fp 1, fn 1
    assert f1[2] is None  # (1.0, 2.0]: one false positive, no object → undefined
    assert f1[3] == 0.0  # (2.0, 3.0]: two objects missed → F1 0, defined
    assert f1_score(0, 1, 0) is None and f1_score(0, 0, 0) is None
    assert f1_score(0, 0, 2) == 0.0 and f1_score(2, 1, 1) == pytest.approx(4 / 6)


def f1_lines(fig: Any) -> dict[str, Any]:
    ax = fig.axes[0]
    return {
        line.get_label(): line for line in ax.get_lines() if not line.get_label().startswith("_")
    }


def test_the_plot_leaves_a_gap_where_f1_is_undefined() -> None:
    report = RunReport(
        "gap",
        "rover",
        3.0,
        frames=frames(*[(0.1 * k, 1, 0, 0) for k in range(10)], (1.05, 0, 0, 0), (2.5, 0, 1, 0)),
    )
    fig = draw_report(report)
    ys = list(f1_lines(fig)["m"].get_ydata())
    assert ys[:10] == [1.0] * 10
    assert math.isnan(ys[-1])  # (1.5, 2.5]: a false positive alone, no F1: a gap, not 0
    assert 0.0 not in ys


# -- issue 34 item 7: the phases' labels never overlap; the flight panel ----------------------
def crowded_report() -> RunReport:
    """The UAV demo's phases: 10–11 s and 11–14.5 s rain+brightness, 14.5–16 clear, fog."""
    spans = [
        (0, 10, "clear"),
        (10, 11, "rain+brightness"),
        (11, 14.5, "rain+brightness"),
        (14.5, 16, "clear"),
        (16, 20, "fog"),
        (20, 49.5, "fog"),
        (49.5, 75, "on the ground"),
    ]
    return RunReport(
        "crowded",
        "uav",
        75.0,
        frames=frames(*[(0.1 * k, 1, 0, 0) for k in range(750)]),
        phases=[{"start": a, "end": b, "label": label} for a, b, label in spans],
    )


def label_boxes(fig: Any) -> list[Any]:
    renderer = fig.canvas.get_renderer()
    texts = [t for ax in fig.axes for t in ax.texts if t.get_gid() == "phase-label"]
    return [t.get_window_extent(renderer) for t in texts]


@pytest.mark.parametrize("width", [11.0, 6.0])
def test_phase_labels_never_overlap(width: float) -> None:
    report = crowded_report()
    fig = draw_report(report, width=width)
    boxes = label_boxes(fig)
    assert len(boxes) == len(report.phases)
    for i, a in enumerate(boxes):
        for b in boxes[i + 1 :]:
            assert not a.overlaps(b), (a, b)
    # each label stays within the figure
    fig_box = fig.bbox
    assert all(b.x0 >= fig_box.x0 and b.x1 <= fig_box.x1 for b in boxes)


def flight_report() -> RunReport:
    modes = ["auto"] * 40 + ["hover"] * 10 + ["auto"] * 16 + ["return_home"] * 30 + ["land"] * 4
    track = [
        {"t": 0.5 * k, "x": float(k), "y": 0.0, "altitude": min(30.0, 3.0 * k),
         "battery": 100.0 - 0.5 * k, "mode": mode}
        for k, mode in enumerate(modes)
    ]  # fmt: skip
    return RunReport(
        "flight",
        "uav",
        50.0,
        frames=frames(*[(0.1 * k, 1, 0, 0) for k in range(500)]),
        phases=[{"start": 0.0, "end": 50.0, "label": "clear"}],
        flight={
            "took_off": 0.0,
            "delivered": False,
            "delivered_at": None,
            "landed": 49.5,
            "landed_xy": [0.0, 0.0],
            "landed_home": True,
            "battery_at_landing": 50.5,
            "track": track,
        },
    )


def test_the_flight_is_kept_and_drawn(tmp_path: Path) -> None:
    report = flight_report()
    assert load_report(report.write(tmp_path / "f.json")) == report
    assert "flight" not in sample_report().as_dict()  # a rover has none
    fig = draw_report(report)
    panel = next(ax for ax in fig.axes if ax.get_ylabel().startswith("altitude"))
    (altitude,) = [line for line in panel.get_lines() if line.get_label() == "altitude"]
    assert list(altitude.get_ydata()) == [row["altitude"] for row in report.flight["track"]]
    battery = next(ax for ax in fig.axes if ax.get_ylabel().startswith("battery"))
    assert [line.get_label() for line in battery.get_lines()] == ["battery"]
    # one band per stretch of a mode: auto, hover, auto, return_home, land
    bands = [p for p in panel.patches if p.get_gid() and p.get_gid().startswith("mode:")]
    assert [p.get_gid() for p in bands] == [
        "mode:auto", "mode:hover", "mode:auto", "mode:return_home", "mode:land"
    ]  # fmt: skip
    out = plot_report(report, tmp_path / "f.png")
    assert png_size(out)[1] > png_size(plot_report(sample_report(), tmp_path / "s.png"))[1]
