"""``anunnaki sim --bus``: the bus kinds registry's kinds, one installed by entry point too."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator
from pathlib import Path
from types import ModuleType

import pytest

from anunnaki.bus import BUS_KINDS
from anunnaki.cli.main import main

#: A third party's transport, as its own distribution would ship it: a factory in group
#: ``anunnaki.buses`` (here an in-process bus that counts the sessions opened with it).
PLUGIN = """
from anunnaki.bus import InprocBus

OPENED = []


def loopbus(config, *, clock=None, hub=None):
    OPENED.append(config.name)
    return InprocBus(hub=hub, namespace=config.namespace, name=config.name, clock=clock)
"""

TINY = ["--until", "1", "--speed", "0", "--width", "32", "--height", "32", "--quiet"]


@pytest.fixture
def installed(install_distribution: Callable[..., Path]) -> Iterator[ModuleType]:
    """The plugin's distribution, installed as pip would."""
    install_distribution(
        "anunnaki-loopbus",
        {"anunnaki.buses": {"loopbus": "anunnaki_loopbus:loopbus"}},
        modules={"anunnaki_loopbus": PLUGIN},
    )
    BUS_KINDS.load_entry_points(force=True)
    try:
        yield importlib.import_module("anunnaki_loopbus")
    finally:
        BUS_KINDS.unregister("loopbus")


def test_the_help_offers_every_bus_kind(
    installed: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as done:
        main(["sim", "--help"])
    assert done.value.code == 0
    help_text = " ".join(capsys.readouterr().out.split())
    assert f"bus kind: {', '.join(BUS_KINDS.names())} (default inproc)" in help_text
    assert {"inproc", "zenoh", "loopbus"} <= set(BUS_KINDS.names())


def test_a_bus_kind_installed_by_entry_point_runs_the_simulation(
    installed: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["sim", "rover", "--bus", "loopbus", *TINY]) == 0
    assert installed.OPENED == ["sim-rover"]
    out = capsys.readouterr().out
    assert "done at t=1.00s: 10 frames" in out and "listening" not in out


def test_an_unknown_bus_kind_is_refused_with_the_valid_ones(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(SystemExit) as done:
        main(["sim", "rover", "--bus", "shm"])
    assert done.value.code == 2
    err = capsys.readouterr().err
    assert "argument --bus: invalid choice: 'shm'" in err
    assert all(f"'{name}'" in err for name in BUS_KINDS.names())


def test_endpoints_for_a_kind_that_does_not_listen_are_refused(
    capsys: pytest.CaptureFixture[str],
) -> None:
    code = main(["sim", "rover", "--bus", "inproc", "--listen", "tcp/127.0.0.1:0", *TINY])
    assert code == 2
    assert "listen only apply to the zenoh bus" in capsys.readouterr().err


def test_a_zenoh_sim_says_where_the_others_join_it(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "uav", "--bus", "zenoh", *TINY]) == 0
    (line,) = [ln for ln in capsys.readouterr().out.splitlines() if "listening" in ln]
    assert line.startswith("zenoh peer listening on tcp/127.0.0.1:"), line
