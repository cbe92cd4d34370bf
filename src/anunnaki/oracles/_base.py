"""The oracle contract: what a behavior assessor is, and the context it reports.

A behavior oracle (paper §3.2) runs beside the managed LEC on the same sensor data and
answers, frame by frame, *how is the LEC doing here?* — a behavior category (0: F1 drop under
5 %, 1: degraded, 2: compromised) and the perceived context (which phenomenon, how strong).
Enlil builds oracles that predict this from the raw frame alone; the ``ground_truth`` assessor
measures it against a simulator's ground truth. Both are plugins of one slot.

Why a ``Protocol``: an oracle is anything with a ``name`` and an ``assess`` method; a third
party implements it without inheriting from Anunnaki. Each optional hook is a typed
``Protocol`` of its own (:class:`ObservesGroundTruth`, :class:`ObservesIgnoreBoxes`,
:class:`ObservesDetections`, :class:`ObservesContext`, :class:`ObservesCleanFrames`),
checked with ``isinstance``: an oracle that needs no ground truth is never sent any.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt
from pydantic import JsonValue

from anunnaki.errors import AnunnakiError
from anunnaki.messages import Assessment

__all__ = [
    "CLEAR",
    "HOOKS",
    "Frame",
    "ObservesCleanFrames",
    "ObservesContext",
    "ObservesDetections",
    "ObservesGroundTruth",
    "ObservesIgnoreBoxes",
    "Oracle",
    "OracleError",
    "context_from_phenomena",
]

#: ``(H, W, 3)`` ``uint8`` RGB, as every LEC sees it.
Frame = npt.NDArray[np.uint8]

#: The perceived phenomenon when none is active.
CLEAR = "clear"


class OracleError(AnunnakiError, ValueError):
    """An oracle is unknown, malformed, or was given options it does not take."""


@runtime_checkable
class Oracle(Protocol):
    """A behavior assessor (plugin slot ``anunnaki.oracles``).

    Attributes:
        name: The oracle's registry name, an identifier such as ``ground_truth``; it is the
            ``assessor`` of every assessment it makes.

    Optional hooks, called by the oracle node (on its threads, never concurrently with
    ``assess`` or each other) when the oracle defines them:

    * ``observe_ground_truth(seq: int, boxes: ndarray, labels: list[str] | None) -> None`` —
      the simulator's objects in frame ``seq``: ``boxes`` ``[N, 4]`` float64 ``x1, y1, x2,
      y2`` pixels, ``labels`` class names (``None`` when the names are not known: match
      class-agnostically);
    * ``observe_detections(detections: Detections) -> None`` — what the LEC published for a
      frame (``frame_seq``, ``model_id``, boxes, label names, scores);
    * ``observe_context(context: dict) -> None`` — the simulator's phenomena ground truth,
      normalised by :func:`context_from_phenomena`.

    """

    name: str

    def assess(self, frame: Frame, *, seq: int, model_id: str) -> Assessment | None:
        """Assess the LEC on one camera frame.

        Called for every frame (or every n-th, as the node is configured), in order.

        Args:
            frame: ``(H, W, 3)`` ``uint8`` RGB; do not modify it.
            seq: The frame's sequence number (``Image.seq``); put it in ``frame_seq``.
            model_id: The LEC's active model; put it in ``model_id``.

        Returns:
            An :class:`~anunnaki.messages.Assessment` whose ``assessor`` is the oracle's name, or
            ``None`` when there is not enough evidence yet (nothing is published).

        """
        ...


@runtime_checkable
class ObservesGroundTruth(Protocol):
    """Optional hook: the simulator's objects in each frame (scoring against ground truth)."""

    def observe_ground_truth(
        self, seq: int, boxes: npt.ArrayLike, labels: Sequence[str] | None
    ) -> None:
        """Take frame ``seq``'s objects: ``[N, 4]`` float64 xyxy pixels and class names.

        ``labels`` is ``None`` when the names are not known: match class-agnostically.
        """
        ...


@runtime_checkable
class ObservesIgnoreBoxes(Protocol):
    """Optional: ``observe_ground_truth`` also takes ``ignore=`` (objects seen, not labelled).

    An oracle opts in by saying so (``ignore_boxes = True``); the node then passes each
    frame's ``[K, 4]`` ignore boxes, where a detection matching no object is no false
    positive.
    """

    ignore_boxes: bool

    def observe_ground_truth(
        self,
        seq: int,
        boxes: npt.ArrayLike,
        labels: Sequence[str] | None,
        ignore: npt.ArrayLike | None = None,
    ) -> None:
        """As :class:`ObservesGroundTruth`, with the frame's ignore boxes."""
        ...


