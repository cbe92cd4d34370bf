"""The per-phenomenon oracle network (``oracle_architecture``, ``anunnaki oracle architecture``)."""

from __future__ import annotations

import contextlib
import io
from types import MappingProxyType

import pytest

from anunnaki.cli.main import main
from anunnaki.enlil import (
    DEFAULT_ORACLE_ARCHITECTURE,
    MODEL_ARCHITECTURES,
    ORACLE_ARCHITECTURES,
    PHENOMENON_ARCHITECTURES,
    EnlilError,
    oracle_architecture,
)
from anunnaki.enlil import _oracle_choice as choice


@pytest.fixture
def hsl_patch(monkeypatch: pytest.MonkeyPatch) -> None:
    """A measured choice in the table (today's is empty): hsl names patch_cnn."""
    monkeypatch.setattr(choice, "PHENOMENON_ARCHITECTURES", MappingProxyType({"hsl": "patch_cnn"}))


def test_the_measured_choice() -> None:
    # docs/enlil.md, "Issue 22 at the shipped scale": hsl, raindrop and fog tie, so no
    # phenomenon names a network; rover-default's own figures (false alarms) chose patch_cnn
    assert dict(PHENOMENON_ARCHITECTURES) == {}
    assert dict(MODEL_ARCHITECTURES) == {"rover-default": "patch_cnn",
                                         "rover-low_light": "patch_cnn"}  # fmt: skip
    names = ORACLE_ARCHITECTURES.names()
    assert DEFAULT_ORACLE_ARCHITECTURE == "small_cnn" in names
    assert set(MODEL_ARCHITECTURES.values()) <= set(names)
    everything = ["hsl", "raindrop", "fog", "brightness"]
    for phenomena in (["hsl"], ["raindrop"], ["fog"], everything,
                      ["raindrop+raindrop+raindrop"], []):  # fmt: skip
        assert oracle_architecture(phenomena) == "small_cnn"
    assert oracle_architecture(everything, model_id="rover-default") == "patch_cnn"
    assert oracle_architecture(["hsl"], model_id="rover-hsl") == "small_cnn"  # Enki's
    assert oracle_architecture(["fog"], model_id="rover-fog-enki") == "small_cnn"


def test_the_phenomenon_with_a_choice_decides(hsl_patch: None) -> None:
    assert oracle_architecture(["hsl"]) == "patch_cnn"
    assert oracle_architecture(["raindrop"]) == oracle_architecture(["fog"]) == "small_cnn"
    # one oracle covers all of a model's phenomena: the one with a choice decides
    assert oracle_architecture(["hsl", "raindrop", "fog", "brightness"]) == "patch_cnn"
    assert oracle_architecture(["brightness", "hsl"]) == "patch_cnn"
    assert oracle_architecture([]) == "small_cnn"


def test_compositions_count_each_part(hsl_patch: None) -> None:
    assert oracle_architecture(["raindrop+raindrop+raindrop"]) == "small_cnn"
    assert oracle_architecture(["fog+hsl"]) == "patch_cnn"
    assert oracle_architecture(["rain + brightness"], choices={"brightness": "x"}) == "x"
    # a choice named for a composition (ARCH_rain_brightness in scripts/train-oracles.sh)
    # names each of its parts
    both = ["fog", "rain+brightness"]
    assert oracle_architecture(both, choices={"rain+brightness": "patch_cnn"}) == "patch_cnn"
    assert oracle_architecture(["hsl+fog"], choices={"hsl+fog": ""}) == "small_cnn"


def test_overrides_default_and_dropping_a_choice(hsl_patch: None) -> None:
    assert oracle_architecture(["fog"], choices={"fog": "patch_cnn"}) == "patch_cnn"
    assert oracle_architecture(["hsl"], choices={"hsl": ""}) == "small_cnn"
    assert oracle_architecture(["hsl"], choices={"hsl": None}, default="patch_cnn") == "patch_cnn"
    assert oracle_architecture(["fog"], default="patch_cnn") == "patch_cnn"
    assert dict(choice.PHENOMENON_ARCHITECTURES) == {"hsl": "patch_cnn"}  # not changed


def test_phenomena_of_one_oracle_must_agree() -> None:
    both = {"hsl": "patch_cnn", "raindrop": "small_cnn"}
    with pytest.raises(EnlilError, match="hsl names patch_cnn and raindrop names small_cnn"):
        oracle_architecture(["hsl", "raindrop"], choices=both)
    with pytest.raises(EnlilError, match="robustify --oracle-architecture"):
        oracle_architecture(["hsl+raindrop"], choices=both)


def test_named_choices_come_first_then_the_model_then_the_phenomena(
    hsl_patch: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    # a network named for one of the phenomena beats the measured tables
    assert oracle_architecture(["hsl", "fog"], choices={"fog": "small_cnn"}) == "small_cnn"
    everything = ["hsl", "raindrop", "fog", "brightness"]
    assert oracle_architecture(everything, model_id="rover-default") == "patch_cnn"
    named = {"raindrop": "small_cnn"}
    assert oracle_architecture(everything, model_id="rover-default", choices=named) == "small_cnn"
    assert oracle_architecture(["fog"], model_id="rover-default", choices={"hsl": "x"}) == (
        "patch_cnn"  # a choice for a phenomenon the oracle does not cover changes nothing
    )
    # two measured phenomena that disagree are refused as well
    table = MappingProxyType({"hsl": "patch_cnn", "fog": "small_cnn"})
    monkeypatch.setattr(choice, "PHENOMENON_ARCHITECTURES", table)
    with pytest.raises(EnlilError, match="hsl names patch_cnn and fog names small_cnn"):
        oracle_architecture(["hsl", "fog"])


def _cli(*args: str) -> tuple[int, str]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["oracle", "architecture", *args])
    return code, out.getvalue().strip()


def test_the_cli_prints_the_rule(hsl_patch: None, capsys: pytest.CaptureFixture[str]) -> None:
    assert _cli("hsl", "raindrop", "fog", "brightness") == (0, "patch_cnn")
    assert _cli("fog") == (0, "small_cnn")
    assert _cli("fog", "--model", "rover-default") == (0, "patch_cnn")
    assert _cli("hsl", "--model", "rover-hsl") == (0, "patch_cnn")  # not in the model table
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
    code, _ = _cli("hsl", "raindrop", "--choose", "hsl=patch_cnn", "--choose", "raindrop=small_cnn")
    assert code != 0
    assert "one oracle covers both" in capsys.readouterr().err
