"""The LEC node: detections per frame, hot swaps between frames, refusals, swap-back with Utu."""

from __future__ import annotations

import hashlib
import json
import re
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from lec_helpers import DEADLINE, Collector

from anunnaki.bus import Bus, ServiceError, open_bus
from anunnaki.goals import parse_binding, parse_goal_model
from anunnaki.lec import ModelRegistry, ModelRegistryError, parse_registry
from anunnaki.lec._detector import DetectionResult
from anunnaki.lec._node import LecNode, LecNodeStats, SwapResult, decode_image, detections_topic
from anunnaki.messages import Assessment, Detections, Generic, Image
from anunnaki.tactics import parse_tactics_yaml
from anunnaki.utu import AutonomicManager, Knowledge

ROOT = Path(__file__).parents[2]
DOC = (ROOT / "docs" / "model-manager.md").read_text(encoding="utf-8")
CAMERA = "/uav/camera/image"
DETS = detections_topic("detector")


# -- doubles ----------------------------------------------------------------------------------


class FakeDetector:
    """A detector double: one box per frame; ``gate`` (if set) holds ``detect`` of one frame."""

    def __init__(self, model_id: str, domain: str) -> None:
        self.model_id = model_id
        self.domain = domain
        self.classes = ("person", "car")
        self.gate: threading.Event | None = None
        self.entered = threading.Event()
        self.fail_next = 0
        self.frames = 0

    def detect(self, images: Any) -> list[DetectionResult]:
        if self.fail_next:
            self.fail_next -= 1
            raise RuntimeError("boom")
        if self.gate is not None:
            self.entered.set()
            self.gate.wait(DEADLINE)
            self.gate = None
        self.frames += len(images)
        return [DetectionResult([[1, 2, 11, 12]], [1], [0.9]) for _ in images]


class Loader:
    """Loads a model file (JSON) and records the calls; a model's load can be held.

    ``hold(model_id)`` makes that model's next load block until the test releases it: the
    deliberately slow-loading model of the swap test, slow for exactly as long as the test
    wants, without a sleep.
    """

    def __init__(self) -> None:
        self.calls: list[str] = []
        self.loaded: dict[str, FakeDetector] = {}
        self._held: dict[str, tuple[threading.Event, threading.Event]] = {}

    def hold(self, model_id: str) -> tuple[threading.Event, threading.Event]:
        """Hold MODEL_ID's next load: returns (set once the load started, set to release)."""
        entered, release = threading.Event(), threading.Event()
        self._held[model_id] = (entered, release)
        return entered, release

    def __call__(self, path: Path) -> FakeDetector:
        data = json.loads(path.read_text(encoding="utf-8"))  # a corrupt file raises here
        model_id = data["model_id"]
        self.calls.append(model_id)
        held = self._held.pop(model_id, None)
        if held is not None:
            entered, release = held
            entered.set()
            if not release.wait(DEADLINE):  # a guard against a hung test, not a timing
                raise RuntimeError(f"the test never released the load of {model_id}")
        det = FakeDetector(model_id, data["domain"])
        self.loaded[model_id] = det
        return det


def model_file(folder: Path, model_id: str, domain: str) -> dict[str, Any]:
    path = folder / f"{model_id}.model"
    path.write_text(json.dumps({"model_id": model_id, "domain": domain}))
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    return {"id": model_id, "domain": domain, "file": path, "sha256": digest}


@pytest.fixture
def loader() -> Loader:
    return Loader()


@pytest.fixture
def registry(tmp_path: Path, loader: Loader) -> ModelRegistry:
    return ModelRegistry(
        [
            model_file(tmp_path, "det-default", "default"),
            model_file(tmp_path, "det-fog", "fog"),
            model_file(tmp_path, "det-dark", "low_light"),
        ],
        loader=loader,
    )


@pytest.fixture
def bus() -> Iterator[Bus]:
    with open_bus("inproc") as b:
        yield b


_PNG = cv2.imencode(".png", np.full((24, 32, 3), 128, np.uint8))[1].tobytes()


