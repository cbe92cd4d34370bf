"""scripts/setup.sh: the demo and test profiles, the stamp that makes a re-run install nothing.

Run on a copy of the script beside a stand-in ``.venv/bin/python`` that records each ``pip
install`` instead of installing, and stand-ins for the root-only apt scripts and the ROS 2
environment's (issue #34, item 9: ``make demo`` installed the browser, ROS 1 and every test
extra).
"""

from __future__ import annotations

import os
import re
import shutil
import stat
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SETUP = ROOT / "scripts" / "setup.sh"


def profile(name: str) -> list[str]:
    """The extras of a profile of scripts/setup.sh (``DEMO_EXTRAS=…``)."""
    m = re.search(rf"^{name.upper()}_EXTRAS=(\S+)$", SETUP.read_text("utf-8"), re.MULTILINE)
    assert m, f"no {name.upper()}_EXTRAS= line in {SETUP}"
    return m.group(1).split(",")


def _executable(path: Path, text: str) -> None:
    path.write_text(text, "utf-8")
    path.chmod(path.stat().st_mode | stat.S_IXUSR)


@pytest.fixture()
def checkout(tmp_path: Path) -> Path:
    """A folder with the script, pyproject.toml, constraints.txt and the stand-ins."""
    (tmp_path / "scripts").mkdir()
    shutil.copy(SETUP, tmp_path / "scripts" / "setup.sh")
    for name in ("pyproject.toml", "constraints.txt"):
        shutil.copy(ROOT / name, tmp_path / name)
    for name in ("setup-browser.sh", "setup-ros.sh", "setup-ros2.sh"):
        _executable(tmp_path / "scripts" / name, f"#!/bin/sh\necho {name} >> calls.log\n")
    (tmp_path / ".venv" / "bin").mkdir(parents=True)
    _executable(tmp_path / ".venv" / "bin" / "python", '#!/bin/sh\necho "pip $*" >> calls.log\n')
    return tmp_path


def setup(checkout: Path, *args: str, script: str = "setup.sh") -> list[str]:
    """Run the script; the calls it made (apt scripts, pip installs) in order."""
    log = checkout / "calls.log"
    log.unlink(missing_ok=True)
    env = {k: v for k, v in os.environ.items() if k != "ANUNNAKI_EXTRAS"}
    out = subprocess.run(
        ["bash", str(checkout / "scripts" / script), *args],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    assert out.returncode == 0, out.stderr
    return log.read_text("utf-8").splitlines() if log.exists() else []


def installed(call: str) -> set[str]:
    m = re.search(r"-e \.\[([^\]]*)\]", call)
    assert m and call.startswith("pip -m pip install"), call
    return set(m.group(1).split(","))


def test_the_demo_profile_installs_its_extras_and_nothing_as_root(checkout: Path) -> None:
    calls = setup(checkout, "demo")
    assert len(calls) == 1 and installed(calls[0]) == set(profile("demo"))
    assert not {"dev", "bus", "enlil", "ros"} & set(profile("demo"))
    assert setup(checkout, "demo") == []  # a re-run installs nothing


def test_the_test_profile_adds_the_rest_after_the_demo(checkout: Path) -> None:
    setup(checkout, "demo")
    calls = setup(checkout, "test")
    helpers = ["setup-browser.sh", "setup-ros.sh", "setup-ros2.sh"]  # ROS 2 in .venv-ros2
    assert calls[:3] == helpers
    assert len(calls) == 4 and installed(calls[3]) == set(profile("test")) | set(profile("demo"))
    assert setup(checkout, "demo") == []  # everything the demo needs is there
    assert setup(checkout) == helpers  # test is the default


def test_a_changed_pyproject_installs_again(checkout: Path) -> None:
    setup(checkout, "demo")
    with (checkout / "pyproject.toml").open("a") as fh:
        fh.write("\n# changed\n")
    calls = setup(checkout, "demo")
    assert len(calls) == 1 and installed(calls[0]) == set(profile("demo"))


def test_an_unknown_profile_is_refused(checkout: Path) -> None:
    out = subprocess.run(
        ["bash", str(checkout / "scripts" / "setup.sh"), "all"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert out.returncode == 2 and "usage: scripts/setup.sh [demo|test] (got 'all')" in out.stderr


def test_the_readme_says_what_each_command_installs() -> None:
    readme = " ".join(ROOT.joinpath("README.md").read_text("utf-8").split())
    for name in ("demo", "test"):
        extras = ",".join(profile(name))
        assert f"`make {name}` installs" in readme
        assert f"`{extras}`" in readme, f"the README does not list the {name} extras {extras}"


def test_a_ros2_environment_copied_from_another_checkout_is_installed_again(
    tmp_path: Path,
) -> None:
    # .venv-ros2 holds the checkout's path (anunnaki installed editable): its stamp says
    # which checkout, so a copy made elsewhere is not taken as ready (it would import the
    # other checkout's code)
    first = tmp_path / "first"
    (first / "scripts").mkdir(parents=True)
    shutil.copy(ROOT / "scripts" / "setup-ros2.sh", first / "scripts" / "setup-ros2.sh")
    shutil.copy(ROOT / "pyproject.toml", first / "pyproject.toml")
    (first / ".venv-ros2" / "bin").mkdir(parents=True)
    _executable(first / ".venv-ros2" / "bin" / "python", '#!/bin/sh\necho "$*" >> calls.log\n')

    def calls(where: Path) -> list[str]:
        return setup(where, script="setup-ros2.sh")

    assert any("install" in c and "-e .[ros]" in c for c in calls(first))
    assert calls(first) == []  # ready: a re-run installs nothing
    second = tmp_path / "second"
    shutil.copytree(first, second, symlinks=True)
    assert any("install" in c and "-e .[ros]" in c for c in calls(second))
