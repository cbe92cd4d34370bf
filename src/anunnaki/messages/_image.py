"""One compressed camera frame, and its conversion from and to pixel arrays.

OpenCV and NumPy are imported inside :meth:`Image.from_array` and :meth:`Image.to_array`,
never at import time: the vocabulary and the bus need neither.
"""

from __future__ import annotations

from typing import Any, ClassVar, Literal, Self

from pydantic import Field, model_validator

from anunnaki.messages._base import MESSAGES, Message

__all__ = ["Image"]

_MAGIC: dict[str, tuple[bytes, ...]] = {
    "jpeg": (b"\xff\xd8\xff",),
    "png": (b"\x89PNG\r\n\x1a\n",),
}


@MESSAGES.register
class Image(Message):
    """One compressed camera frame.

    Frames travel as raw bytes after the JSON header (no base64) and are never persisted by
    the framework (guideline P1: media is compressed and not stored); only what is derived
    from them (assessments, detections) is kept.

    Attributes:
        encoding: ``"jpeg"`` or ``"png"``; ``data`` must start with that format's signature.
        width: Width in pixels (> 0).
        height: Height in pixels (> 0).
        channels: 1 (grey), 3 (RGB) or 4 (RGBA).
        data: The encoded image file's bytes.
        frame_id: The camera's frame (ROS ``header.frame_id``).
        seq: The camera's frame counter.

    """

    BINARY_FIELD: ClassVar[str | None] = "data"

    encoding: Literal["jpeg", "png"]
    width: int = Field(gt=0)
    height: int = Field(gt=0)
    channels: Literal[1, 3, 4] = 3
    data: bytes = Field(min_length=1)
    frame_id: str = ""
    seq: int = Field(default=0, ge=0)

    @model_validator(mode="after")
    def _signature(self) -> Self:
        if not self.data.startswith(_MAGIC[self.encoding]):
            raise ValueError(f"data does not start with the {self.encoding} signature")
        return self

    @classmethod
    def from_array(
        cls,
        rgb: Any,
        *,
        encoding: Literal["jpeg", "png"] = "jpeg",
        quality: int = 90,
        frame_id: str = "",
        seq: int = 0,
    ) -> Image:
        """Encode an ``(H, W, 3)`` RGB ``uint8`` array (or ``(H, W)`` grey) as a frame.

        ``quality`` is the JPEG quality (1–100); PNG uses fast compression (level 1).

        Raises:
            ValueError: The array is not an ``(H, W)``/``(H, W, 3)`` ``uint8`` image.
            MissingExtraError: OpenCV is not installed (``anunnaki[phenomena]``).

        """
        cv2, np = _cv2()
        arr = np.asarray(rgb)
        if arr.dtype != np.uint8 or arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] != 3):
            raise ValueError(
                f"an image must be (H, W) or (H, W, 3) uint8, got {arr.shape} {arr.dtype}"
            )
        pixels = arr if arr.ndim == 2 else np.ascontiguousarray(arr[:, :, ::-1])
        if encoding == "jpeg":
            ok, buf = cv2.imencode(".jpg", pixels, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
        else:
            ok, buf = cv2.imencode(".png", pixels, [cv2.IMWRITE_PNG_COMPRESSION, 1])
        if not ok:  # pragma: no cover - OpenCV encodes any uint8 image
            raise ValueError("image encoding failed")
        return cls(
            encoding=encoding,
            width=int(arr.shape[1]),
            height=int(arr.shape[0]),
            channels=1 if arr.ndim == 2 else 3,
            data=bytes(buf.tobytes()),
            frame_id=frame_id,
            seq=seq,
        )

    def to_array(self) -> Any:
        """Decode the frame into an ``(H, W, 3)`` RGB ``uint8`` array (grey/RGBA become RGB).

        Raises:
            ValueError: The bytes do not decode.
            MissingExtraError: OpenCV is not installed (``anunnaki[phenomena]``).

        """
        cv2, np = _cv2()
        bgr = cv2.imdecode(np.frombuffer(self.data, dtype=np.uint8), cv2.IMREAD_COLOR)
        if bgr is None:
            raise ValueError(f"frame {self.seq}: the {self.encoding} bytes do not decode")
        return np.ascontiguousarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8)


def _cv2() -> tuple[Any, Any]:
    """OpenCV and NumPy, imported on first use (the messages themselves need neither)."""
    try:
        import cv2
        import numpy
    except ImportError as exc:  # pragma: no cover - part of the phenomena/vision extras
        from anunnaki.errors import MissingExtraError

        raise MissingExtraError("opencv-python-headless", "phenomena") from exc
    return cv2, numpy
