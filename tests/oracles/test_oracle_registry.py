"""The oracle slot: by name or by object, runtime registration, entry-point plugins."""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from anunnaki.errors import AnunnakiError
from anunnaki.messages import Assessment
from anunnaki.oracles import (
    ORACLES,
    GroundTruthAssessor,
    Oracle,
    OracleError,
)


class Constant:
    """A minimal oracle: always the same category."""

    name = "constant"

    def __init__(self, category: int = 0) -> None:
        self.category = category

    def assess(self, frame: np.ndarray, *, seq: int, model_id: str) -> Assessment:
        return Assessment(category=self.category, confidence=1.0, model_id=model_id,
                          assessor=self.name, frame_seq=seq)  # fmt: skip


def test_builtins_by_name_with_options() -> None:
    assert "ground_truth" in ORACLES.names()
    assert ORACLES.copy(entry_points=False).names() == ["ground_truth"]
    assert {"enlil", "light"} <= set(ORACLES.names())  # pyproject.toml's entry points
    oracle = ORACLES.create("ground_truth", window=12, clean_f1=0.9)
    assert isinstance(oracle, GroundTruthAssessor) and oracle.window == 12
    assert isinstance(ORACLES.create(" ground_truth "), GroundTruthAssessor)


def test_instances_pass_through() -> None:
    mine = Constant(2)
    assert ORACLES.create(mine) is mine
    assert isinstance(mine, Oracle)
    with pytest.raises(OracleError, match="apply when an oracle is built by name"):
        ORACLES.create(mine, window=3)


def test_unknown_names_list_the_valid_ones() -> None:
    with pytest.raises(OracleError, match="unknown oracle 'enlil_fog'; valid names: ") as info:
        ORACLES.create("enlil_fog")
    assert "ground_truth" in str(info.value)
    assert isinstance(info.value, AnunnakiError) and isinstance(info.value, ValueError)


@pytest.mark.parametrize("bad", [None, 3, Constant, ["ground_truth"], object()])
def test_other_arguments_are_refused(bad: Any) -> None:
    with pytest.raises(OracleError, match="expected an oracle name or an Oracle instance"):
        ORACLES.create(bad)


def test_bad_options_name_the_oracle() -> None:
    with pytest.raises(OracleError, match="oracle 'ground_truth': bad options \\['colour'\\]"):
        ORACLES.create("ground_truth", colour="red")


def test_register_in_code() -> None:
    registry = ORACLES.copy(entry_points=False)
    assert registry.register(Constant) is Constant
    oracle = registry.create("constant", category=1)
    assert isinstance(oracle, Constant) and oracle.category == 1
    registry.register(Constant)  # the same class again: harmless
    assert "constant" not in ORACLES.names()  # the copy is private

    class Other(Constant):
        pass

    with pytest.raises(OracleError, match="already registered as 'constant'"):
        registry.register(Other)
    registry.register(Other, replace=True)
    assert type(registry.create("constant")) is Other


def test_the_slot_registers_by_decorator() -> None:
    @ORACLES.register
    class Steady(Constant):
        name = "steady"

    try:
        assert isinstance(ORACLES.create("steady"), Steady)
    finally:
        ORACLES.unregister("steady")
    assert "steady" not in ORACLES.names()


@pytest.mark.parametrize(
    ("cls", "message"),
    [
        (Constant(), "is not a class"),
        (type("NoAssess", (), {"name": "x"}), "has no assess"),
        (type("NoName", (), {"assess": lambda self: None}), "must be an identifier"),
        (type("BadName", (), {"name": "my oracle", "assess": lambda self: None}), "identifier"),
    ],
)
def test_malformed_classes_are_refused(cls: Any, message: str) -> None:
    with pytest.raises(OracleError, match=message):
        ORACLES.copy().register(cls)


PLUGIN = '''
"""A fake third-party oracle package."""
from anunnaki.messages import Assessment


class Haze:
    name = "haze"

    def __init__(self, level=1):
        self.level = level

    def assess(self, frame, *, seq, model_id):
        return Assessment(category=self.level, confidence=0.5, model_id=model_id,
                          assessor=self.name, frame_seq=seq)


class FakeGroundTruth(Haze):
    name = "ground_truth"


class Renamed(Haze):
    name = "renamed_haze"


NOT_AN_ORACLE = 42
'''


ENTRY_POINTS = {
    "haze": "fake_oracle_plugin:Haze",
    "broken": "fake_no_such_oracle_module:Nope",
    "answer": "fake_oracle_plugin:NOT_AN_ORACLE",
    "ground_truth": "fake_oracle_plugin:FakeGroundTruth",
    "other_name": "fake_oracle_plugin:Renamed",
}


def test_entry_point_plugins(
    install_distribution: Callable[..., Path], caplog: pytest.LogCaptureFixture
) -> None:
    registry = ORACLES.copy()  # created before the plugin is installed: lookups are lazy
    install_distribution(
        "fake-oracle-plugin",
        {str(ORACLES.group): ENTRY_POINTS},
        modules={"fake_oracle_plugin": PLUGIN},
    )
    with caplog.at_level(logging.WARNING, logger="anunnaki.oracles"):
        assert registry.names() == ["enlil", "ground_truth", "haze", "light", "renamed_haze"]
    haze = registry.create("haze", level=2)
    assert type(haze).__name__ == "Haze"
    result = haze.assess(np.zeros((2, 2, 3), np.uint8), seq=4, model_id="m")
    assert result is not None and result.category == 2 and result.assessor == "haze"
    log = caplog.text
    assert "'broken'" in log and "fake_no_such_oracle_module" in log
    assert "'answer'" in log and "is not a class" in log
    assert "'ground_truth'" in log and "already taken" in log
    assert "'other_name'" in log and "registers as 'renamed_haze'" in log
    assert isinstance(registry.create("ground_truth"), GroundTruthAssessor)  # no shadowing
    assert "haze" not in ORACLES.copy(entry_points=False).names()