@runtime_checkable
class ObservesDetections(Protocol):
    """Optional hook: what the LEC published for each frame."""

    def observe_detections(self, detections: Any) -> None:
        """``detections``: a :class:`~anunnaki.messages.Detections` (frame, model, boxes, names)."""
        ...


@runtime_checkable
class ObservesContext(Protocol):
    """Optional hook: the simulator's phenomena (normalised by :func:`context_from_phenomena`)."""

    def observe_context(self, context: dict[str, JsonValue]) -> None:
        """``{"phenomenon": NAME, "params": {...}}``."""
        ...


@runtime_checkable
class ObservesCleanFrames(Protocol):
    """Optional: each camera frame as a simulator rendered it, before the scenario's phenomena.

    An oracle opts in by saying so (``clean_frames = True``); the node then passes it every
    frame published on ``topics.CLEAN_FRAMES`` (``(H, W, 3)`` ``uint8`` RGB, decoded as the
    camera frame is, under the camera frame's ``seq``), and a simulated system that runs it
    publishes them. A real robot has no such frames.
    """

    clean_frames: bool

    def observe_clean_frame(self, seq: int, frame: Frame) -> None:
        """Take frame ``seq`` as rendered before any phenomenon; do not modify it."""
        ...


#: The optional hooks an oracle may implement, as the Protocols the oracle node checks with
#: ``isinstance``; it feeds an oracle only the hooks it has.
HOOKS: tuple[type, ...] = (
    ObservesGroundTruth,
    ObservesIgnoreBoxes,
    ObservesDetections,
    ObservesContext,
    ObservesCleanFrames,
)


def _params(value: Any) -> dict[str, JsonValue]:
    if not isinstance(value, Mapping):
        return {}
    out: dict[str, JsonValue] = {}
    for key, item in value.items():
        if isinstance(item, bool | int | float | str) or item is None:
            out[str(key)] = item
    return out


def _entry(item: Any) -> tuple[str, dict[str, JsonValue]] | None:
    if isinstance(item, str):
        return (item, {}) if item.strip() else None
    if isinstance(item, Mapping):
        name = item.get("name", item.get("phenomenon"))
        if isinstance(name, str) and name.strip():
            return name.strip(), _params(item.get("params"))
    return None


def context_from_phenomena(message: Mapping[str, Any]) -> dict[str, JsonValue]:
    """Normalise a simulator's phenomena message into an assessment context.

    Accepted forms (from ``/sim/phenomena``)::

        {"phenomenon": "fog", "params": {"density": 4}}       # one phenomenon
        {"name": "fog", "params": {...}}                       # the same
        {"phenomena": [{"name": "fog", "params": {...}}, "raindrop"]}   # several ("active"
                                                               # is accepted for the key)
        {"phenomenon": null} / {"phenomena": []} / {"phenomenon": "clear"}   # none

    Returns:
        ``{"phenomenon": NAME, "params": {...}}`` — ``NAME`` is ``clear`` when nothing is
        active, the phenomenon's name, or several joined with ``+`` (``fog+raindrop``, the
        name of their composition) with ``params`` keyed by name. A ``strength`` number in the
        message is kept.

    """
    entries: list[tuple[str, dict[str, JsonValue]]] = []
    many = message.get("phenomena", message.get("active"))
    if isinstance(many, Sequence) and not isinstance(many, str):
        entries = [e for e in (_entry(item) for item in many) if e is not None]
    else:
        single = _entry(message)
        if single is not None:
            entries = [(single[0], _params(message.get("params")))]
    entries = [(n, p) for n, p in entries if n.lower() not in (CLEAR, "none")]
    context: dict[str, JsonValue] = {}
    if not entries:
        context = {"phenomenon": CLEAR, "params": {}}
    elif len(entries) == 1:
        context = {"phenomenon": entries[0][0], "params": entries[0][1]}
    else:
        nested: dict[str, JsonValue] = {name: params for name, params in entries}
        context = {"phenomenon": "+".join(n for n, _ in entries), "params": nested}
    strength = message.get("strength")
    if isinstance(strength, int | float) and not isinstance(strength, bool):
        context["strength"] = float(strength)
    return context
