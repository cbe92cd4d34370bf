"""The camera chain: one wiring of LEC node, oracle node and scorer for every kind.

An oracle that takes options from the detector's model registry says so with the
``TakesModels`` hook (a class method), never by its name; the file's own options win.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any, ClassVar

import pytest

from anunnaki import topics
from anunnaki.bus import open_bus
from anunnaki.errors import ModelFileError
from anunnaki.managed import CameraChain, TakesModels, check_camera_chain
from anunnaki.oracles import ORACLES, GroundTruthAssessor

ROOT = Path(__file__).parents[2]
MODELS = ROOT / "examples" / "models" / "rover.yaml"


class _Plain:
    """An oracle that asks nothing of the registry."""

    name: ClassVar[str] = "chain_plain"

    def __init__(self, **options: Any) -> None:
        self.options = options

    def assess(self, frame: Any, *, seq: int, model_id: str) -> None:
        return None


class _Taker(_Plain):
    """An oracle that takes the registry's model ids (the hook)."""

    name: ClassVar[str] = "chain_taker"

    @classmethod
    def options_from_models(cls, models: Any) -> dict[str, Any]:
        return {"ids": [spec.id for spec in models], "window": 99}


@pytest.fixture
def oracles() -> Iterator[None]:
    registry = ORACLES
    registry.register(_Plain)
    registry.register(_Taker)
    try:
        yield
    finally:
        registry.unregister("chain_plain")
        registry.unregister("chain_taker")


def test_the_hook_is_a_protocol_not_a_name(oracles: None) -> None:
    assert isinstance(_Taker, TakesModels) and not isinstance(_Plain, TakesModels)
    assert isinstance(GroundTruthAssessor, TakesModels)


def test_an_oracle_takes_from_the_registry_by_its_hook_and_the_file_wins(oracles: None) -> None:
    with open_bus("inproc") as bus:
        chain = CameraChain(
            bus,
            camera="/toy/camera/image",
            models=MODELS,
            oracle={"name": "chain_taker", "window": 3},
            scorer={"name": "chain_plain"},
        )
        with chain:
            taker, plain = chain.oracle.oracle, chain.scorer.oracle
            assert taker.options["ids"] == [spec.id for spec in chain.registry]
            assert taker.options["window"] == 3  # the launch file's own option wins
            assert plain.options == {}  # no hook: nothing from the registry
            assert chain.scorer.node == "/scorer_chain_plain"
            assert chain.lec is not None and chain.detections_topic == chain.lec.detections_topic
            assert "on /toy/camera/image" in chain.describe()
            assert "scored live by chain_plain" in chain.describe()
        assert topics.SCORER == "/sim/oracle/scorer"


def test_the_ground_truth_oracle_gets_the_clean_f1_without_a_branch_on_its_name() -> None:
    with (
        open_bus("inproc") as bus,
        CameraChain(
            bus, camera="/rover/camera/image", models=MODELS, oracle={"name": "ground_truth"}
        ) as chain,
    ):
        assert chain.oracle.oracle._clean == chain.registry.clean_f1


def test_no_models_no_detector_and_no_hook_call(oracles: None) -> None:
    with (
        open_bus("inproc") as bus,
        CameraChain(bus, camera="/c", oracle={"name": "chain_taker"}) as chain,
    ):
        assert chain.lec is None and chain.registry is None
        assert chain.oracle.oracle.options == {}
        assert chain.describe() == "no detector; oracle chain_taker"


def test_bring_up_checks_name_the_element() -> None:
    check_camera_chain(models=str(MODELS), oracle={"name": "ground_truth"})
    with pytest.raises(ModelFileError, match="unknown oracle 'crystal_ball'") as err:
        check_camera_chain(models=None, oracle=None, scorer={"name": "crystal_ball"})
    assert err.value.element == "managed.scorer.name"
    with pytest.raises(ModelFileError, match="the oracle has no name") as err2:
        check_camera_chain(models=None, oracle={"window": 3}, where="managed.x")
    assert err2.value.element == "managed.x.oracle.name"
    check_camera_chain(models=None, oracle={"window": 3}, default_oracle="ground_truth")


def test_a_shadow_oracle_assesses_the_default_model_on_its_own_topic(oracles: None) -> None:
    with (
        open_bus("inproc") as bus,
        CameraChain(
            bus,
            camera="/rover/camera/image",
            models=MODELS,
            oracle={"name": "chain_plain"},
            shadow={"name": "chain_plain", "domain": "default"},
        ) as chain,
    ):
        default = chain.registry.default.id
        assert chain.shadow.model_id == default
        assert chain.shadow.node == "/shadow_chain_plain"
        assert chain.shadow._topics["output"] == topics.SHADOW_ORACLE == "/utu/oracle/shadow"
        assert f"shadowed by chain_plain for {default}" in chain.describe()
        assert "domain" not in chain.shadow.oracle.options  # the chain's, not the oracle's


def test_a_shadow_names_one_known_model() -> None:
    check_camera_chain(
        models=str(MODELS), oracle=None, shadow={"name": "ground_truth", "domain": "default"}
    )
    with pytest.raises(ModelFileError, match="say which model") as err:
        check_camera_chain(models=str(MODELS), oracle=None, shadow={"name": "ground_truth"})
    assert err.value.element == "managed.shadow"
    with pytest.raises(ModelFileError, match="smog") as err2:
        check_camera_chain(
            models=str(MODELS), oracle=None, shadow={"name": "ground_truth", "domain": "smog"}
        )
    assert err2.value.element == "managed.shadow.domain"
    with pytest.raises(ModelFileError, match="needs the detector's models"):
        check_camera_chain(models=None, oracle=None, shadow={"domain": "default"})
