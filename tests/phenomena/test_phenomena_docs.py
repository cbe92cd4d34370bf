"""docs/phenomena.md agrees with the code; its example and figure script run.

Its benchmark's quick mode is tests/benchmarks/test_phenomena_benchmark.py.
"""

from __future__ import annotations

import re
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from anunnaki.phenomena import PHENOMENA, Phenomenon, synthetic_scene

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "phenomena.md"


def doc_text() -> str:
    return DOC.read_text(encoding="utf-8")


def code_block_after(marker: str) -> str:
    """The fenced Python block that contains *marker*."""
    for block in re.findall(r"```python\n(.*?)```", doc_text(), flags=re.DOTALL):
        if marker in block:
            return block
    raise AssertionError(f"no python block with {marker!r} in {DOC}")


@pytest.mark.parametrize("name", PHENOMENA.names())
def test_parameter_tables_match_the_code(name: str) -> None:
    text = doc_text()
    assert f"### `{name}`" in text
    for spec in PHENOMENA.create(name).params:
        default = "required" if spec.default is None else f"{spec.default:g}"
        integer = " (integer)" if spec.integer else ""
        row = (
            f"| `{spec.name}` | {spec.low:g} … {spec.high:g}{integer} | {spec.unit} | "
            f"{spec.default_identity:g} | {default} | {spec.description} |"
        )
        assert row in text, f"docs/phenomena.md lacks or misstates:\n{row}"


def test_usage_example_runs_as_documented() -> None:
    namespace: dict[str, object] = {}
    exec(code_block_after("synthetic_scene(128, 128)"), namespace)
    fog = namespace["fog"]
    assert isinstance(fog, Phenomenon)
    assert fog.bounds() == [(1.0, 10.0), (0.0, 1.0)]
    assert fog.from_vector([4.3, 0.3]) == {"density": 4.0, "intensity": 0.3}
    assert fog.strength_params(0.5) == {"density": 6.0, "intensity": 0.15}
    assert namespace["rainy_lens"].param_names[:3] == (  # type: ignore[attr-defined]
        "rain.intensity",
        "rain.slant",
        "rain.drop_length",
    )


def test_plugin_example_is_complete_and_passes_basic_checks() -> None:
    module = types.ModuleType("anunnaki_sepia")
    exec(code_block_after("class Sepia(Phenomenon)"), module.__dict__)
    registry = PHENOMENA.copy(entry_points=False)
    registry.register(module.Sepia)
    sepia = registry.create("sepia")
    image = synthetic_scene(64, 64)
    np.testing.assert_array_equal(sepia.apply(image, sepia.identity_params(), seed=0), image)
    strong = sepia.strength_params(1.0)
    assert sepia.apply(image, strong, seed=1).tobytes() == sepia.apply(image, strong, 1).tobytes()
    assert sepia.apply(image, strong, seed=1).tobytes() != sepia.apply(image, strong, 2).tobytes()
    assert '[project.entry-points."anunnaki.phenomena"]' in doc_text()
    assert 'sepia = "anunnaki_sepia:Sepia"' in doc_text()


def test_figure_is_in_the_doc_and_the_script_writes_it(tmp_path: Path) -> None:
    assert "](images/phenomena.png)" in doc_text()
    assert (ROOT / "docs" / "images" / "phenomena.png").is_file()
    output = tmp_path / "figure.png"
    subprocess.run(
        [sys.executable, str(ROOT / "docs" / "make_phenomena_figure.py"), "--output", str(output)],
        check=True,
        timeout=120,
        capture_output=True,
    )
    assert output.read_bytes().startswith(b"\x89PNG")


def test_occlusion_example_runs_as_documented() -> None:
    namespace: dict[str, object] = {}
    exec(code_block_after("drops.occlusion(frame.shape"), namespace)
    mask = namespace["mask"]
    assert isinstance(mask, np.ndarray) and mask.shape == (96, 128)
    assert isinstance(namespace["hidden"], np.bool_ | bool)
