"""The oracle node on the bus, with a real LEC node and a scripted simulator."""

from __future__ import annotations

import hashlib
import json
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from anunnaki import topics
from anunnaki.bus import Bus, Sample, open_bus
from anunnaki.lec import LecNode, ModelRegistry
from anunnaki.lec._detector import DetectionResult
from anunnaki.messages import Assessment, Detections, Image
from anunnaki.oracles import GroundTruthAssessor, OracleError, OracleNode

CAMERA = "/uav/camera/image"
BOX = [8.0, 8.0, 24.0, 24.0]


class SceneDetector:
    """A detector double: finds the car unless the frame is foggy (bright) and it is not
    the fog model."""

    classes = ("person", "car")

    def __init__(self, model_id: str, domain: str) -> None:
        self.model_id = model_id
        self.domain = domain

    def detect(self, images: Any) -> list[DetectionResult]:
        out = []
        for image in images:
            sees = self.domain == "fog" or float(image.mean()) < 200
            out.append(DetectionResult([BOX], [1], [0.9]) if sees else DetectionResult.empty())
        return out


def load(path: Path) -> SceneDetector:
    data = json.loads(path.read_text())
    return SceneDetector(data["id"], data["domain"])


@pytest.fixture
def registry(tmp_path: Path) -> ModelRegistry:
    entries = []
    for model_id, domain in (("det-default", "default"), ("det-fog", "fog")):
        path = tmp_path / f"{model_id}.model"
        path.write_text(json.dumps({"id": model_id, "domain": domain}))
        entries.append({"id": model_id, "domain": domain, "file": path, "metrics": {"f1": 1.0},
                        "sha256": hashlib.sha256(path.read_bytes()).hexdigest()})  # fmt: skip
    return ModelRegistry(entries, loader=load)


@pytest.fixture
def bus() -> Iterator[Bus]:
    with open_bus("inproc") as b:
        yield b


def png(grey: int) -> bytes:
    return bytes(cv2.imencode(".png", np.full((32, 32, 3), grey, np.uint8))[1].tobytes())


CLEAR_PNG, FOG_PNG = png(90), png(230)


class Spy(GroundTruthAssessor):
    """The ground-truth assessor, telling the test which frames it has matched."""

    def __init__(self, **options: Any) -> None:
        super().__init__(**options)
        self.cond = threading.Condition()
        self.truth: set[int] = set()
        self.dets: set[int] = set()

    def observe_ground_truth(self, seq: int, boxes: Any, labels: Any) -> None:
        super().observe_ground_truth(seq, boxes, labels)
        with self.cond:
            self.truth.add(seq)
            self.cond.notify_all()

    def observe_detections(self, detections: Detections) -> None:
        super().observe_detections(detections)
        with self.cond:
            self.dets.add(detections.frame_seq)
            self.cond.notify_all()

    def wait_matched(self, seq: int, timeout: float = 5.0) -> None:
        with self.cond:
            assert self.cond.wait_for(lambda: seq in self.truth and seq in self.dets, timeout), (
                f"frame {seq} not matched within {timeout} s"
            )


class Outputs:
    """Assessments on /utu/oracle/output; ``wait_for(seq)`` returns the one about a frame."""

    def __init__(self, bus: Bus, topic: str = "/utu/oracle/output") -> None:
        self.items: list[Assessment] = []
        self.cond = threading.Condition()
        bus.subscribe(topic, self._on, queue=1024)

    def _on(self, sample: Sample) -> None:
        assert isinstance(sample.message, Assessment)
        with self.cond:
            self.items.append(sample.message)
            self.cond.notify_all()

    def wait_for(self, seq: int, timeout: float = 5.0) -> Assessment:
        def find() -> Assessment | None:
            return next((a for a in self.items if a.frame_seq == seq), None)

        with self.cond:
            assert self.cond.wait_for(lambda: find() is not None, timeout), (
                f"no assessment of {seq}"
            )
            found = find()
        assert found is not None
        return found


def until(predicate: Callable[[], bool], timeout: float = 5.0) -> bool:
    """Wait (with a deadline) for a condition another thread brings about."""
    tick = threading.Event()
    for _ in range(int(timeout / 0.005)):
        if predicate():
            return True
        tick.wait(0.005)
    return predicate()


class Sim:
    """A scripted simulator: ground truth, phenomena, frames."""

    def __init__(self, bus: Bus) -> None:
        self.bus = bus
        self.seq = 0

    def fog(self, on: bool) -> None:
        self.bus.publish(
            "/sim/phenomena",
            {"phenomenon": "fog", "params": {"density": 4}} if on else {"phenomenon": None},
        )

    def frame(self, data: bytes) -> int:
        seq = self.seq
        self.seq += 1
        self.bus.publish("/sim/ground_truth", {"seq": seq, "boxes": [BOX], "labels": [1]})
        self.bus.publish(CAMERA, Image(encoding="png", width=32, height=32, data=data, seq=seq))
        return seq


