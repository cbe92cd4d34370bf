"""``scripts/train-oracles.sh``: the oracle architecture each model gets from the variables."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "train-oracles.sh"


def choices(tmp_path: Path, **env: str) -> tuple[int, dict[str, str], str]:
    """Run ``--print-architectures`` (trains nothing): exit code, model → network, stderr."""
    clean = {k: v for k, v in os.environ.items() if not k.startswith("ARCH")}
    result = subprocess.run(
        ["bash", str(SCRIPT), "--print-architectures"],
        env=clean | {"RUNS": str(tmp_path / "runs"), "DATA": str(tmp_path / "data")} | env,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    rows = dict(line.split("\t") for line in result.stdout.splitlines())
    return result.returncode, rows, result.stderr


def test_the_measured_choice_by_default(tmp_path: Path) -> None:
    code, rows, _ = choices(tmp_path)
    assert code == 0
    # patch_cnn for hsl (docs/enlil.md, "Issue 22"): the models with hsl among their phenomena
    assert rows == {"rover-default": "patch_cnn", "rover-fog": "small_cnn",
                    "rover-low_light": "patch_cnn", "uav-default": "small_cnn"}  # fmt: skip
    assert not (tmp_path / "runs").exists() and not (tmp_path / "data").exists()


def test_small_cnn_unless_a_variable_names_another(tmp_path: Path) -> None:
    code, rows, _ = choices(tmp_path, ARCH_hsl="")  # an empty variable drops the default
    assert code == 0
    assert rows == dict.fromkeys(("rover-default", "rover-fog", "rover-low_light",
                                  "uav-default"), "small_cnn")  # fmt: skip


def test_per_phenomenon_then_per_model(tmp_path: Path) -> None:
    code, rows, _ = choices(tmp_path, ARCH_hsl="patch_cnn", ARCH_raindrop="patch_cnn")
    assert code == 0
    # rover-default covers hsl and raindrop, rover-low_light hsl; the fog-only ones do not
    assert rows == {"rover-default": "patch_cnn", "rover-fog": "small_cnn",
                    "rover-low_light": "patch_cnn", "uav-default": "small_cnn"}  # fmt: skip
    code, rows, _ = choices(tmp_path, ARCH="patch_cnn", ARCH_rover_fog="small_cnn")
    assert rows["rover-fog"] == "small_cnn" and rows["uav-default"] == "patch_cnn"


def test_phenomena_of_one_oracle_must_agree(tmp_path: Path) -> None:
    code, _, err = choices(tmp_path, ARCH_hsl="patch_cnn", ARCH_raindrop="small_cnn")
    assert code == 1
    assert "rover-default's phenomena name different architectures" in err
    assert "set ARCH_rover_default" in err
    code, rows, _ = choices(
        tmp_path, ARCH_hsl="patch_cnn", ARCH_raindrop="small_cnn", ARCH_rover_default="patch_cnn"
    )
    assert code == 0 and rows["rover-default"] == "patch_cnn"


def test_a_composition_is_named_with_underscores(tmp_path: Path) -> None:
    # uav-default covers fog and rain+brightness: ARCH_rain+brightness is no shell name
    code, rows, err = choices(tmp_path, ARCH_rain_brightness="patch_cnn")
    assert code == 0, err
    assert rows["uav-default"] == "patch_cnn" and rows["rover-fog"] == "small_cnn"
    code, _, err = choices(
        tmp_path, ARCH_hsl="", ARCH_rain_brightness="patch_cnn", ARCH_fog="small_cnn"
    )
    assert code == 1 and "uav-default's phenomena" in err
    assert "ARCH_rain_brightness=patch_cnn" in err