def frame(seq: int) -> Image:
    return Image(encoding="png", width=32, height=24, data=_PNG, seq=seq)


# -- detections -------------------------------------------------------------------------------


def test_every_frame_gets_one_detection_message(bus: Bus, registry: ModelRegistry) -> None:
    active = Collector(bus, "/lm_manager/active")
    dets = Collector(bus, DETS)
    with LecNode(bus, registry, camera=CAMERA, active_period=None) as node:
        assert active.wait(1)[0] == Generic(
            data={"lec": "detector", "model": "det-default", "domain": "default"}
        )
        assert "/lm_manager" in bus.alive_nodes()
        for seq in range(5):
            bus.publish(CAMERA, frame(seq))
        got = dets.wait(5)
        assert [d.frame_seq for d in got] == [0, 1, 2, 3, 4]
        first = got[0]
        assert isinstance(first, Detections)
        assert (first.model_id, first.domain, first.width, first.height) == (
            "det-default", "default", 32, 24)  # fmt: skip
        assert first.boxes == [[1.0, 2.0, 11.0, 12.0]] and first.labels == ["car"]
        assert first.scores == [pytest.approx(0.9)] and first.latency_ms is not None
    assert "/lm_manager" not in bus.alive_nodes()
    assert node.stats().frames == 5 and node.stats().detections == 5  # after close: all in


def test_decode_image_gives_rgb() -> None:
    bgr = np.zeros((4, 6, 3), np.uint8)
    bgr[..., 2] = 255  # red in OpenCV's BGR
    msg = Image(encoding="png", width=6, height=4, data=cv2.imencode(".png", bgr)[1].tobytes())
    rgb = decode_image(msg)
    assert rgb.shape == (4, 6, 3) and rgb.dtype == np.uint8 and (rgb[..., 0] == 255).all()
    with pytest.raises(ValueError, match="do not decode"):
        decode_image(Image(encoding="png", width=1, height=1, data=b"\x89PNG\r\n\x1a\nbroken"))


def test_bad_frames_and_a_raising_model_are_counted_and_skipped(
    bus: Bus, registry: ModelRegistry, loader: Loader
) -> None:
    dets = Collector(bus, DETS)
    with LecNode(bus, registry, camera=CAMERA, active_period=None) as node:
        bus.publish(CAMERA, Image(encoding="png", width=1, height=1, data=b"\x89PNG\r\n\x1a\nx"))
        loader.loaded["det-default"].fail_next = 1
        bus.publish(CAMERA, frame(1))
        bus.publish(CAMERA, frame(2))
        assert [d.frame_seq for d in dets.wait(1)] == [2]
        assert node.stats().failed == 2 and node.stats().frames == 3


def test_the_active_model_is_announced_periodically(bus: Bus, registry: ModelRegistry) -> None:
    active = Collector(bus, "/lm_manager/active")
    with LecNode(bus, registry, camera=CAMERA, active_period=0.02):
        got = active.wait(4)
    assert all(m["model"] == "det-default" for m in got)


def test_a_bad_initial_model_fails_at_bring_up(
    bus: Bus, registry: ModelRegistry, tmp_path: Path
) -> None:
    with pytest.raises(ModelRegistryError, match="unknown model 'det-snow'"):
        LecNode(bus, registry, initial="det-snow")
    (tmp_path / "det-default.model").write_text("{}")
    with pytest.raises(ModelRegistryError, match="sha256 mismatch"):
        LecNode(bus, registry)
    assert "/lm_manager" not in bus.alive_nodes()
    assert LecNode(bus, registry, initial="det-dark", active_period=None).active.id == "det-dark"


# -- swapping -----------------------------------------------------------------------------------