def test_assessments_follow_fog_and_the_model_swap(bus: Bus, registry: ModelRegistry) -> None:
    outputs = Outputs(bus)
    spy = Spy(clean_f1=registry.clean_f1, window=10, min_frames=5)
    with (
        LecNode(bus, registry, camera=CAMERA, active_period=None) as lec,
        OracleNode(bus, spy, camera=CAMERA, classes=("person", "car")) as node,
    ):
        assert {"/lm_manager", "/oracle_ground_truth"} <= bus.alive_nodes()
        sim = Sim(bus)

        def phase(data: bytes, frames: int) -> Assessment:
            for _ in range(frames):
                spy.wait_matched(sim.frame(data))
            return outputs.wait_for(sim.frame(data))  # a probe: sees the whole phase

        sim.fog(False)
        clear = phase(CLEAR_PNG, 12)
        assert (clear.category, clear.model_id, clear.assessor) == (
            0,
            "det-default",
            "ground_truth",
        )
        assert clear.context == {"phenomenon": "clear", "params": {}} and clear.confidence == 1.0

        sim.fog(True)
        foggy = phase(FOG_PNG, 12)
        assert (foggy.category, foggy.model_id) == (2, "det-default")
        assert foggy.context == {"phenomenon": "fog", "params": {"density": 4}}

        assert lec.swap(domain="fog").ok
        assert until(lambda: node.model_id == "det-fog")
        robust = phase(FOG_PNG, 12)
        assert (robust.category, robust.model_id) == (0, "det-fog")
        assert robust.context["phenomenon"] == "fog"
        stats = node.stats()
    assert stats.frames == sim.seq and stats.errors == 0
    assert stats.assessments + stats.withheld == stats.frames
    assert all(a.assessor == "ground_truth" for a in outputs.items)
    assert "/oracle_ground_truth" not in bus.alive_nodes()


class PairedSpy(Spy):
    """The paired ground-truth assessor, telling the test which clean renders it has."""

    def __init__(self, **options: Any) -> None:
        super().__init__(**options)
        self.clean: set[int] = set()

    def observe_clean_frame(self, seq: int, frame: np.ndarray) -> None:
        super().observe_clean_frame(seq, frame)
        with self.cond:
            self.clean.add(seq)
            self.cond.notify_all()

    def wait_matched(self, seq: int, timeout: float = 5.0) -> None:
        super().wait_matched(seq, timeout)
        with self.cond:
            assert self.cond.wait_for(lambda: seq in self.clean, timeout), f"no clean {seq}"


def test_a_paired_scorer_is_fed_the_clean_frames(bus: Bus, registry: ModelRegistry) -> None:
    """A paired ground-truth scorer gets the simulator's clean renders and runs the active
    model on them. Every other frame is bright without any fog (its clean render is as
    bright) and det-default sees nothing there: the same F1 on the frames and on their clean
    renders, no drop; a plain scorer (clean F1 1.0) calls it compromised, and asks for no
    clean frames."""
    outputs = Outputs(bus)
    spy = PairedSpy(reference="paired", models=registry, window=10, min_frames=5)
    with (
        LecNode(bus, registry, camera=CAMERA, active_period=None),
        OracleNode(bus, spy, camera=CAMERA, classes=("person", "car")) as node,
        OracleNode(
            bus, "ground_truth", camera=CAMERA, classes=("person", "car"), clean_f1=1.0,
            window=10, min_frames=5, node="/plain", output="/plain/output",
        ) as plain,
    ):  # fmt: skip
        assert node.wants_clean_frames and not plain.wants_clean_frames
        plains: list[Assessment] = []
        bus.subscribe("/plain/output", lambda sample: plains.append(sample.message), queue=64)
        sim = Sim(bus)
        for k in range(11):
            data = FOG_PNG if k % 2 else CLEAR_PNG
            bus.publish(
                topics.CLEAN_FRAMES, Image(encoding="png", width=32, height=32, data=data, seq=k)
            )
            assert sim.frame(data) == k
            if k < 10:
                spy.wait_matched(k)
        probe = outputs.wait_for(10)  # the window of frames 0-9
        assert (probe.assessor, probe.model_id, probe.category) == (
            "ground_truth",
            "det-default",
            0,
        )
        window = spy.metrics()
        assert window is not None and window.f1 == window.clean_f1 == pytest.approx(2 / 3)
        assert until(lambda: any(a.frame_seq == 10 for a in plains))
        assert next(a for a in plains if a.frame_seq == 10).category == 2
        assert node.stats().errors == 0


