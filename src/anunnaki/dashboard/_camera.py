"""The camera pane's store: the latest frames, their detections, the active model, the rate.

Frames are kept encoded (never decoded) and only a few of them; detections are kept per
frame sequence number; the frame rate is measured on the frames' own stamps. Apart from
:class:`~anunnaki.dashboard.DashboardState` because the camera is a stream of its own (the
page fetches pixels by sequence number); the store calls it with its lock held.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any

__all__ = ["CameraPane", "Frame"]

#: Detections kept, by frame sequence number (the newest ones).
_DETECTIONS_KEPT = 32


@dataclass(frozen=True)
class Frame:
    """One camera frame as the dashboard keeps it (the encoded bytes, never decoded).

    Attributes:
        topic: The camera topic.
        seq: The camera's frame counter.
        encoding: ``"jpeg"`` or ``"png"``.
        width: Width in pixels.
        height: Height in pixels.
        data: The encoded image file.
        t: Its stamp on the dashboard's clock (seconds): the sender's publication time on
            the wall clock, its simulated instant on ``clock: sim``. The frame rate is
            measured on these stamps, never on arrivals (which come in bursts).

    """

    topic: str
    seq: int
    encoding: str
    width: int
    height: int
    data: bytes
    t: float

    @property
    def media_type(self) -> str:
        """The HTTP content type of :attr:`data`."""
        return "image/png" if self.encoding == "png" else "image/jpeg"


class CameraPane:
    """Frames, detections and the active model, as the camera pane shows them (not locked)."""

    def __init__(self) -> None:
        self.frames: deque[Frame] = deque(maxlen=8)
        self.detections: dict[int, dict[str, Any]] = {}
        self.active_model: dict[str, Any] | None = None
        self.count = 0
        self._stamps: deque[float] = deque(maxlen=64)

    def add_frame(self, frame: Frame) -> None:
        """Keep a frame and its stamp."""
        if self._stamps and frame.t < self._stamps[-1]:
            self._stamps.clear()  # the clock went back (a new run): start over
        self._stamps.append(frame.t)
        self.frames.append(frame)
        self.count += 1

    def add_detections(self, row: dict[str, Any]) -> None:
        """Keep a checked detections row; it names the active model unless the manager did."""
        self.detections[row["frame_seq"]] = row
        while len(self.detections) > _DETECTIONS_KEPT:
            del self.detections[min(self.detections)]
        if self.active_model is None or self.active_model.get("source") == "detections":
            self.active_model = {
                "model": row["model_id"],
                "domain": row["domain"],
                "source": "detections",
            }

    def latest(self) -> Frame | None:
        """The latest frame, ``None`` before any."""
        return self.frames[-1] if self.frames else None

    def frame(self, seq: int | None = None) -> Frame | None:
        """The latest frame, or the one with sequence number ``seq`` if still kept."""
        if not self.frames:
            return None
        if seq is None:
            return self.frames[-1]
        return next((f for f in reversed(self.frames) if f.seq == seq), None)

    def frame_rate(self, window: float = 2.0) -> float | None:
        """Frames a second on the frames' stamps over the last ``window`` seconds of them."""
        stamps = self._stamps
        if len(stamps) < 2:
            return None
        last = stamps[-1]
        inside = [t for t in stamps if t >= last - window]
        span = last - inside[0]
        if len(inside) < 2 or span <= 0:
            return None
        return (len(inside) - 1) / span

    def view(self, frame: Frame | None) -> dict[str, Any]:
        """The pane's section of a snapshot or delta, showing ``frame``."""
        out: dict[str, Any] = {
            "active": self.active_model,
            "frames": self.count,
            "fps": self.frame_rate(),
        }
        if frame is not None:
            out["frame"] = {
                "topic": frame.topic,
                "seq": frame.seq,
                "width": frame.width,
                "height": frame.height,
                "t": frame.t,
            }
            out["detections"] = self.detections.get(frame.seq) or (
                self.detections[max(self.detections)] if self.detections else None
            )
        elif self.detections:
            out["detections"] = self.detections[max(self.detections)]
        return out
