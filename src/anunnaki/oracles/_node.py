"""The oracle node: one behavior oracle on the bus, publishing assessments for Utu.

Paper §3.2 and §4.1.4: behavior oracles "run in parallel to the managed AI system and
subscribe to the same sensor data received by managed LECs"; each is a node of its own
(``/adv_detector`` in Fig. 13) that publishes behavior assessments — agent A4's
``/utu/oracle/output``. The node feeds an oracle what it asks for, by the hooks it has::

    /rover/camera/image ─Image─▶ decode ─▶ oracle.assess(frame, seq, model_id) ─▶ /utu/oracle/output
    /lec/detector/detections ──▶ oracle.observe_detections      (if defined)
    /sim/ground_truth ─────────▶ oracle.observe_ground_truth    (if defined)
    /sim/phenomena ────────────▶ oracle.observe_context         (if defined)
    /sim/camera/clean ─Image─▶ decode ─▶ oracle.observe_clean_frame   (if it asks: clean_frames)
    /lm_manager/active ────────▶ the model id handed to assess

It holds a liveliness token (``/oracle_<name>``), so a goal model can bind A4 to it with
``node: /oracle_ground_truth`` and Utu treats the oracle's values as unknown the moment the
node dies. Calls into the oracle are serialised (one lock), so an oracle need not be
thread-safe. A bad message or an oracle that raises is logged and counted; the node lives on.

An assessment is about a model: until the model manager has announced the LEC's model (or
its detections have named one), frames are withheld, not assessed for a model 'unknown'.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from anunnaki import topics
from anunnaki.bus import Bus, Node, Publisher, Sample
from anunnaki.errors import AnunnakiError
from anunnaki.lec import decode_image, detections_topic
from anunnaki.messages import Assessment, Detections, Image
from anunnaki.oracles._base import (
    ObservesCleanFrames,
    ObservesContext,
    ObservesDetections,
    ObservesGroundTruth,
    ObservesIgnoreBoxes,
    Oracle,
    context_from_phenomena,
)
from anunnaki.oracles._registry import ORACLES
from anunnaki.plugins import Registry

__all__ = [
    "OracleNode",
    "OracleNodeStats",
    "truth_from_message",
]

log = logging.getLogger("anunnaki.oracles")


@dataclass(frozen=True)
class OracleNodeStats:
    """Counters of a running :class:`OracleNode`.

    Attributes:
        frames: Frames received.
        assessments: Assessments published.
        withheld: Frames the oracle returned ``None`` for (not enough evidence yet).
        errors: Bad messages, undecodable frames and oracle exceptions (logged, skipped).

    """

    frames: int
    assessments: int
    withheld: int
    errors: int


def truth_from_message(
    body: dict[str, Any], classes: Sequence[str] | None = None
) -> tuple[int, np.ndarray, list[str] | None]:
    """Read a ground-truth message ``{seq, boxes, labels[, classes]}``.

    Labels may be class names, or indices into ``classes`` (the message's own list first,
    then the node's). Returns ``(seq, boxes [N, 4] float64, names or None)``: ``None`` when
    indices cannot be named (the assessor then matches class-agnostically).

    Raises:
        ValueError: A missing or malformed field.

    """
    seq = body.get("seq")
    if not isinstance(seq, int) or isinstance(seq, bool) or seq < 0:
        raise ValueError(f"ground truth needs 'seq', a frame number >= 0, got {seq!r}")
    boxes = np.asarray(body.get("boxes", []), dtype=np.float64)
    if boxes.size == 0:
        boxes = boxes.reshape(0, 4)
    if boxes.ndim != 2 or boxes.shape[1] != 4:
        raise ValueError(f"ground truth of frame {seq}: boxes must be [N, 4], got {boxes.shape}")
    labels = body.get("labels", [])
    if not isinstance(labels, list) or len(labels) != len(boxes):
        raise ValueError(f"ground truth of frame {seq}: give one label per box")
    if all(isinstance(x, str) for x in labels):
        return seq, boxes, [str(x) for x in labels]
    own = body.get("classes")
    names = own if isinstance(own, list) and all(isinstance(c, str) for c in own) else classes
    if all(isinstance(x, int) and not isinstance(x, bool) for x in labels):
        if names is not None and all(0 <= x < len(names) for x in labels):
            return seq, boxes, [str(names[x]) for x in labels]
        return seq, boxes, None
    raise ValueError(f"ground truth of frame {seq}: labels must be class names or indices")


def _ignore_boxes(body: dict[str, Any]) -> np.ndarray:
    """The ground-truth message's optional ``ignore`` boxes ``[K, 4]`` (seen, not labelled)."""
    raw = body.get("ignore") or []
    try:
        boxes = np.asarray(raw, dtype=np.float64)
    except (TypeError, ValueError):
        return np.zeros((0, 4))
    return boxes.reshape(-1, 4) if boxes.size and boxes.shape[-1] == 4 else np.zeros((0, 4))


class OracleNode(Node):
    """Runs one behavior oracle on the bus.

    A :class:`~anunnaki.bus.Node`: the kit owns its lifecycle (declare, liveliness token,
    spin, close); the work runs on the bus's delivery threads.

    Args:
        bus: The bus.
        oracle: An oracle instance, or a registered name (built with ``options``).
        camera: The camera topic (``Image``).
        lec: The assessed LEC's name (its detections and active-model announcements).
        detections: Its detections topic (default ``/lec/<lec>/detections``).
        ground_truth: The simulator's ground-truth topic.
        phenomena: The simulator's phenomena topic.
        clean: The simulator's clean frames (each frame before the phenomena), fed to an
            oracle that asks for them (:class:`~anunnaki.oracles.ObservesCleanFrames`).
        active: The model manager's announcements (``{lec, model, domain}``).
        output: Where assessments are published.
        node: The liveliness token (default ``/oracle_<name>``).
        classes: Class names for ground truth given as indices.
        every: Assess every n-th frame (guideline C5: a configurable rate).
        model: Assess this model id on every frame, whichever model the LEC runs (a
            *shadow* oracle: the default model's, telling whether the default would cope
            now); ``None`` (the default) assesses the active model.
        frame_queue: Frames that may wait; the oldest are dropped beyond it.
        registry: Where a name is looked up (default: :data:`~anunnaki.oracles.ORACLES`).
        **options: The oracle's options when it is given by name (e.g. ``window=30``).

    """

    def __init__(
        self,
        bus: Bus,
        oracle: str | Oracle,
        *,
        camera: str = "/rover/camera/image",
        lec: str = "detector",
        detections: str | None = None,
        ground_truth: str = topics.GROUND_TRUTH,
        phenomena: str = topics.PHENOMENA,
        clean: str = topics.CLEAN_FRAMES,
        active: str = topics.ACTIVE_MODEL,
        output: str = topics.ORACLE_OUTPUT,
        node: str | None = None,
        classes: Sequence[str] | None = None,
        every: int = 1,
        model: str | None = None,
        frame_queue: int = 16,
        registry: Registry[Oracle] | None = None,
        **options: Any,
    ) -> None:
        if not isinstance(every, int) or every < 1:
            raise ValueError(f"every must be a whole number >= 1, got {every!r}")
        if model is not None and (not isinstance(model, str) or not model):
            raise ValueError(f"model must be a model id, got {model!r}")
        self.oracle: Oracle = (registry or ORACLES).create(oracle, **options)
        self.bus = bus
        self.lec = lec
        self.every = every
        self.classes = tuple(classes) if classes is not None else None
        self.node = node or f"/oracle_{self.oracle.name}"
        self._oracle_lock = threading.Lock()
        self._lock = threading.Lock()
        self._fixed = model
        self._model_id: str | None = model
        self._frames = self._published = self._withheld = self._errors = 0
        self._agnostic_warned = False
        # The optional hooks, found by the Protocols they implement (never by signature).
        oracle = self.oracle
        self._on_dets = oracle if isinstance(oracle, ObservesDetections) else None
        self._on_gt = oracle if isinstance(oracle, ObservesGroundTruth) else None
        self._on_ctx = oracle if isinstance(oracle, ObservesContext) else None
        self._on_clean_frame = (
            oracle
            if isinstance(oracle, ObservesCleanFrames) and oracle.clean_frames is True
            else None
        )
        self._topics = {
            "camera": camera,
            "detections": detections or detections_topic(lec),
            "ground_truth": ground_truth,
            "phenomena": phenomena,
            "clean": clean,
            "active": active,
            "output": output,
        }
        self._frame_queue = frame_queue
        super().__init__(bus, token=self.node, ready=None)

    def declare(self) -> None:
        """The output publisher and the inputs the oracle's hooks ask for."""
        bus, topic = self.bus, self._topics
        self._output: Publisher = self.own(bus.publisher(topic["output"]))
        self.own(bus.subscribe(topic["active"], self._on_active, queue=16))
        self.own(
            bus.subscribe(topic["detections"], self._on_detections, queue=256, expect=Detections)
        )
        if self._on_gt is not None:
            self.own(bus.subscribe(topic["ground_truth"], self._on_truth, queue=256))
        if self._on_ctx is not None:
            self.own(bus.subscribe(topic["phenomena"], self._on_phenomena, queue=16))
        if self._on_clean_frame is not None:
            self.own(bus.subscribe(topic["clean"], self._on_clean, queue=256, expect=Image))
        self.own(
            bus.subscribe(topic["camera"], self._on_frame, queue=self._frame_queue, expect=Image)
        )

    def __repr__(self) -> str:
        return f"OracleNode({self.oracle.name!r}, node={self.node!r})"

    @property
    def wants_clean_frames(self) -> bool:
        """Whether the oracle takes the simulator's clean frames (a simulation publishes them)."""
        return self._on_clean_frame is not None

    @property
    def model_id(self) -> str | None:
        """The model the oracle assesses: the latest announced (or detected) one."""
        with self._lock:
            return self._model_id

    def stats(self) -> OracleNodeStats:
        """The node's counters."""
        with self._lock:
            return OracleNodeStats(self._frames, self._published, self._withheld, self._errors)

    def _error(self, fmt: str, *args: Any) -> None:
        with self._lock:
            self._errors += 1
        log.warning("oracle %s: " + fmt, self.oracle.name, *args)

    # -- inputs ------------------------------------------------------------------------------
    def _on_active(self, sample: Sample) -> None:
        if self._fixed is not None:
            return
        body = sample.message.to_body()
        if body.get("lec", self.lec) != self.lec:
            return
        model = body.get("model")
        if isinstance(model, str) and model:
            with self._lock:
                self._model_id = model

    def _on_detections(self, sample: Sample) -> None:
        dets = sample.message
        assert isinstance(dets, Detections)
        with self._lock:
            if self._model_id is None and self._fixed is None:
                self._model_id = dets.model_id
        if self._on_dets is not None:
            self._call(self._on_dets.observe_detections, dets)

    def _on_truth(self, sample: Sample) -> None:
        try:
            seq, boxes, names = truth_from_message(sample.message.to_body(), self.classes)
        except ValueError as exc:
            self._error("bad ground truth on %s: %s", sample.topic, exc)
            return
        if names is None and len(boxes) and not self._agnostic_warned:
            self._agnostic_warned = True
            log.warning(
                "oracle %s: ground-truth labels are class indices and no class names are "
                "known (give classes=… or a 'classes' list in the message); matching "
                "class-agnostically",
                self.oracle.name,
            )
        ignore = _ignore_boxes(sample.message.to_body())
        oracle = self.oracle
        if len(ignore) and isinstance(oracle, ObservesIgnoreBoxes) and oracle.ignore_boxes is True:
            self._call(oracle.observe_ground_truth, seq, boxes, names, ignore=ignore)
        elif self._on_gt is not None:
            self._call(self._on_gt.observe_ground_truth, seq, boxes, names)

    def _on_phenomena(self, sample: Sample) -> None:
        if self._on_ctx is not None:
            self._call(
                self._on_ctx.observe_context, context_from_phenomena(sample.message.to_body())
            )

    def _decoded(self, message: Image, what: str) -> np.ndarray | None:
        """The frame, read-only: an oracle must not modify what it is shown.

        ``None`` (logged and counted) when it cannot be decoded.
        """
        try:
            frame = decode_image(message)
        except (ValueError, AnunnakiError) as exc:
            self._error("%s %d: %s", what, message.seq, exc)
            return None
        frame.flags.writeable = False
        return frame

    def _on_clean(self, sample: Sample) -> None:
        message = sample.message
        assert isinstance(message, Image) and self._on_clean_frame is not None
        frame = self._decoded(message, "clean frame")
        if frame is not None:
            self._call(self._on_clean_frame.observe_clean_frame, message.seq, frame)

    def _call(self, hook: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        try:
            with self._oracle_lock:
                return hook(*args, **kwargs)
        except Exception as exc:  # an oracle's bug never kills the node
            self._error("%s raised %s: %s", hook.__name__, type(exc).__name__, exc)
            return None

    def _on_frame(self, sample: Sample) -> None:
        message = sample.message
        assert isinstance(message, Image)
        self._assess_frame(message)

    def _assess_frame(self, message: Image) -> None:
        with self._lock:
            self._frames += 1
            due = (self._frames - 1) % self.every == 0
            model_id = self._model_id
            if due and model_id is None:  # no model yet: nothing to assess it for
                self._withheld += 1
        if not due or model_id is None:
            return
        frame = self._decoded(message, "frame")
        if frame is None:
            return
        try:
            with self._oracle_lock:
                result = self.oracle.assess(frame, seq=message.seq, model_id=model_id)
        except Exception as exc:
            self._error("assess raised %s: %s", type(exc).__name__, exc)
            return
        if result is None:
            with self._lock:
                self._withheld += 1
            return
        if not isinstance(result, Assessment):
            self._error("assess returned %s, not an Assessment", type(result).__name__)
            return
        try:
            self._output.put(result)
        except AnunnakiError as exc:
            self._error("could not publish: %s", exc)
            return
        with self._lock:
            self._published += 1
