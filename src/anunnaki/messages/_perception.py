"""What the perception chain says: the LEC's detections and the oracles' assessments.

A camera frame (:class:`~anunnaki.messages.Image`) goes to the LEC, whose
:class:`Detections` go to a behaviour oracle, whose :class:`Assessment` goes to Utu
(agent A4 of a goal model, on ``anunnaki.topics.ORACLE_OUTPUT``).
"""

from __future__ import annotations

from typing import Self

from pydantic import Field, JsonValue, model_validator

from anunnaki.messages._base import MESSAGES, Message

__all__ = ["Assessment", "Detections"]


@MESSAGES.register
class Assessment(Message):
    """A behavior assessment of an LEC (agent A4 on ``/utu/oracle/output``, paper §3.2).

    Attributes:
        category: Behavior category: 0 = F1 drop under 5 %, 1 = degraded (over 5 %),
            2 = compromised (over 10 %), relative to the model's F1 on clean data.
        confidence: The assessor's confidence in the category, in [0, 1].
        context: The perceived context, e.g. ``{"phenomenon": "fog", "density": 4}``.
        model_id: The id of the model whose behaviour is assessed.
        assessor: The assessor's name (an oracle, or ``ground_truth``).
        frame_seq: The camera frame the assessment is about, when there is one.
        drop: The predicted relative F1 drop of the model, when the assessor predicts
            one (an oracle with a drop head); ``None`` in older messages and files.

    """

    category: int = Field(ge=0, le=2)
    confidence: float = Field(ge=0.0, le=1.0)
    context: dict[str, JsonValue] = Field(default_factory=dict)
    model_id: str
    assessor: str
    frame_seq: int | None = None
    drop: float | None = None


@MESSAGES.register
class Detections(Message):
    """What an LEC detected in one camera frame.

    Attributes:
        frame_seq: The frame's sequence number (every frame gets exactly one).
        model_id: The model that produced the detections.
        domain: That model's domain (``default``, ``fog``, ``low_light`` …).
        width: Frame width in pixels.
        height: Frame height in pixels.
        boxes: ``[x1, y1, x2, y2]`` per detection, in pixels.
        labels: Class name per detection.
        scores: Confidence per detection, in [0, 1].
        latency_ms: Inference time, when measured.

    """

    frame_seq: int = Field(ge=0)
    model_id: str
    domain: str = "default"
    width: int = Field(gt=0)
    height: int = Field(gt=0)
    boxes: list[list[float]] = Field(default_factory=list)
    labels: list[str] = Field(default_factory=list)
    scores: list[float] = Field(default_factory=list)
    latency_ms: float | None = None

    @model_validator(mode="after")
    def _parallel(self) -> Self:
        if not (len(self.boxes) == len(self.labels) == len(self.scores)):
            raise ValueError("boxes, labels and scores must have the same length")
        if any(len(b) != 4 for b in self.boxes):
            raise ValueError("each box is [x1, y1, x2, y2]")
        return self