class Flaky:
    """An oracle that raises on frames 2, 6, 10, … and needs no simulator."""

    name = "flaky"

    def assess(self, frame: np.ndarray, *, seq: int, model_id: str) -> Assessment | None:
        if seq % 4 == 2:
            raise RuntimeError("unlucky frame")
        return Assessment(category=0, confidence=1.0, model_id=model_id, assessor=self.name,
                          frame_seq=seq)  # fmt: skip


def test_every_nth_frame_and_failures_are_contained(bus: Bus) -> None:
    outputs = Outputs(bus)
    with OracleNode(bus, Flaky(), camera=CAMERA, every=2, node="/adv_detector") as node:
        assert "/adv_detector" in bus.alive_nodes()
        bus.publish("/lm_manager/active", {"lec": "tracker", "model": "x", "domain": "default"})
        bus.publish("/lm_manager/active", {"lec": "detector", "model": "m1", "domain": "default"})
        assert until(lambda: node.model_id == "m1")
        for seq in range(8):
            bus.publish(CAMERA, Image(encoding="png", width=32, height=32, data=CLEAR_PNG, seq=seq))
        bus.publish(
            CAMERA, Image(encoding="png", width=1, height=1, data=b"\x89PNG\r\n\x1a\n", seq=8)
        )
        assert outputs.wait_for(4).model_id == "m1"
        assert until(lambda: node.stats().frames == 9)
        # Every second frame is assessed: 0 and 4 are published, 2 and 6 raise, 8 is broken.
        assert until(lambda: node.stats().errors == 3)
        assert [a.frame_seq for a in outputs.items] == [0, 4]
        assert node.stats().assessments == 2


class Recorder:
    """An oracle that records which model each frame was assessed for."""

    name = "recorder"

    def __init__(self) -> None:
        self.models: list[str] = []

    def assess(self, frame: np.ndarray, *, seq: int, model_id: str) -> Assessment | None:
        self.models.append(model_id)
        return Assessment(category=0, confidence=1.0, model_id=model_id, assessor=self.name,
                          frame_seq=seq)  # fmt: skip


def test_no_frame_is_assessed_before_a_model_is_known(bus: Bus) -> None:
    """No model 'unknown' (the enlil oracle warned that no oracle covers it, issue 22)."""
    oracle = Recorder()
    outputs = Outputs(bus)
    with OracleNode(bus, oracle, camera=CAMERA) as node:
        for seq in range(3):
            bus.publish(CAMERA, Image(encoding="png", width=32, height=32, data=CLEAR_PNG, seq=seq))
        assert until(lambda: node.stats().withheld == 3)
        assert oracle.models == [] and node.stats().assessments == 0
        bus.publish("/lm_manager/active", {"lec": "detector", "model": "m1", "domain": "default"})
        assert until(lambda: node.model_id == "m1")
        bus.publish(CAMERA, Image(encoding="png", width=32, height=32, data=CLEAR_PNG, seq=3))
        assert outputs.wait_for(3).model_id == "m1"
        assert oracle.models == ["m1"]


def test_bad_ground_truth_is_counted(bus: Bus) -> None:
    with OracleNode(bus, "ground_truth", camera=CAMERA, clean_f1=1.0) as node:
        bus.publish("/sim/ground_truth", {"seq": -1, "boxes": [], "labels": []})
        bus.publish("/sim/ground_truth", {"seq": 1, "boxes": [BOX], "labels": [0]})  # no names
        assert until(lambda: node.stats().errors == 1)


def test_options_go_to_a_named_oracle_only(bus: Bus) -> None:
    with OracleNode(bus, "ground_truth", window=7) as node:
        assert isinstance(node.oracle, GroundTruthAssessor) and node.oracle.window == 7
    with pytest.raises(OracleError, match="built by name"):
        OracleNode(bus, Flaky(), window=7)
    with pytest.raises(ValueError, match="every must be"):
        OracleNode(bus, Flaky(), every=0)


def test_a_shadow_oracle_assesses_its_model_whichever_is_active(bus: Bus) -> None:
    """``model=``: the default model's oracle on every frame while another model runs."""
    oracle = Recorder()
    outputs = Outputs(bus, "/utu/oracle/shadow")
    with (
        OracleNode(
            bus, oracle, camera=CAMERA, model="m-default", output="/utu/oracle/shadow"
        ) as node,
        OracleNode(bus, Recorder(), camera=CAMERA, node="/plain") as plain,
    ):
        assert node.model_id == "m-default"  # known from the start: nothing withheld
        bus.publish("/lm_manager/active", {"lec": "detector", "model": "m-fog", "domain": "fog"})
        assert until(lambda: plain.model_id == "m-fog")  # the announcement is out
        bus.publish(CAMERA, Image(encoding="png", width=32, height=32, data=CLEAR_PNG, seq=0))
        assert outputs.wait_for(0).model_id == "m-default"
        assert oracle.models == ["m-default"] and node.model_id == "m-default"
    with pytest.raises(ValueError, match="model must be a model id"):
        OracleNode(bus, Recorder(), model="")
