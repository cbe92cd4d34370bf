"""The per-phenomenon oracle network (``oracle_architecture``, ``anunnaki oracle architecture``)."""

from __future__ import annotations

import contextlib
import io

import pytest

from anunnaki.cli.main import main
from anunnaki.enlil import (
    DEFAULT_ORACLE_ARCHITECTURE,
    ORACLE_ARCHITECTURES,
    PHENOMENON_ARCHITECTURES,
    EnlilError,
    oracle_architecture,
)


def test_the_measured_choice() -> None:
    # docs/enlil.md, "Issue 22": patch_cnn for hsl, no preference elsewhere (small_cnn)
    assert dict(PHENOMENON_ARCHITECTURES) == {"hsl": "patch_cnn"}
    assert DEFAULT_ORACLE_ARCHITECTURE == "small_cnn"
    assert set(PHENOMENON_ARCHITECTURES.values()) <= set(ORACLE_ARCHITECTURES.names())
    assert oracle_architecture(["hsl"]) == "patch_cnn"
    assert oracle_architecture(["raindrop"]) == oracle_architecture(["fog"]) == "small_cnn"
    # one oracle covers all of a model's phenomena: the one with a choice decides
    assert oracle_architecture(["hsl", "raindrop", "fog", "brightness"]) == "patch_cnn"
    assert oracle_architecture(["brightness", "hsl"]) == "patch_cnn"
    assert oracle_architecture([]) == "small_cnn"


def test_compositions_count_each_part() -> None:
    assert oracle_architecture(["raindrop+raindrop+raindrop"]) == "small_cnn"
    assert oracle_architecture(["fog+hsl"]) == "patch_cnn"
    assert oracle_architecture(["rain + brightness"], choices={"brightness": "x"}) == "x"


def test_overrides_default_and_dropping_a_choice() -> None:
    assert oracle_architecture(["fog"], choices={"fog": "patch_cnn"}) == "patch_cnn"
    assert oracle_architecture(["hsl"], choices={"hsl": ""}) == "small_cnn"
    assert oracle_architecture(["hsl"], choices={"hsl": None}, default="patch_cnn") == "patch_cnn"
    assert oracle_architecture(["fog"], default="patch_cnn") == "patch_cnn"
    assert dict(PHENOMENON_ARCHITECTURES) == {"hsl": "patch_cnn"}  # the table is not changed


def test_phenomena_of_one_oracle_must_agree() -> None:
    with pytest.raises(EnlilError, match="hsl names patch_cnn and raindrop names small_cnn"):
        oracle_architecture(["hsl", "raindrop"], choices={"raindrop": "small_cnn"})
    with pytest.raises(EnlilError, match="robustify --oracle-architecture"):
        oracle_architecture(["hsl+raindrop"], choices={"raindrop": "small_cnn"})


def _cli(*args: str) -> tuple[int, str]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["oracle", "architecture", *args])
    return code, out.getvalue().strip()


def test_the_cli_prints_the_rule(capsys: pytest.CaptureFixture[str]) -> None:
    assert _cli("hsl", "raindrop", "fog", "brightness") == (0, "patch_cnn")
    assert _cli("fog") == (0, "small_cnn")
    assert _cli("fog", "--default", "patch_cnn") == (0, "patch_cnn")
    assert _cli("hsl", "--choose", "hsl=") == (0, "small_cnn")
    assert _cli("raindrop", "--choose", "raindrop=patch_cnn") == (0, "patch_cnn")
    capsys.readouterr()
    code, _ = _cli("hsl", "--choose", "patch_cnn")
    assert code != 0
    assert "write PHENOMENON=ARCH" in capsys.readouterr().err
    code, _ = _cli("fog", "--choose", "fog=no_such_net")
    assert code != 0
    err = capsys.readouterr().err
    assert "'no_such_net': no such oracle architecture" in err and "patch_cnn" in err
    code, _ = _cli("hsl", "raindrop", "--choose", "raindrop=small_cnn")
    assert code != 0
    assert "one oracle covers both" in capsys.readouterr().err