def test_swap_during_30hz_frames_with_a_slow_load(
    bus: Bus, registry: ModelRegistry, loader: Loader
) -> None:
    """Frames at 30 Hz; the fog model's load is held by the test while frames keep coming.

    Everything is synchronised on counts: the camera runs until the test has seen what it
    needs, so a slow machine makes the test longer, never wrong.
    """
    entered, release = loader.hold("det-fog")
    dets = Collector(bus, DETS)
    replies: list[Any] = []
    sent: list[int] = []
    stop = threading.Event()

    def camera() -> None:
        pace = threading.Event()
        while not stop.is_set() and len(sent) < 3000:  # 3000: a bound, should all else fail
            bus.publish(CAMERA, frame(len(sent)))
            sent.append(len(sent))
            pace.wait(1 / 30)  # the camera's 30 Hz rate, not synchronisation

    def ask() -> None:
        payload = {"lec": "detector", "domain": "fog"}
        replies.append(bus.request("/lm_manager/swap", payload, DEADLINE))

    # A queue deep enough that a starved frame thread on a busy machine drops nothing.
    with LecNode(bus, registry, camera=CAMERA, active_period=None, frame_queue=1024) as node:
        cam = threading.Thread(target=camera)
        cam.start()
        try:
            dets.wait(10)  # the default model runs
            swapper = threading.Thread(target=ask)
            swapper.start()
            assert entered.wait(DEADLINE), "the fog model's load never started"
            at_hold = len(dets.items)
            # The load is held: frames keep flowing, on the old model, and no reply yet.
            dets.wait(at_hold + 15)
            assert replies == [] and swapper.is_alive() and node.active.id == "det-default"
            at_release = len(dets.items)
            release.set()
            swapper.join(DEADLINE)
            assert not swapper.is_alive() and len(replies) == 1
            # The new model serves the frames that follow.
            dets.wait_until(
                lambda items: sum(d.model_id == "det-fog" for d in items) >= 10,
                "10 detections of the fog model",
            )
        finally:
            release.set()  # (already set, unless an assertion above failed)
            stop.set()
            cam.join()
        n = len(sent)
        got = dets.wait(n)
    stats = node.stats()  # after close: the last frame's counters are in
    assert replies[0].ok is True
    reply = replies[0].body
    assert reply["model"] == "det-fog" and reply["domain"] == "fog"
    assert reply["previous"] == "det-default" and reply["changed"] is True
    # Every frame exactly once, in order, each tagged with the old or the new model ...
    assert len(got) == n and [d.frame_seq for d in got] == list(range(n))
    assert stats == LecNodeStats(frames=n, detections=n, failed=0, swaps=1, refused=0)
    models = [d.model_id for d in got]
    assert set(models) == {"det-default", "det-fog"}
    # ... and the switch is monotone: no old-model detection after the first new-model one.
    first_new = models.index("det-fog")
    assert models == ["det-default"] * first_new + ["det-fog"] * (n - first_new)
    assert all(d.domain == ("fog" if d.model_id == "det-fog" else "default") for d in got)
    # Frames kept flowing while the load was held, and the old model served all of them.
    assert at_release >= at_hold + 15 and first_new >= at_release
    # Each model ran exactly the frames tagged with it; each was loaded once.
    assert loader.loaded["det-default"].frames == first_new
    assert loader.loaded["det-fog"].frames == n - first_new
    assert loader.calls == ["det-default", "det-fog"]


def test_a_slow_frame_does_not_block_a_swap(
    bus: Bus, registry: ModelRegistry, loader: Loader
) -> None:
    dets = Collector(bus, DETS)
    with LecNode(bus, registry, camera=CAMERA, active_period=None) as node:
        old = loader.loaded["det-default"]
        old.gate = threading.Event()
        bus.publish(CAMERA, frame(0))
        assert old.entered.wait(5.0)  # frame 0 is stuck inside the old model
        result = node.swap("det-dark")  # returns although frame 0 is still running
        assert result.ok and result.model == "det-dark" and dets.items == []
        old.gate.set()
        bus.publish(CAMERA, frame(1))
        got = dets.wait(2)
    assert [(d.frame_seq, d.model_id) for d in got] == [(0, "det-default"), (1, "det-dark")]


