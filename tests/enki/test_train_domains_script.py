"""``scripts/train-domains.sh`` and ``scripts/describe-domain.py``: the shipped Enki models."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from anunnaki.lec import load_registry

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = ROOT / "scripts"
MODELS = ROOT / "examples" / "models"


def scratch_models(tmp_path: Path) -> Path:
    """A scratch copy of the rover's registry with rover-default and rover-hsl."""
    folder = tmp_path / "models"
    folder.mkdir()
    for name in ("rover-default", "rover-hsl"):
        for suffix in (".safetensors", ".json", ".oracle.safetensors", ".oracle.json"):
            shutil.copy(MODELS / f"{name}{suffix}", folder / f"{name}{suffix}")
    text = (MODELS / "rover.yaml").read_text(encoding="utf-8")
    keep = [e for e in text.split("\n  - id: ")[1:] if e.startswith(("rover-default", "rover-hsl"))]
    (folder / "rover.yaml").write_text(
        text.split("\n  - id: ")[0] + "".join("\n  - id: " + e for e in keep), encoding="utf-8"
    )
    return folder


def test_a_registered_model_is_not_trained_again(tmp_path: Path) -> None:
    models = scratch_models(tmp_path)
    before = (models / "rover.yaml").read_text(encoding="utf-8")
    env = {"MODELS": str(models), "RUNS": str(tmp_path / "runs"), "PY": sys.executable}
    result = subprocess.run(
        ["bash", str(SCRIPTS / "train-domains.sh"), "rover-hsl"],
        env=os.environ | env | {"DATA": str(tmp_path / "data")},
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert f"rover-hsl is in {models}/rover.yaml already" in result.stderr
    assert (models / "rover.yaml").read_text(encoding="utf-8") == before
    assert not (tmp_path / "data").exists()  # nothing rendered, nothing trained
    times = (tmp_path / "runs" / "times.tsv").read_text(encoding="utf-8").splitlines()
    assert times == ["step\tseconds\tload average (1 min) at start"]


def test_the_description_carries_the_sidecars_figures(tmp_path: Path) -> None:
    models = scratch_models(tmp_path)
    registry = models / "rover.yaml"
    lines = registry.read_text(encoding="utf-8").splitlines()
    k = lines.index("  - id: rover-hsl")
    d = next(i for i in range(k, len(lines)) if lines[i].startswith("    description:"))
    lines[d] = "    description: clean F1 only"
    registry.write_text("\n".join(lines) + "\n", encoding="utf-8")
    subprocess.run(
        [sys.executable, str(SCRIPTS / "describe-domain.py"), str(registry), "rover-hsl"],
        check=True,
        timeout=60,
    )
    after = registry.read_text(encoding="utf-8").splitlines()
    assert [i for i, (a, b) in enumerate(zip(lines, after, strict=True)) if a != b] == [d]
    sidecar = json.loads((models / "rover-hsl.json").read_text(encoding="utf-8"))
    clean = sidecar["metrics"]["enki"]["clean"]
    spec = load_registry(registry).get("rover-hsl")
    assert spec.description.startswith("Enki (hsl, seed 0): test F1 ")
    assert f"{clean['new']:.3f} clean (rover-default {clean['input']:.3f})" in spec.description
    assert "oracle val accuracy" in spec.description


def test_an_unknown_model_is_refused(tmp_path: Path) -> None:
    models = scratch_models(tmp_path)
    result = subprocess.run(
        [sys.executable, str(SCRIPTS / "describe-domain.py"), str(models / "rover.yaml"), "x"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode != 0 and "'x'" in result.stderr


#: The shipped Enki models: registry, id, domain.
SHIPPED = [
    ("rover.yaml", "rover-hsl", "hsl"),
    ("rover.yaml", "rover-raindrop", "raindrop"),
    ("uav.yaml", "uav-fog", "fog"),
    ("rover.yaml", "rover-fog-enki", "fog"),
    ("uav.yaml", "uav-rain_brightness", "rain_brightness"),
]


@pytest.mark.parametrize(("registry", "name", "domain"), SHIPPED)
def test_the_shipped_entry_matches_its_sidecar(registry: str, name: str, domain: str) -> None:
    """The shipped description line is what describe-domain.py writes from the sidecars."""
    spec = load_registry(MODELS / registry).get(name)
    assert spec.domain == domain and spec.oracle is not None
    sys.path.insert(0, str(SCRIPTS))
    try:
        import importlib

        describe = importlib.import_module("describe-domain").describe
    finally:
        sys.path.remove(str(SCRIPTS))
    model = json.loads(spec.file.with_suffix(".json").read_text(encoding="utf-8"))
    oracle = json.loads(spec.oracle.file.with_suffix(".json").read_text(encoding="utf-8"))
    assert spec.description == describe(model, oracle)
