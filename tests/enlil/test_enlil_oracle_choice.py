"""The per-phenomenon oracle network (``oracle_architecture``, ``anunnaki oracle architecture``)."""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys
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


def _batch(monkeypatch: pytest.MonkeyPatch, lines: str, *args: str) -> tuple[int, str]:
    monkeypatch.setattr("sys.stdin", io.StringIO(lines))
    return _cli("--batch", *args)


def test_the_cli_answers_many_oracles_at_once(
    hsl_patch: None, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    # one line an oracle, as one call's arguments; each answer is ID<tab>network
    lines = (
        "hsl raindrop fog brightness --model rover-default\n"
        "\n"
        "fog 'rain+brightness' --model uav-default --choose fog=patch_cnn\n"
        "fog --model uav-fog --default patch_cnn\n"
        "raindrop --model rover-raindrop\n"
    )
    code, out = _batch(monkeypatch, lines)
    assert code == 0
    assert out.splitlines() == [
        "rover-default\tpatch_cnn",
        "uav-default\tpatch_cnn",
        "uav-fog\tpatch_cnn",
        "rover-raindrop\tsmall_cnn",
    ]
    # the command line's --choose and --default reach every line, before the line's own
    code, out = _batch(
        monkeypatch,
        "raindrop --model a\nhsl --model b --choose hsl=small_cnn\n",
        "--default",
        "patch_cnn",
        "--choose",
        "hsl=patch_cnn",
    )
    assert (code, out.splitlines()) == (0, ["a\tpatch_cnn", "b\tsmall_cnn"])
    # the first line that fails stops the answers, naming its line
    capsys.readouterr()
    lines = (
        "fog --model a\n"
        "hsl raindrop --model b --choose hsl=patch_cnn --choose raindrop=small_cnn\n"
        "fog --model c\n"
    )
    code, out = _batch(monkeypatch, lines)
    assert (code, out) == (2, "a\tsmall_cnn")
    err = capsys.readouterr().err
    assert "stdin line 2" in err and "hsl names patch_cnn and raindrop names small_cnn" in err


@pytest.mark.parametrize(
    ("args", "lines", "message"),
    [
        ((), "fog\n", "stdin line 1 ('fog'): no --model"),
        ((), "fog --model a --nope\n", "unrecognized arguments: --nope"),
        ((), "--model a\n", "required: phenomenon"),
        ((), "fog --model 'a\n", "No closing quotation"),
        ((), "fog --model a --choose fog=no_such_net\n", "'no_such_net': no such oracle"),
        (("fog",), "", "the command line names none"),
        (("--model", "a"), "", "the command line names none"),
    ],
)
def test_a_bad_batch_is_refused_naming_the_fix(
    args: tuple[str, ...],
    lines: str,
    message: str,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    capsys.readouterr()
    code, out = _batch(monkeypatch, lines, *args)
    assert (code, out) == (2, "")
    assert message in capsys.readouterr().err


def test_the_cli_needs_phenomena_or_a_batch(capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert _cli() == (2, "")
    assert "name the oracle's phenomena" in capsys.readouterr().err


def test_asking_imports_no_torch() -> None:
    # scripts/train-oracles.sh and robustify ask before anything is trained: an interpreter
    # that imports torch for it took 3-13 s on the 2-core machine (issue #34, item 10)
    probe = (
        "import contextlib, io, sys\n"
        "from anunnaki.cli.main import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    code = main(['oracle', 'architecture', 'fog', '--model', 'uav-default'])\n"
        "import anunnaki.enlil\n"
        "print(code, 'torch' in sys.modules)\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=300, check=True
    )
    assert result.stdout.split() == ["0", "False"], result.stderr
