"""``anunnaki sim``: runs a scenario flat out and prints a line per simulated second."""

from __future__ import annotations

from pathlib import Path

from anunnaki.cli.main import main
from anunnaki.sim import load_report

EXAMPLES = Path(__file__).parents[2] / "examples"


def test_sim_rover_prints_a_line_per_second(capsys) -> None:
    code = main(
        [
            "sim",
            "rover",
            "--scenario",
            str(EXAMPLES / "rover" / "scenario.yaml"),
            "--until",
            "2",
            "--speed",
            "0",
            "--width",
            "32",
            "--height",
            "32",
        ]
    )
    out = capsys.readouterr().out
    assert code == 0
    lines = [ln for ln in out.splitlines() if ln.startswith("t=")]
    assert len(lines) == 2 and "autonomous" in lines[0] and "collisions 0" in lines[0]
    assert "done at t=2.00s: 20 frames" in out


def test_sim_uav_runs(capsys) -> None:
    code = main(["sim", "uav", "--until", "1", "--speed", "0", "--width", "32", "--height", "32"])
    assert code == 0 and "battery" in capsys.readouterr().out


def test_sim_with_a_bad_scenario_exits_2(tmp_path, capsys) -> None:
    bad = tmp_path / "s.yaml"
    bad.write_text("platform: rover\ncamera: {rate: -1}\n")
    assert main(["sim", "rover", "--scenario", str(bad)]) == 2
    assert f"{bad}:2" in capsys.readouterr().err
    assert main(["sim", "uav", "--scenario", str(EXAMPLES / "rover" / "scenario.yaml")]) == 2


def test_sim_with_the_detector_in_the_loop_reports_per_phase(capsys, tmp_path) -> None:
    report, plot = tmp_path / "run.json", tmp_path / "run.png"
    code = main(
        [
            "sim",
            "rover",
            "--scenario",
            str(EXAMPLES / "rover" / "demo-scenario.yaml"),
            "--models",
            str(EXAMPLES / "models" / "rover.yaml"),
            "--until",
            "9",
            "--speed",
            "0",
            "--quiet",
            "--report",
            str(report),
            "--plot",
            str(plot),
        ]
    )
    out = capsys.readouterr().out
    assert code == 0, out
    assert "detector rover-default (default) on /rover/camera/image; oracle ground_truth" in out
    rows = [ln for ln in out.split("per phase:")[1].splitlines() if "–" in ln]
    assert rows[0].split()[:3] == ["0.0–", "8.0", "s"] and "clear" in rows[0]
    assert "fog" in rows[1] and "rover-default" in rows[1]
    assert int(rows[0].split()[4]) == 80  # frames scored in the clear phase
    # The same run as data, and drawn.
    assert f"report: {report}" in out and f"plot: {plot}" in out
    run = load_report(report)
    assert (run.platform, run.name, run.duration) == ("rover", "fog-then-dusk", 9.0)
    assert [p["label"] for p in run.phases] == ["clear", "fog"]
    assert len(run.frames) == 90 and {f.model for f in run.frames} == {"rover-default"}
    assert sum(f.tp for f in run.frames if f.t < 8.0) == run.phases[0]["tp"] > 0
    assert run.assessments and {c for _, c in run.assessments} <= {0, 1, 2}
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_sim_uav_with_the_detector(capsys) -> None:
    code = main(
        [
            "sim",
            "uav",
            "--models",
            str(EXAMPLES / "models" / "uav.yaml"),
            "--oracle",
            "none",
            "--until",
            "2",
            "--speed",
            "0",
            "--quiet",
        ]
    )
    out = capsys.readouterr().out
    assert code == 0, out
    assert "detector uav-default (default) on /uav/camera/image; oracle none" in out
    assert "done at t=2.00s" in out and "per phase:" in out
