"""The ``anunnaki`` command line: the real console script, piped and forced into colour."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import anunnaki
from anunnaki.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
ROVER = ROOT / "examples" / "rover"
ANSI = re.compile(r"\x1b\[[0-9;]*m")


def console_script() -> str:
    beside = Path(sys.executable).with_name("anunnaki")
    found = str(beside) if beside.exists() else shutil.which("anunnaki")
    assert found is not None, "the anunnaki console script is not installed"
    return found


def clean_env(**extra: str) -> dict[str, str]:
    """The environment without anything that forces or forbids colour, plus ``extra``."""
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("FORCE_COLOR", "TTY_COMPATIBLE", "NO_COLOR", "TERM", "COLUMNS")
    }
    env.update(extra)
    return env


def run(*args: str, **env: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [console_script(), *args],
        capture_output=True,
        text=True,
        env=clean_env(**env),
        timeout=60,
        check=False,
    )


ROVER_ARGS = (
    "evaluate",
    str(ROVER / "goals.yaml"),
    "--binding",
    str(ROVER / "binding.yaml"),
    "--trace",
    str(ROVER / "trace.jsonl"),
)


def test_version() -> None:
    done = run("--version")
    assert done.returncode == 0
    assert done.stdout == f"anunnaki {anunnaki.__version__}\n"


def test_evaluate_piped_is_plain_text_with_tree_and_summary() -> None:
    done = run(*ROVER_ARGS, TERM="xterm-256color")
    assert done.returncode == 0, done.stderr
    out = done.stdout
    assert "\x1b[" not in out
    assert done.stderr == ""
    # the tree at the moment the oracle reports category 1
    block = out[out.index("t =   25.000 s") :]
    block = block[: block.index("\n\n")]
    assert block.splitlines()[:5] == [
        "t =   25.000 s  G1 satisfied→unsatisfied, G2 satisfied→unsatisfied, "
        "G3 satisfied→unsatisfied, G4 satisfied→unsatisfied, O1 absent→holds",
        "G1 unsatisfied 0.000  Rover operates safely in its environment",
        "├── G2 unsatisfied 0.000  Rover detects and avoids obstacles",
        "│   ├── G3 unsatisfied 0.000  Rover detects obstacles",
        "│   │   ├── G4 unsatisfied 0.000  Rover detects obstacles autonomously",
    ]
    assert (
        "│   │   │   ├── ⊘ O1 holds       1.000  Object detector is degraded/compromised" in block
    )
    # phases as rules, the summary at the end
    assert re.search(
        r"─+ phase dim-light: light dims: the oracle reports category 1 \(O1 holds\) ─+", out
    )
    summary = out[out.index(" summary ") :].splitlines()[1:]
    assert summary == [
        "nominal                  root G1 at end of phase: satisfied",
        "ultrasonic-4.8Hz         root G1 at end of phase: satisfied",
        "pedestrian-near          root G1 at end of phase: satisfied",
        "dim-light                root G1 at end of phase: unsatisfied",
        "manual                   root G1 at end of phase: satisfied",
        "ultrasonic-silent        root G1 at end of phase: unknown",
        f"718 messages replayed from {ROVER / 'trace.jsonl'}",
    ]


@pytest.mark.parametrize("force", [{"FORCE_COLOR": "1"}, {"TTY_COMPATIBLE": "1"}])
def test_evaluate_in_colour_when_forced(force: dict[str, str]) -> None:
    done = run(*ROVER_ARGS, TERM="xterm-256color", **force)
    assert done.returncode == 0, done.stderr
    codes = set(ANSI.findall(done.stdout))
    assert "\x1b[1;31m" in codes  # bold red: unsatisfied
    assert "\x1b[32m" in codes  # green: satisfied
    plain = ANSI.sub("", done.stdout)
    assert "root G1 at end of phase: unsatisfied" in plain


def test_evaluate_json_lines_parse(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*ROVER_ARGS, "--json"]) == 0
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    changes, last = lines[:-1], lines[-1]
    assert last["messages"] == 718
    assert last["silent_topics"] == {}
    assert [row["phase"] for row in last["summary"]][:2] == ["nominal", "ultrasonic-4.8Hz"]
    first = changes[0]
    assert (first["t"], first["phase"]) == (0.0, "nominal")
    assert set(first["nodes"]) == {f"G{i}" for i in (1, 2, 3, 4, 5, 6, 7, 8, 11, 12, 13, 14)} | {
        "O1"
    }
    assert {
        "node": "G7",
        "from": "unknown",
        "to": "satisfied",
        "utility_from": None,
        "utility": 1.0,
    } in first["changed"]
    assert [c["t"] for c in changes] == sorted(c["t"] for c in changes)
    assert "explanation" not in first


def count_changes(capsys: pytest.CaptureFixture[str], *extra: str) -> list[dict[str, object]]:
    assert main([*ROVER_ARGS, "--json", *extra]) == 0
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines()[:-1]]
    return [c for line in lines for c in line["changed"]]


def test_delta_changes_how_many_changes_are_reported(capsys: pytest.CaptureFixture[str]) -> None:
    default = count_changes(capsys)
    everything = count_changes(capsys, "--delta", "0")
    statuses = count_changes(capsys, "--delta", "1.5")
    assert len(everything) > len(default) > len(statuses)
    # with a delta above any possible move, only status changes are reported
    assert all(c["from"] != c["to"] for c in statuses)
    # the RELAX-ed G6 sagging from 1.0 to 0.6 stays satisfied: a utility move only
    sag = [c for c in default if c["node"] == "G6" and c["from"] == c["to"] == "satisfied"]
    assert sag
    assert not [c for c in statuses if c["node"] == "G6" and c["from"] == "satisfied" == c["to"]]
    # every utility move reported at the default is at least 0.05
    for c in default:
        if c["from"] == c["to"] and c["utility"] is not None and c["utility_from"] is not None:
            assert abs(float(c["utility"]) - float(c["utility_from"])) >= 0.05  # type: ignore[arg-type]


@pytest.mark.parametrize("bad", ["-0.1", "nan", "inf", "lots"])
def test_a_bad_delta_is_a_usage_error(bad: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main([*ROVER_ARGS, "--delta", bad])
    assert info.value.code == 2
    assert "--delta" in capsys.readouterr().err


def test_explain_prints_the_reasons_under_each_tree(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*ROVER_ARGS, "--explain", "G1"]) == 0
    out = capsys.readouterr().out
    block = out[out.index("t =   25.000 s") :]
    block = block[: block.index("\n\n")]
    assert "G1 unsatisfied (utility 0): AND: all children must be satisfied" in block
    assert (
        "      G4 unsatisfied (utility 0): AND: all children must be satisfied; obstructed by O1"
        in block
    )
    assert "        O1 holds (utility 1): A4.category >= 1 with A4.category = 1" in block


def test_explain_of_an_unknown_goal_exits_2_before_replaying(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main([*ROVER_ARGS, "--explain", "G99"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.startswith(
        "error: --explain G99: the goal model has no goal or obstacle 'G99'"
    )


def test_explanations_and_paths_are_printed_verbatim_not_as_markup(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model = tmp_path / "m.yaml"
    model.write_text(
        "anunnaki: goal-model/1\nname: markup\n"
        "agents: [{id: A1, topics: [{topic: /a, attributes: [x]}]}]\n"
        "goals:\n"
        "  - {id: G1, description: '[bold]kept[/bold]', utility: 'A1.x in [true, false]',\n"
        "     agents: [A1]}\n"
    )
    folder = tmp_path / "[red]"
    folder.mkdir()
    trace = folder / "t.jsonl"
    trace.write_text('{"t": 0, "topic": "/a", "msg": {"x": true}}\n')
    assert main(["evaluate", str(model), "-t", str(trace), "--explain", "G1"]) == 0
    out = capsys.readouterr().out
    assert "G1 satisfied (utility 1): A1.x in [true, false] with A1.x = true" in out
    assert "[bold]kept[/bold]" in out
    assert f"1 messages replayed from {trace}" in out


def test_topics_the_trace_never_carries_are_named(capsys: pytest.CaptureFixture[str]) -> None:
    args = [
        "evaluate",
        str(ROVER / "goals.yaml"),
        "-b",
        str(ROVER / "binding-ros.yaml"),
        "-t",
        str(ROVER / "trace.jsonl"),
    ]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert (
        "no message on /rover/controller/state (A1), /camera/image_info (A2), "
        "/ultrasonic/range (A3)" in out
    )
    assert main([*args, "--json"]) == 0
    last = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert last["silent_topics"] == {
        "/rover/controller/state": ["A1"],
        "/camera/image_info": ["A2"],
        "/ultrasonic/range": ["A3"],
    }


def test_a_bad_trace_exits_2_with_file_line_and_no_traceback(tmp_path: Path) -> None:
    trace = tmp_path / "bad.jsonl"
    trace.write_text(
        '{"anunnaki": "trace/1"}\n{"t": 0, "topic": "/rover/status", "msg": {"mode": "manual"}}\n'
        '{"t": 1, "topic": "/rover/status", "msg": {"mode": "manual"}, "extra": 1}\n'
    )
    done = run(
        "evaluate", str(ROVER / "goals.yaml"), "-b", str(ROVER / "binding.yaml"), "-t", str(trace)
    )
    assert done.returncode == 2
    assert "Traceback" not in done.stderr + done.stdout
    assert done.stderr == (
        f"error: {trace}:3: trace record: unknown key(s) extra "
        "(hint: a record has 't', 'topic' and 'msg')\n"
    )


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["evaluate", "missing.yaml", "-t", str(ROVER / "trace.jsonl")],
            "error: missing.yaml: cannot read file",
        ),
        (
            ["evaluate", str(ROVER / "goals.yaml"), "-t", str(ROVER / "trace.jsonl")],
            "publishes no topic",
        ),
        (
            [
                "evaluate",
                str(ROVER / "goals.yaml"),
                "-b",
                str(ROVER / "binding.yaml"),
                "-t",
                "nope.jsonl",
            ],
            "error: nope.jsonl: cannot read trace",
        ),
    ],
    ids=["missing-model", "no-binding", "missing-trace"],
)
def test_evaluate_errors_exit_2(
    args: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(args) == 2
    err = capsys.readouterr().err
    assert message in err
    assert "Traceback" not in err


def test_python_dash_m_runs_the_same_command_line() -> None:
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "anunnaki.cli.main",
            "check",
            str(ROVER / "goals.yaml"),
            str(ROVER / "binding.yaml"),
        ],
        capture_output=True,
        text=True,
        env=clean_env(),
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout == "ok: 12 goals, 1 obstacles, 4 agents\n"
    assert done.stderr == ""


def test_no_command_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main([])
    assert info.value.code == 2
    assert "COMMAND" in capsys.readouterr().err


def test_evaluate_json_a_satisfied_or_with_an_unknown_child_has_a_utility(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model = tmp_path / "m.yaml"
    model.write_text(
        "anunnaki: goal-model/1\nname: or-unknown\nroot: G1\n"
        "agents:\n"
        "  - {id: A1, topics: [{topic: /a, attributes: [x]}]}\n"
        "  - {id: A2, topics: [{topic: /b, attributes: [y]}]}\n"
        "goals:\n"
        "  - {id: G1, refinement: or, children: [G2, G3]}\n"
        "  - {id: G2, utility: A1.x, relax: {operator: shall}, threshold: 0.5}\n"
        "  - {id: G3, utility: A2.y >= 1}\n"
    )
    trace = tmp_path / "t.jsonl"
    trace.write_text('{"t": 0, "topic": "/a", "msg": {"x": 0.6}}\n')  # A2 never publishes
    assert main(["evaluate", str(model), "-t", str(trace), "--json"]) == 0
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert lines[0]["nodes"] == {
        "G1": {"utility": 0.6, "status": "satisfied"},  # was: satisfied with utility null
        "G2": {"utility": 0.6, "status": "satisfied"},
        "G3": {"utility": None, "status": "unknown"},
    }
    assert lines[-1]["silent_topics"] == {"/b": ["A2"]}
