"""``anunnaki check LAUNCH`` checks what ``anunnaki run LAUNCH`` loads, with run's own loader.

Each case edits a copy of an example (examples/rover/demo.yaml, examples/uav/sim.yaml, with
the files they name, relative to them) so that ``run`` refuses it, and asks ``check`` the
same: it must find the very problem run stops at (file, line, element, message, hint), and
exit 1, as it does for the same files checked one by one.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from anunnaki.cli.main import main
from anunnaki.errors import ModelFileError
from anunnaki.launch import load_launch

EXAMPLES = Path(__file__).parents[2] / "examples"


def copy_example(tmp_path: Path, name: str) -> Path:
    """examples/<name> copied to ``tmp_path`` beside the shipped models (``../models``)."""
    shutil.copytree(EXAMPLES / name, tmp_path / name)
    (tmp_path / "models").symlink_to(EXAMPLES / "models", target_is_directory=True)
    return tmp_path / name


def edit(path: Path, old: str, new: str) -> int:
    """Replace the first ``old`` in ``path`` by ``new``; the 1-based line it is on."""
    text = path.read_text()
    assert old in text, f"{old!r} not in {path}"
    path.write_text(text.replace(old, new, 1))
    return text[: text.index(old)].count("\n") + 1


def checked(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, list[dict[str, object]]]:
    """``anunnaki check ARGS --json``: the exit code and the findings."""
    capsys.readouterr()
    code = main(["check", *args, "--json"])
    out = json.loads(capsys.readouterr().out)
    assert out["exit_code"] == code
    return code, out["findings"]


def refused(launch: Path) -> ModelFileError:
    """The error ``anunnaki run`` stops at, before it starts anything."""
    with pytest.raises(ModelFileError) as err:
        load_launch(launch)
    return err.value


def as_finding(exc: ModelFileError) -> dict[str, object]:
    return {
        "severity": "error",
        "message": exc.message,
        "path": exc.path,
        "line": exc.line,
        "element": exc.element,
        "hint": exc.hint,
    }


# Each: (example, the launch file, how to break it) -> (the file at fault, its line).
def smog(d: Path) -> tuple[Path, int]:
    f = d / "conditions-scenario.yaml"
    return f, edit(f, "phenomenon: fog,", "phenomenon: smog,")


def no_such_domain(d: Path) -> tuple[Path, int]:
    f = d / "tactics-lm.yaml"
    return f, edit(f, "        domain: fog", "        domain: nosuch") - 2


def failsafe_not_a_tactic(d: Path) -> tuple[Path, int]:
    f = d / "demo.yaml"
    return f, edit(f, "failsafe: fail-safe", "failsafe: stop-everything")


def bad_notify(d: Path) -> tuple[Path, int]:
    f = d / "demo.yaml"
    return f, edit(f, "log_level: WARNING", "log_level: LOUD")


def unknown_oracle(d: Path) -> tuple[Path, int]:
    f = d / "demo.yaml"
    return f, edit(f, "oracle: {name: enlil", "oracle: {name: crystal_ball")


def missing_registry(d: Path) -> tuple[Path, int | None]:
    edit(d / "demo.yaml", "models: ../models/rover.yaml", "models: ../models/rover-nope.yaml")
    return d.parent / "models" / "rover-nope.yaml", None


def removed_sync(d: Path) -> tuple[Path, int]:
    # a launch file written before the replay stopped waiting for Utu
    f = d / "utu.yaml"
    return f, edit(f, "    publish_clock: true\n", "    publish_clock: true\n    sync: true\n") + 1


def domain_the_registry_lacks(d: Path) -> tuple[Path, int]:
    # the binding's enum lists low_light; the UAV's model registry has no model for it
    f = d / "tactics.yaml"
    return f, edit(f, "        domain: fog", "        domain: low_light") - 2


CASES: dict[str, tuple[str, str, Callable[[Path], tuple[Path, int | None]]]] = {
    "unknown phenomenon in the scenario": ("rover", "demo.yaml", smog),
    "tactic domain outside the binding's enum": ("rover", "demo.yaml", no_such_domain),
    "fail-safe that is no tactic": ("rover", "demo.yaml", failsafe_not_a_tactic),
    "invalid notify section": ("rover", "demo.yaml", bad_notify),
    "unknown oracle": ("rover", "demo.yaml", unknown_oracle),
    "missing model registry": ("rover", "demo.yaml", missing_registry),
    "removed option of the scripted replay": ("rover", "utu.yaml", removed_sync),
}


@pytest.mark.parametrize("case", list(CASES))
def test_check_finds_what_run_refuses(
    case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    example, name, breaks = CASES[case]
    d = copy_example(tmp_path, example)
    launch = d / name
    assert checked(capsys, str(launch)) == (0, [])
    at_fault, line = breaks(d)
    exc = refused(launch)
    assert (os.path.normpath(str(exc.path)), exc.line) == (str(at_fault), line), exc.render()
    code, findings = checked(capsys, str(launch))
    assert code == 1
    assert as_finding(exc) in findings, (exc.render(), findings)
    assert all("Value error" not in str(f["message"]) for f in findings)


def test_a_swap_the_registry_cannot_serve_is_a_warning_from_run_and_check(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    d = copy_example(tmp_path, "uav")
    tactics, line = domain_the_registry_lacks(d)
    (warning,) = load_launch(d / "sim.yaml").parts.warnings  # run prints it at start
    assert warning.render() == (
        f"{tactics}:{line}: warning: tactics[swap-to-robust-model].actions[0].domain: tactic "
        "'swap-to-robust-model' swaps to domain 'low_light', for which the model registry has "
        "no model: the model manager will refuse the swap (hint: the registry's domains "
        f"({tmp_path / 'models' / 'uav.yaml'}): default, fog, rain_brightness; name one of "
        "them, or add a model for the domain to the registry)"
    )
    code, findings = checked(capsys, str(d / "sim.yaml"))
    assert code == 1
    assert findings == [{**as_finding(warning.to_error()), "severity": "warning"}]
    # the files alone name no registry: the binding's enum lists low_light
    files = [str(d / f) for f in ("goals.yaml", "binding.yaml", "tactics.yaml")]
    assert checked(capsys, *files) == (0, [])


def test_an_unknown_phenomenon_reads_the_same_from_run_and_check(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    d = copy_example(tmp_path, "rover")
    scenario, line = smog(d)
    capsys.readouterr()
    assert main(["run", str(d / "demo.yaml")]) == 2
    said = capsys.readouterr().err.strip()
    assert said == (
        f"error: {scenario}:{line}: phenomena[1]: unknown phenomenon 'smog'; known: "
        "brightness, fog, hsl, motion_blur, noise, rain, raindrop, snow "
        "(hint: see docs/simulation.md)"
    )
    assert main(["check", str(d / "demo.yaml")]) == 1
    out = capsys.readouterr().out
    assert out.splitlines() == [
        said.removeprefix("error: ").replace(": phenomena[1]:", ": error: phenomena[1]:"),
        "1 error(s), 0 warning(s)",
    ]


def test_a_utu_configuration_is_checked_as_run_takes_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rover = EXAMPLES / "rover"
    utu = tmp_path / "utu.yaml"
    utu.write_text(
        f"anunnaki: utu/1\ngoal_model: {rover / 'goals.yaml'}\nbinding: {rover / 'binding.yaml'}\n"
        f"tactics: {rover / 'tactics.yaml'}\nfailsafe: fail-safe\n"
    )
    assert checked(capsys, str(utu)) == (0, [])
    edit(utu, "failsafe: fail-safe", "failsafe: nope")
    exc = refused(utu)
    assert (exc.path, exc.line, exc.element) == (str(utu), 5, "failsafe")
    assert checked(capsys, str(utu)) == (1, [as_finding(exc)])


def test_tactics_given_with_a_launch_file_replace_the_ones_it_names(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    d = copy_example(tmp_path, "rover")
    other = d / "other-tactics.yaml"
    shutil.copy(d / "tactics-lm.yaml", other)
    line = edit(other, "        domain: fog", "        domain: nosuch") - 2
    assert checked(capsys, str(d / "demo.yaml")) == (0, [])
    code, findings = checked(capsys, str(d / "demo.yaml"), "--tactics", str(other))
    assert code == 1
    assert [(f["path"], f["line"]) for f in findings] == [(str(other), line)]


def test_a_bad_tactic_domain_exits_1_whether_checked_by_launch_or_by_files(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    d = copy_example(tmp_path, "rover")
    no_such_domain(d)
    by_launch = checked(capsys, str(d / "demo.yaml"))
    files = [str(d / f) for f in ("goals-lm.yaml", "binding-enlil.yaml", "tactics-lm.yaml")]
    by_files = checked(capsys, *files)
    assert by_launch[0] == by_files[0] == 1
    assert by_launch[1] == by_files[1]
    assert [f["element"] for f in by_files[1]] == ["tactics[swap-to-fog-model].actions[0]"]


def test_check_lists_every_problem_where_run_stops_at_the_first(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    d = copy_example(tmp_path, "rover")
    smog(d)
    failsafe_not_a_tactic(d)
    no_such_domain(d)
    code, findings = checked(capsys, str(d / "demo.yaml"))
    assert code == 1
    assert [(Path(str(f["path"])).name, f["line"]) for f in findings] == [
        ("tactics-lm.yaml", line_of(d / "tactics-lm.yaml", "domain: nosuch") - 2),
        ("demo.yaml", line_of(d / "demo.yaml", "failsafe:")),
        ("conditions-scenario.yaml", line_of(d / "conditions-scenario.yaml", "smog")),
    ]


def line_of(path: Path, marker: str) -> int:
    return next(i for i, s in enumerate(path.read_text().splitlines(), 1) if marker in s)


@pytest.mark.parametrize(
    ("setup", "code"),
    [
        ("the launch file is missing", 2),
        ("the launch file is a folder", 2),
        ("a launch file and positional files", 2),
        ("the launch file is not valid YAML", 1),
        ("the goal model it names is missing", 1),
    ],
)
def test_exit_codes_of_a_launch_check(
    setup: str, code: int, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    d = copy_example(tmp_path, "rover")
    args = [str(d / "demo.yaml")]
    if setup == "the launch file is missing":
        args = [str(d / "nope.yaml")]
    elif setup == "the launch file is a folder":
        args = [str(d)]
    elif setup == "a launch file and positional files":
        args.append(str(d / "binding-enlil.yaml"))
    elif setup == "the launch file is not valid YAML":
        edit(d / "demo.yaml", "name: rover-demo", "name: [rover-demo")
    elif setup == "the goal model it names is missing":
        (d / "goals-lm.yaml").unlink()
    found, findings = checked(capsys, *args)
    assert found == code and len(findings) == 1, findings


def test_checking_a_launch_starts_nothing_and_imports_no_torch() -> None:
    # the demos' oracle (enlil) and detector need torch and pybullet at run time; the check
    # reads their files and names only, so it stays fast and starts nothing
    probe = (
        "import sys\n"
        "from anunnaki.cli.main import main\n"
        "codes = [main(['check', launch]) for launch in sys.argv[1:]]\n"
        "heavy = sorted(m for m in ('torch', 'pybullet', 'zenoh') if m in sys.modules)\n"
        "print(codes, heavy)\n"
    )
    demos = [str(EXAMPLES / "rover" / "demo.yaml"), str(EXAMPLES / "uav" / "sim.yaml")]
    out = subprocess.run(
        [sys.executable, "-c", probe, *demos],
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    ).stdout
    assert out.splitlines()[-1] == "[0, 0] []", out
