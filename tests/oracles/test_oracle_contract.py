"""The one contract suite every oracle passes: built-ins, installed plugins, the docs' example.

To run it against a new oracle, register it (or add a factory to ``CASES``).
"""

from __future__ import annotations

import json
import re
import threading
from collections import deque
from collections.abc import Callable, Sized
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from anunnaki.bus import Sample, open_bus
from anunnaki.messages import Assessment, Detections
from anunnaki.oracles import (
    HOOKS,
    ORACLES,
    ObservesContext,
    ObservesDetections,
    ObservesGroundTruth,
    Oracle,
    context_from_phenomena,
)
from anunnaki.phenomena import synthetic_scene

DOC = (Path(__file__).parents[2] / "docs" / "oracles.md").read_text(encoding="utf-8")
BUILTINS = {"ground_truth"}


def _docs_example() -> type[Any]:
    """Run the third-party example of docs/oracles.md; it registers in the slot, for a while."""
    (code,) = [
        body
        for lang, body in re.findall(r"^```(\w*)\n(.*?)^```", DOC, re.MULTILINE | re.DOTALL)
        if lang == "python" and "ORACLES.register" in body
    ]
    namespace: dict[str, Any] = {"__name__": "docs_oracles_example"}
    try:
        exec(compile(code, "docs/oracles.md", "exec"), namespace)
        assert isinstance(ORACLES.create("darkness"), namespace["DarknessOracle"])
    finally:
        ORACLES.unregister("darkness")  # the other tests see the slot as installed
    return namespace["DarknessOracle"]


DARKNESS = _docs_example()


def _untrained_enlil_oracle() -> Any:
    """An untrained (random-weight) oracle for model ``m-default``: the contract, not skill."""
    torch = pytest.importorskip("torch")
    from anunnaki.enlil import OracleCard, OracleModel
    from anunnaki.enlil._oracle_net import PhenomenonSpec, build_network

    card = OracleCard(
        model_id="m-default",
        phenomena=[PhenomenonSpec(name="fog", param_names=["density", "intensity"])],
        input_size=(32, 32),
    )
    torch.manual_seed(0)  # the same weights every time: the contract checks determinism
    return OracleModel(card, build_network(card))


#: Options the built-ins need to say anything at all.
OPTIONS: dict[str, Callable[[], dict[str, Any]]] = {
    "ground_truth": lambda: {"clean_f1": 0.9, "window": 8},
    "enlil": lambda: {"oracles": {"m-default": _untrained_enlil_oracle()}},
}

CASES: dict[str, Callable[[], Oracle]] = {
    name: (lambda name=name: ORACLES.create(name, **OPTIONS.get(name, dict)()))
    for name in ORACLES.names()
}
CASES["darkness (docs example)"] = DARKNESS
CASES["darkness, options"] = lambda: DARKNESS(dim=120.0, dark=40.0)


@pytest.fixture(params=sorted(CASES), ids=str)
def make(request: pytest.FixtureRequest) -> Callable[[], Oracle]:
    return CASES[request.param]


def test_all_builtins_are_in_the_suite() -> None:
    assert set(CASES) >= BUILTINS


# -- a scripted scenario fed to every oracle --------------------------------------------------

BOX = [8.0, 8.0, 40.0, 40.0]