def test_refused_swaps_keep_the_old_model_running(
    bus: Bus, registry: ModelRegistry, tmp_path: Path
) -> None:
    def ask(**payload: Any) -> str:
        with pytest.raises(ServiceError) as info:
            bus.request("/lm_manager/swap", payload, 5.0)
        return info.value.error

    dets = Collector(bus, DETS)
    with LecNode(bus, registry, camera=CAMERA, active_period=None) as node:
        error = ask(lec="detector", model="det-snow")
        assert "unknown model 'det-snow'" in error and "det-fog (fog)" in error
        assert "domains with a model: default, fog, low_light" in ask(lec="detector", domain="snow")
        assert "serves lec 'detector', not 'tracker'" in ask(lec="tracker", domain="fog")
        assert "say what to swap to" in ask(lec="detector")
        assert "'model' must be a string" in ask(lec="detector", model=3)
        assert "is for domain 'fog'" in ask(lec="detector", model="det-fog", domain="default")
        refused = node.swap("det-snow")
        assert not refused.ok and refused.reply().body == {
            "lec": "detector",
            "active": "det-default",
        }
        # A changed file (hash mismatch) and a corrupt one whose hash the registry states.
        (tmp_path / "det-fog.model").write_text("{}")
        assert "sha256 mismatch" in ask(lec="detector", domain="fog")
        corrupt = tmp_path / "det-corrupt.model"
        corrupt.write_bytes(b"\x00\x01 not a model")
        registry.add(id="det-corrupt", domain="rain", file=corrupt,
                     sha256=hashlib.sha256(corrupt.read_bytes()).hexdigest())  # fmt: skip
        assert "the loader refused" in ask(lec="detector", domain="rain")
        bus.publish(CAMERA, frame(7))
        assert dets.wait(1)[0].model_id == "det-default"
        assert node.active.id == "det-default" and node.stats().refused == 9
        assert node.stats().swaps == 0


def test_swap_to_the_active_model_and_back_from_cache(
    bus: Bus, registry: ModelRegistry, loader: Loader
) -> None:
    active = Collector(bus, "/lm_manager/active")
    dets = Collector(bus, DETS)
    with LecNode(bus, registry, camera=CAMERA, active_period=None) as node:
        same = node.swap(domain="default")
        assert same == SwapResult(True, "detector", "det-default", "default", "det-default")
        assert same.reply().body["changed"] is False
        assert node.swap("det-dark").changed
        bus.publish(CAMERA, frame(0))
        assert dets.wait(1)[0].model_id == "det-dark"
        back = node.swap(domain="default")
        assert back.ok and back.changed and back.previous == "det-dark"
        # Cached: the loader is not called again, the very same instance serves the frames.
        assert loader.calls == ["det-default", "det-dark"]
        bus.publish(CAMERA, frame(1))
        assert [(d.frame_seq, d.model_id) for d in dets.wait(2)] == [
            (0, "det-dark"), (1, "det-default")]  # fmt: skip
        assert loader.loaded["det-default"].frames == 1 and loader.loaded["det-dark"].frames == 1
        got = active.wait(3)
        assert [m["model"] for m in got] == ["det-default", "det-dark", "det-default"]
        assert node.stats().swaps == 2


def test_utu_counts_a_refused_swap_as_a_failed_action(bus: Bus, registry: ModelRegistry) -> None:
    from anunnaki.utu import BusActuator

    with LecNode(bus, registry, camera=CAMERA, active_period=None):
        act = BusActuator(bus)
        bad = act.request("/lm_manager/swap", {"lec": "detector", "domain": "snow"}, 5.0)
        assert not bad.ok and "no model for domain 'snow'" in bad.detail
        good = act.request("/lm_manager/swap", {"lec": "detector", "model": "det-dark"}, 5.0)
        assert good.ok and good.reply is not None and good.reply["model"] == "det-dark"


# -- the documentation ------------------------------------------------------------------------


def doc_block(tag: str) -> str:
    for lang, body in re.findall(r"^```(\w*)\n(.*?)^```", DOC, re.MULTILINE | re.DOTALL):
        if lang == "yaml" and body.startswith(f"anunnaki: {tag}\n"):
            return str(body)
    raise AssertionError(f"no {tag} block in docs/model-manager.md")


