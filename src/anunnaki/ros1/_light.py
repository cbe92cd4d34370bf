"""The ``light`` oracle: the LEC's behaviour judged from how much light the camera gets.

A real robot has no ground truth, and a learned (Enlil) oracle needs training first; this
is the simplest honest oracle for a camera alone, the paper's own adverse context (dim
light, §4.1.4): the frame's mean luma (Rec. 601, 0–255) against two thresholds. Bright
enough is category 0; under ``dim`` category 1 (degraded); under ``dark`` category 2. The
context reports ``{"phenomenon": "low_light", "luma": …}`` (or ``clear``). It is a plugin
of the oracle slot (entry point ``anunnaki.oracles: light``), usable with any camera.
"""

from __future__ import annotations

from typing import Any

from anunnaki.messages import Assessment
from anunnaki.oracles import OracleError

__all__ = ["LightOracle"]


class LightOracle:
    """Category from the frame's mean luma.

    Args:
        dim: Mean luma (0–255) under which the LEC is taken as degraded (category 1).
        dark: Mean luma under which it is taken as compromised (category 2); < ``dim``.

    """

    name = "light"

    def __init__(self, *, dim: float = 90.0, dark: float = 40.0) -> None:
        if not 0 <= dark < dim <= 255:
            raise OracleError(f"light oracle: need 0 <= dark < dim <= 255, got {dark}, {dim}")
        self.dim = float(dim)
        self.dark = float(dark)

    def assess(self, frame: Any, *, seq: int, model_id: str) -> Assessment | None:
        """Assess one ``(H, W, 3)`` RGB frame."""
        if frame.size == 0:
            return None
        r, g, b = (frame[..., i].mean() for i in range(3))
        luma = float(0.299 * r + 0.587 * g + 0.114 * b)
        category = 2 if luma < self.dark else 1 if luma < self.dim else 0
        # confidence: how far the luma is from the nearest threshold, in [0.5, 1]
        edge = min(abs(luma - self.dim), abs(luma - self.dark))
        confidence = min(1.0, 0.5 + edge / 100.0)
        phenomenon = "clear" if category == 0 else "low_light"
        return Assessment(
            category=category,
            confidence=confidence,
            context={"phenomenon": phenomenon, "luma": round(luma, 1)},
            model_id=model_id,
            assessor=self.name,
            frame_seq=seq,
        )