def scenario() -> list[dict[str, Any]]:
    """40 frames: clear and well detected, then foggy and missed, some frames dark."""
    out = []
    for seq in range(40):
        foggy = seq >= 20
        image = synthetic_scene(64, 64, seed=seq % 3)
        if seq % 10 == 9:
            image = (image // 8).astype(np.uint8)  # a dark frame
        if foggy:
            image = (image // 2 + 120).astype(np.uint8)
        image.flags.writeable = False
        out.append(
            {
                "seq": seq,
                "image": image,
                "truth": (np.array([BOX]), ["car"]),
                "detections": Detections(
                    frame_seq=seq,
                    model_id="m-default",
                    width=64,
                    height=64,
                    boxes=[] if foggy else [BOX],
                    labels=[] if foggy else ["car"],
                    scores=[] if foggy else [0.9],
                ),
                "context": context_from_phenomena(
                    {"phenomenon": "fog", "params": {"density": 4}} if foggy else {}
                ),
            }
        )
    return out


SCENARIO = scenario()


def run(oracle: Oracle, frames: list[dict[str, Any]] = SCENARIO) -> list[Assessment | None]:
    results = []
    for f in frames:
        if isinstance(oracle, ObservesContext):
            oracle.observe_context(f["context"])
        if isinstance(oracle, ObservesGroundTruth):
            oracle.observe_ground_truth(f["seq"], *f["truth"])
        if isinstance(oracle, ObservesDetections):
            oracle.observe_detections(f["detections"])
        results.append(oracle.assess(f["image"], seq=f["seq"], model_id="m-default"))
    return results


# -- the contract ----------------------------------------------------------------------------


def test_is_an_oracle_with_a_valid_name(make: Callable[[], Oracle]) -> None:
    oracle = make()
    assert isinstance(oracle, Oracle)
    assert re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", oracle.name)
    assert ORACLES.create(oracle) is oracle  # a slot takes the object as it is
    # Every observe_* method it has is a hook of HOOKS (a misspelt one would never be fed).
    fed = {name for hook in HOOKS if isinstance(oracle, hook) for name in _methods(hook)}
    defined = {name for name in dir(oracle) if name.startswith("observe_")}
    assert defined <= fed, f"{sorted(defined - fed)} match no hook Protocol of {HOOKS}"


def _methods(protocol: type) -> set[str]:
    return {name for name in vars(protocol) if name.startswith("observe_")}


def test_assessments_are_well_formed(make: Callable[[], Oracle]) -> None:
    oracle = make()
    results = run(oracle)
    made = [r for r in results if r is not None]
    assert made, "an oracle must say something about 40 frames"
    for f, r in zip(SCENARIO, results, strict=True):
        if r is None:
            continue
        assert isinstance(r, Assessment)
        assert r.assessor == oracle.name
        assert r.frame_seq == f["seq"] and r.model_id == "m-default"
        assert r.category in (0, 1, 2) and 0.0 <= r.confidence <= 1.0
        json.dumps(r.context)  # plain JSON
        phenomenon = r.context.get("phenomenon")
        assert phenomenon is None or isinstance(phenomenon, str)


def test_assessments_survive_the_bus(make: Callable[[], Oracle]) -> None:
    made = [r for r in run(make()) if r is not None]
    got: list[Any] = []
    done = threading.Event()

    def on(sample: Sample) -> None:
        got.append(sample.message)
        if len(got) == len(made):
            done.set()

    with open_bus("inproc") as bus:
        bus.subscribe("/utu/oracle/output", on, queue=len(made) + 1)
        for r in made:
            bus.publish("/utu/oracle/output", r)
        assert done.wait(5.0)
    assert got == made


def test_deterministic(make: Callable[[], Oracle]) -> None:
    assert run(make()) == run(make())


def test_never_modifies_the_frame(make: Callable[[], Oracle]) -> None:
    oracle = make()
    image = synthetic_scene(48, 64, seed=5)
    before = image.copy()
    oracle.assess(image, seq=0, model_id="m")  # writable: a write would go unnoticed here
    np.testing.assert_array_equal(image, before)
    run(oracle)  # read-only frames: a write raises


@pytest.mark.parametrize("shape", [(1, 1, 3), (480, 640, 3), (37, 91, 3)])
def test_any_frame_size(make: Callable[[], Oracle], shape: tuple[int, int, int]) -> None:
    """Fed the scenario's hooks, an oracle assesses frames of any size, not only 64 x 64."""
    oracle = make()
    rng = np.random.default_rng(0)
    frames = [dict(f, image=rng.integers(0, 256, shape, dtype=np.uint8)) for f in SCENARIO[:12]]
    results = run(oracle, frames)
    # 12 frames warm up every oracle of the suite (the ground truth's window of 8 needs 2):
    # the last frame is assessed, whatever its size.
    assert results[-1] is not None, f"no assessment of a {shape} frame after 12 frames"
    for f, r in zip(frames, results, strict=True):
        if r is not None:
            assert r.frame_seq == f["seq"] and r.assessor == oracle.name
            assert r.model_id == "m-default" and r.category in (0, 1, 2)


#: The cases whose oracle takes ground truth (the optional ``observe_ground_truth`` hook).
TRUTH_CASES = sorted(
    name for name, make in CASES.items() if hasattr(make(), "observe_ground_truth")
)


def test_the_ground_truth_hook_is_covered() -> None:
    assert "ground_truth" in TRUTH_CASES and not any("darkness" in n for n in TRUTH_CASES)


def container_sizes(oracle: Any) -> dict[str, int]:
    """The length of every container the oracle holds: dicts, lists, sets, deques, ..."""
    return {
        name: len(value)
        for name, value in vars(oracle).items()
        if isinstance(value, Sized) and not isinstance(value, str | bytes | np.ndarray)
    }


@pytest.mark.parametrize("name", TRUTH_CASES)
def test_unmatched_hook_input_is_bounded(name: str) -> None:
    oracle: Any = CASES[name]()
    detected = getattr(oracle, "observe_detections", lambda _: None)

    def detections(seq: int) -> Detections:
        return SCENARIO[0]["detections"].model_copy(update={"frame_seq": seq})

    for seq in range(5000):  # truth for frames the LEC never reports
        oracle.observe_ground_truth(seq, np.array([BOX]), ["car"])
    for seq in range(5000, 10_000):  # detections for frames the simulator never reports
        detected(detections(seq))
    unassessed = 0
    for seq in range(10_000, 12_000):  # matched frames, assessed: the sliding window
        oracle.observe_ground_truth(seq, np.array([BOX]), ["car"])
        detected(detections(seq))
        unassessed += oracle.assess(SCENARIO[0]["image"], seq=seq, model_id="m-default") is None
    assert unassessed < 100, "the window never filled: the bound below would say little"
    sizes = container_sizes(oracle)
    assert sizes, "no container found to measure"
    assert max(sizes.values()) < 1000, sizes
    if name == "ground_truth":  # the waiting frames reach their bound (4 x window; the last
        # matched frame left it), the window its own
        bound = 4 * OPTIONS[name]()["window"]
        assert bound - 1 <= max(sizes.values()) <= bound
        assert [len(v) for v in vars(oracle).values() if isinstance(v, deque)] == [8]


def test_the_documented_assessment_is_an_assessment() -> None:
    blocks = re.findall(r"^```json\n(.*?)^```", DOC, re.MULTILINE | re.DOTALL)
    assert blocks
    for body in blocks:
        message = Assessment.model_validate(json.loads(body))
        assert message.context["phenomenon"] == "fog"
