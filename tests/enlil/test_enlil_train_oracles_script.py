"""``scripts/train-oracles.sh``: the oracle architecture each model gets from the variables.

The script asks the rule in code once a run, for all of its models (``anunnaki oracle
architecture --batch``): one interpreter a run, which imports no torch (about 1.5 s quiet;
when it started one a model, with torch, a run took 65-175 s at load 4-11, issue #34): the
timeouts allow for a loaded machine.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "train-oracles.sh"


def choices(tmp_path: Path, *args: str, **env: str) -> tuple[int, dict[str, str], str]:
    """Run ``--print-architectures`` (trains nothing): exit code, model → network, stderr."""
    return script(tmp_path, "--print-architectures", *args, **env)


def script(tmp_path: Path, *args: str, **env: str) -> tuple[int, dict[str, str], str]:
    """Run the script: exit code, the rows it printed (model → network), stderr."""
    clean = {k: v for k, v in os.environ.items() if not k.startswith("ARCH")}
    clean["PY"] = sys.executable
    result = subprocess.run(
        ["bash", str(SCRIPT), *args],
        env=clean | {"RUNS": str(tmp_path / "runs"), "DATA": str(tmp_path / "data")} | env,
        capture_output=True,
        text=True,
        timeout=900,
        check=False,
    )
    rows = dict(line.split("\t") for line in result.stdout.splitlines())
    return result.returncode, rows, result.stderr


@pytest.mark.timeout(600)  # a loaded machine (module docstring)
def test_the_measured_choice_by_default(tmp_path: Path) -> None:
    code, rows, _ = choices(tmp_path)
    assert code == 0
    # no phenomenon names a network (docs/enlil.md, "Issue 22 at the shipped scale"), so
    # small_cnn but for the models measured (or kept) as patch_cnn
    # (the rover's Enki models' oracles come with their models: scripts/train-domains.sh)
    assert rows == {"rover-default": "patch_cnn", "rover-low_light": "patch_cnn",
                    "uav-default": "small_cnn", "uav-fog": "small_cnn",
                    "uav-rain_brightness": "small_cnn"}  # fmt: skip
    assert not (tmp_path / "runs").exists() and not (tmp_path / "data").exists()


@pytest.mark.timeout(600)  # a loaded machine (module docstring)
def test_a_phenomenon_s_choice_reaches_the_models_with_it(tmp_path: Path) -> None:
    code, rows, _ = choices(tmp_path, ARCH_fog="patch_cnn")
    assert code == 0
    # every model covers fog but rover-low_light (brightness, hsl)
    assert rows == {"rover-default": "patch_cnn", "rover-low_light": "patch_cnn",
                    "uav-default": "patch_cnn", "uav-fog": "patch_cnn",
                    "uav-rain_brightness": "patch_cnn"}  # fmt: skip
    code, rows, _ = choices(tmp_path, ARCH_brightness="patch_cnn")
    assert code == 0
    assert rows["uav-default"] == rows["uav-fog"] == "small_cnn"


@pytest.mark.timeout(600)  # a loaded machine (module docstring)
def test_per_model_and_the_default(tmp_path: Path) -> None:
    code, rows, _ = choices(tmp_path, ARCH="patch_cnn")
    assert code == 0
    assert rows["uav-default"] == "patch_cnn"  # nothing names its network: the default
    code, rows, _ = choices(tmp_path, ARCH="patch_cnn", ARCH_uav_default="small_cnn")
    assert code == 0
    assert rows["uav-default"] == "small_cnn"  # its own beats the default


@pytest.mark.timeout(600)  # a loaded machine (module docstring)
def test_phenomena_of_one_oracle_must_agree(tmp_path: Path) -> None:
    code, _, err = choices(tmp_path, ARCH_hsl="patch_cnn", ARCH_raindrop="small_cnn")
    assert code == 1
    assert "phenomenon hsl names patch_cnn and raindrop names small_cnn" in err
    assert "no oracle network for rover-default (above): set ARCH_rover_default" in err
    code, rows, _ = choices(
        tmp_path, ARCH_hsl="patch_cnn", ARCH_raindrop="small_cnn", ARCH_rover_default="patch_cnn"
    )
    assert code == 0 and rows["rover-default"] == "patch_cnn"


@pytest.mark.timeout(600)  # a loaded machine (module docstring)
def test_a_composition_is_named_with_underscores(tmp_path: Path) -> None:
    # uav-default covers fog and rain+brightness: ARCH_rain+brightness is no shell name;
    # the composition's choice names each of its parts (rain, brightness)
    code, rows, err = choices(tmp_path, ARCH_rain_brightness="patch_cnn")
    assert code == 0, err
    assert rows["uav-default"] == "patch_cnn" and rows["rover-low_light"] == "patch_cnn"
    assert rows["uav-fog"] == rows["uav-rain_brightness"] == "patch_cnn"  # both phenomena
    code, _, err = choices(
        tmp_path, ARCH_hsl="", ARCH_rain_brightness="patch_cnn", ARCH_fog="small_cnn"
    )
    assert code == 1
    assert "phenomenon fog names small_cnn and rain names patch_cnn" in err
    assert "no oracle network for uav-default (above): set ARCH_uav_default" in err


@pytest.mark.timeout(600)  # a loaded machine (module docstring)
def test_a_conflict_stops_the_script_before_its_first_step(tmp_path: Path) -> None:
    # every network is asked before anything runs: the conflict of the third model stops
    # the script before the rover's dataset of the first (its step would print "==> ...")
    code, rows, err = script(
        tmp_path, ARCH_rain_brightness="patch_cnn", ARCH_fog="small_cnn", ARCH_hsl=""
    )
    assert code == 1 and rows == {}
    assert "no oracle network for uav-default (above): set ARCH_uav_default" in err
    assert "==>" not in err
    assert not (tmp_path / "runs").exists() and not (tmp_path / "data").exists()
    # the models named choose what is asked: without uav-default nothing conflicts
    code, rows, err = choices(tmp_path, "rover-low_light", "uav-fog", ARCH_fog="patch_cnn")
    assert code == 0, err
    assert rows == {"rover-low_light": "patch_cnn", "uav-fog": "patch_cnn"}
