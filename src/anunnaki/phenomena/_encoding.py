"""What a camera's encoding on the bus does to a frame, after the phenomena.

A simulated or real camera sends its frames as JPEG (``camera: {encoding: jpeg, quality:
90}`` in a scenario); the detector and the oracle see the decoded frame. The phenomena act
on the scene before the camera encodes it, so a fogged frame is encoded as it is: JPEG's
quantisation removes the low-contrast detail the fog leaves, and a model loses more F1 in
fog through the camera than on the same frames unencoded (uav-fog under the UAV demo's fog:
a 3.1 % drop on 200 views of the demo's town as PNG, 9.3 % through JPEG at quality 90;
docs/uav.md, "The oracle against the ground truth"). An assessment or an oracle meant for
such a camera measures and learns from frames that went through the same encoding: the
phenomenon first, then :meth:`CameraEncoding.apply`, the clean frames through the encoding
too (the reference of the drop is the model on what the camera sends without the
phenomenon).

It is written ``jpeg:90`` (``jpeg`` alone: quality 90, the cameras' default); PNG is
lossless and changes nothing, so there is no ``png`` encoding to apply. The round trip is
:meth:`anunnaki.messages.Image.from_array` and ``to_array``: the camera's own codec.
"""

from __future__ import annotations

from dataclasses import dataclass

from anunnaki.phenomena._base import Image, PhenomenonError, check_image

__all__ = ["CameraEncoding"]

#: JPEG quality when ``jpeg`` is given without one (the scenarios' camera default).
DEFAULT_QUALITY = 90


@dataclass(frozen=True)
class CameraEncoding:
    """A camera's lossy encoding of its frames: JPEG at ``quality`` (10-100).

    ``str(encoding)`` is its spec, ``jpeg:90``, as :meth:`parse` reads it and as
    archives and oracle cards record it.
    """

    quality: int = DEFAULT_QUALITY

    def __post_init__(self) -> None:
        if isinstance(self.quality, bool) or not isinstance(self.quality, int):
            raise PhenomenonError(f"JPEG quality must be an integer, got {self.quality!r}")
        if not 10 <= self.quality <= 100:
            raise PhenomenonError(
                f"JPEG quality must be within 10-100 (a scenario camera's bounds), "
                f"got {self.quality}"
            )

    def apply(self, image: Image) -> Image:
        """The frame as the detector gets it: encoded as JPEG, then decoded (``(H, W, 3)``)."""
        from anunnaki.messages import Image as Frame

        rgb = check_image("camera encoding", image)
        sent: Image = Frame.from_array(rgb, encoding="jpeg", quality=self.quality).to_array()
        return sent

    def __str__(self) -> str:
        return f"jpeg:{self.quality}"

    @classmethod
    def parse(cls, spec: str | CameraEncoding | None) -> CameraEncoding | None:
        """Read an encoding spec: ``jpeg:Q`` or ``jpeg`` (quality 90).

        ``""``, ``none`` or ``None``: no encoding (the frames as rendered or stored).

        Raises:
            PhenomenonError: Anything else, naming the spec and what is accepted.

        """
        if spec is None or isinstance(spec, CameraEncoding):
            return spec
        text = spec.strip().lower()
        if text in ("", "none"):
            return None
        kind, _, quality = text.partition(":")
        if kind == "jpeg":
            if not quality:
                return cls()
            if quality.isdigit():
                return cls(int(quality))
        hint = " (PNG is lossless: give none)" if kind == "png" else ""
        raise PhenomenonError(
            f"unknown camera encoding {spec!r}; give jpeg:QUALITY (e.g. jpeg:90, as a "
            f"scenario's camera: {{encoding: jpeg, quality: 90}}) or none{hint}"
        )