def test_the_documented_registry_parses(tmp_path: Path, loader: Loader) -> None:
    (tmp_path / "models").mkdir()
    for name in ("uav-default", "uav-fog"):
        (tmp_path / "models" / f"{name}.safetensors").write_text("{}")
    reg = parse_registry(doc_block("models/1"), source="doc", base=tmp_path, loader=loader)
    assert reg.ids() == ["uav-default", "uav-fog"] and reg.clean_f1("uav-fog") == 0.91


def test_the_documented_model_files_check_cleanly() -> None:
    from anunnaki.check import check_tactics

    binding = parse_binding(doc_block("binding/1"), source="binding.yaml")
    model = parse_goal_model(
        doc_block("goal-model/1"), source="goals.yaml", binding=binding, strict=False
    )
    assert [f.render() for f in model.findings] == []
    tactics = parse_tactics_yaml(doc_block("tactics/1"), source="tactics.yaml")
    assert [f.render() for f in check_tactics(model, tactics, "tactics.yaml")] == []


# -- swap-back, end to end with Utu ---------------------------------------------------------------


def oracle_says(t: float, domain: str) -> tuple[int, str]:
    """The scripted oracle: (category, context) at time t, given the active model's domain."""
    if 5.0 <= t < 15.0:  # fog: the default model is degraded, the fog model is fine
        category = 1 if domain != "fog" else 0
        if 10.0 <= t < 10.5:
            category = 1  # a flicker while the fog model runs: G9 holds, nothing happens
        return category, "fog"
    if 17.0 <= t < 17.5:
        return 1, "fog"  # a patch of fog: the hold restarts
    if 19.0 <= t < 19.5:
        return 1, "clear"  # a noisy assessment: the hold restarts again
    return 0, "clear"


def test_swap_back_end_to_end(tmp_path: Path, registry: ModelRegistry) -> None:
    binding = parse_binding(doc_block("binding/1"), source="binding.yaml")
    model = parse_goal_model(doc_block("goal-model/1"), source="goals.yaml", binding=binding)
    tactics = parse_tactics_yaml(doc_block("tactics/1"), source="tactics.yaml")
    with (
        open_bus("inproc") as bus,
        LecNode(bus, registry, camera=CAMERA, active_period=None) as node,
        AutonomicManager(
            model, tactics, bus=bus, knowledge=Knowledge(str(tmp_path / "k.db")), warmup=1.0
        ) as utu,
    ):
        domains: list[tuple[float, str]] = []
        for k in range(300):  # 30 s of simulated time in steps of 0.1 s
            t = round(k * 0.1, 1)
            bus.publish("/uav/camera/info", {"seq": k, "width": 320, "height": 240})
            if k % 5 == 0:  # the oracle at 2 Hz
                category, context = oracle_says(t, node.active.domain)
                bus.publish(
                    "/utu/oracle/output",
                    Assessment(category=category, confidence=1.0, model_id=node.active.id,
                               context={"phenomenon": context, "params": {}},
                               assessor="script"),
                )  # fmt: skip
            if k % 10 == 0:
                node.publish_active()  # the node's 1 Hz announcement, on simulated time
            utu.step(t)
            if not domains or domains[-1][1] != node.active.domain:
                domains.append((t, node.active.domain))
        started = [d for d in utu.knowledge.decisions(limit=10_000) if d.kind == "started"]
        failed = [
            d for d in utu.knowledge.decisions(limit=10_000) if d.kind == "postcondition_failed"
        ]
    assert [d.tactic for d in started] == ["swap-to-robust-model", "swap-back-to-default"]
    assert node.stats().swaps == 2 and failed == []
    assert [d for _, d in domains] == ["default", "fog", "default"]
    fog_at, back_at = domains[1][0], domains[2][0]
    assert 5.0 <= fog_at <= 5.2
    # Clear from 15 s, but flickers at 17 s and 19 s: back 5 s after the last one ended.
    assert 24.5 < back_at <= 24.7
