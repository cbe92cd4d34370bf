"""The phenomenon contract: parameter specs, validation, the vector view and ``apply``.

Why the base class does so much: Enlil and Enki search over phenomenon parameters with
pyribs, scenario files ramp them with a scalar strength, and third parties add phenomena as
plugins. All of them must see the same rules (bounds, units, integer rounding, identity,
determinism), so the rules live here once and a subclass only writes :meth:`Phenomenon.perturb`.
"""

from __future__ import annotations

import math
import numbers
import os
import re
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import KW_ONLY, dataclass, replace
from types import MappingProxyType, ModuleType
from typing import Any, ClassVar, TypeAlias

from anunnaki.errors import AnunnakiError, MissingExtraError

try:
    import numpy as np
    import numpy.typing as npt
except ImportError as _exc:  # pragma: no cover - only without the vision extra
    raise MissingExtraError("numpy", "phenomena") from _exc

__all__ = [
    "HIDDEN",
    "Image",
    "Mask",
    "ParamSpec",
    "Phenomenon",
    "PhenomenonError",
    "check_image",
    "require_albumentations_functional",
    "require_cv2",
    "to_uint8",
]

#: An image: ``(height, width, 3)`` ``uint8`` RGB array.
Image: TypeAlias = npt.NDArray[np.uint8]

#: An occlusion mask: ``(height, width)`` ``float32`` in ``[0, 1]``, the share of each pixel
#: that a phenomenon replaced (1: the scene behind it is gone, 0: untouched).
Mask: TypeAlias = npt.NDArray[np.float32]

#: A labelled box is *hidden* when the mean of the occlusion mask over it is at least this:
#: at least half of it is gone, so neither a detector nor a person can be asked to find it
#: (docs/phenomena.md, "Occlusion masks"). Training and evaluation make it an ignore box.
HIDDEN = 0.5

_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")


class PhenomenonError(AnunnakiError, ValueError):
    """A phenomenon, its parameters, its image or its seed are invalid.

    The message names the phenomenon and, for a parameter problem, the parameter, the value
    given, the bounds and the unit, e.g. ``fog: parameter 'density' = 12 is out of bounds;
    expected density in [1, 10] layers``.

    Args:
        message: What is wrong, in one sentence (without the phenomenon prefix).
        phenomenon: Name of the phenomenon at fault, when there is one.
        parameter: Name of the parameter at fault, when there is one.
        value: The offending value, as given.
        bounds: ``(low, high)`` of the parameter, when it has bounds.
        unit: Unit of the parameter.
        hint: What to do about it.

    """

    def __init__(
        self,
        message: str,
        *,
        phenomenon: str | None = None,
        parameter: str | None = None,
        value: object = None,
        bounds: tuple[float, float] | None = None,
        unit: str | None = None,
        hint: str | None = None,
    ) -> None:
        self.message = message
        self.phenomenon = phenomenon
        self.parameter = parameter
        self.value = value
        self.bounds = bounds
        self.unit = unit
        self.hint = hint
        text = f"{phenomenon}: {message}" if phenomenon else message
        if hint:
            text += f" (hint: {hint})"
        super().__init__(text)


def _fmt(value: float) -> str:
    return f"{value:g}"


@dataclass(frozen=True)
class ParamSpec:
    """One axis of a phenomenon's parameter space.

    Args:
        name: Parameter name (an identifier; compositions prefix it: ``fog.density``).
        low: Smallest allowed value (inclusive).
        high: Largest allowed value (inclusive).
        unit: Unit written after the bounds in docs and errors (``"degrees"``, ``"px"``).
        description: One sentence on what the parameter does.
        default_identity: The value at zero strength; all parameters at their
            ``default_identity`` leave the image unchanged.
        default: Value used when the parameter is omitted. ``None`` (the default) makes the
            parameter required: leaving it out is an error.
        integer: The parameter counts something; values are rounded to the nearest integer
            (halves up) after the bounds check. Searchers may pass any float in bounds.

    """

    name: str
    low: float
    high: float
    unit: str
    description: str
    default_identity: float
    _: KW_ONLY
    default: float | None = None
    integer: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME_RE.match(self.name):
            raise PhenomenonError(
                f"invalid parameter name {self.name!r}; use an identifier such as 'radius'"
            )
        numbers_ = {"low": self.low, "high": self.high, "default_identity": self.default_identity}
        if self.default is not None:
            numbers_["default"] = self.default
        for field_name, number in numbers_.items():
            if not _is_real(number) or not math.isfinite(float(number)):
                raise PhenomenonError(
                    f"{field_name} = {number!r} is not a finite number", parameter=self.name
                )
        if not self.low < self.high:
            raise PhenomenonError(
                f"bounds [{_fmt(self.low)}, {_fmt(self.high)}] are empty; need low < high",
                parameter=self.name,
            )
        for field_name in ("default_identity", "default"):
            number = getattr(self, field_name)
            if number is not None and not self.low <= number <= self.high:
                raise PhenomenonError(
                    f"{field_name} = {_fmt(number)} is outside {self.describe_bounds()}",
                    parameter=self.name,
                )
        if self.integer and not (float(self.low).is_integer() and float(self.high).is_integer()):
            raise PhenomenonError("an integer parameter needs integer bounds", parameter=self.name)

    @property
    def required(self) -> bool:
        """Whether leaving the parameter out is an error (it has no ``default``)."""
        return self.default is None

    def describe_bounds(self) -> str:
        """Return ``[low, high] unit``, as used in docs and error messages."""
        text = f"[{_fmt(self.low)}, {_fmt(self.high)}]"
        return f"{text} {self.unit}" if self.unit else text

    def prefixed(self, prefix: str) -> ParamSpec:
        """Return a copy named ``prefix.name`` (used by compositions)."""
        return replace(self, name=f"{prefix}.{self.name}")


def _is_real(value: object) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def check_image(phenomenon: str, image: object) -> Image:
    """Return *image* as a C-contiguous ``(H, W, 3)`` ``uint8`` array or raise.

    Raises:
        PhenomenonError: *image* is not a non-empty ``(H, W, 3)`` ``uint8`` numpy array; the
            message says what was given and how to convert it.

    """
    if not isinstance(image, np.ndarray):
        raise PhenomenonError(
            f"image must be a numpy array of shape (H, W, 3) and dtype uint8, "
            f"got {type(image).__name__}",
            phenomenon=phenomenon,
        )
    shape_ok = image.ndim == 3 and image.shape[2] == 3 and image.shape[0] > 0 and image.shape[1] > 0
    if image.dtype == np.uint8 and shape_ok:
        return np.ascontiguousarray(image)
    hint = None
    if image.dtype != np.uint8 and np.issubdtype(image.dtype, np.floating):
        hint = "convert float images in [0, 1] with (image * 255).round().astype(np.uint8)"
    elif image.ndim == 2:
        hint = "stack a grey image to RGB with np.repeat(image[..., None], 3, axis=2)"
    elif image.ndim == 3 and image.shape[2] == 4:
        hint = "drop the alpha channel with image[..., :3]"
    raise PhenomenonError(
        f"image must be an RGB array of shape (H, W, 3) and dtype uint8, "
        f"got shape {image.shape} and dtype {image.dtype}",
        phenomenon=phenomenon,
        hint=hint,
    )


def to_uint8(values: npt.ArrayLike) -> Image:
    """Round to the nearest integer and saturate to ``[0, 255]`` as ``uint8``."""
    return np.clip(np.rint(values), 0, 255).astype(np.uint8)


def require_cv2() -> ModuleType:
    """Import OpenCV, or raise :class:`~anunnaki.errors.MissingExtraError` naming the extra."""
    try:
        import cv2
    except ImportError as exc:
        raise MissingExtraError("opencv-python-headless", "phenomena") from exc
    return cv2


def require_albumentations_functional() -> ModuleType:
    """Import ``albumentations.augmentations.pixel.functional`` (2.0.x) without its update check.

    Raises:
        MissingExtraError: albumentations (or OpenCV, which it needs) is not installed.

    """
    require_cv2()
    os.environ.setdefault("NO_ALBUMENTATIONS_UPDATE", "1")
    try:
        from albumentations.augmentations.pixel import functional
    except ImportError as exc:
        raise MissingExtraError("albumentations", "phenomena") from exc
    module: ModuleType = functional
    return module


class Phenomenon(ABC):
    """A parameterised, deterministic image perturbation (fog, raindrops, lighting, ...).

    A subclass sets three class attributes and writes one hook:

    * ``name`` — the registry name (an identifier, e.g. ``"fog"``);
    * ``params`` — a tuple of :class:`ParamSpec`, the parameter space in a fixed order
      (the order of :meth:`bounds`, :meth:`to_vector` and :meth:`from_vector`);
    * ``strength_target`` — parameter values at full strength (``strength_params(1.0)``);
      parameters it leaves out stay at their identity value;
    * :meth:`perturb` — the effect itself.

    Set ``stochastic = False`` when the output does not depend on the seed. Subclasses must
    be constructible without arguments to be looked up by name. A phenomenon that replaces
    pixels (a drop on the lens) also writes :meth:`occlusion_mask`, so that a box it hides
    is not counted against the detector (:meth:`occlusion`); the others need not.

    Images are ``(height, width, 3)`` ``uint8`` RGB arrays. :meth:`apply` is deterministic:
    the same image, parameters and seed give the same bytes, on any machine with the same
    library versions. All randomness comes from ``numpy.random.default_rng(seed)`` (or
    ``SeedSequence(seed)``); nothing reads global random state or the clock.
    """

    name: str
    params: tuple[ParamSpec, ...]
    stochastic: bool = True
    strength_target: ClassVar[Mapping[str, float]] = MappingProxyType({})

    # -- the parameter space -------------------------------------------------------------

    @property
    def param_names(self) -> tuple[str, ...]:
        """Parameter names, in vector order."""
        return tuple(spec.name for spec in self.params)

    def spec(self, name: str) -> ParamSpec:
        """Return the :class:`ParamSpec` called *name*.

        Raises:
            PhenomenonError: No such parameter; the message lists the valid ones.

        """
        for spec in self.params:
            if spec.name == name:
                return spec
        raise self._unknown_parameter(name)

    def bounds(self) -> list[tuple[float, float]]:
        """Return ``[(low, high), ...]`` in vector order, as pyribs emitters expect."""
        return [(float(spec.low), float(spec.high)) for spec in self.params]

    def identity_params(self) -> dict[str, float]:
        """Return the parameters at zero strength: applying them leaves the image unchanged."""
        return {spec.name: float(spec.default_identity) for spec in self.params}

    def validate(self, params: Mapping[str, Any]) -> dict[str, float]:
        """Check *params* and return the complete, canonical parameter dict.

        Omitted optional parameters get their ``default``; integer parameters are rounded
        (halves up); every value becomes a ``float``. The result is in vector order.

        Raises:
            PhenomenonError: *params* has an unknown name, lacks a required one, or has a
                value that is not a finite number within the bounds. The message names the
                phenomenon, the parameter, the value, the bounds and the unit.

        """
        if not isinstance(params, Mapping):
            raise PhenomenonError(
                f"parameters must be a mapping of name to number, got {type(params).__name__}",
                phenomenon=self.name,
            )
        known = set(self.param_names)
        for key in params:
            if key not in known:
                raise self._unknown_parameter(key)
        result: dict[str, float] = {}
        for spec in self.params:
            if spec.name in params:
                result[spec.name] = self._check_value(spec, params[spec.name])
            elif spec.default is not None:
                result[spec.name] = float(spec.default)
            else:
                raise PhenomenonError(
                    f"missing parameter {spec.name!r}; expected {spec.name} in "
                    f"{spec.describe_bounds()} ({spec.description})",
                    phenomenon=self.name,
                    parameter=spec.name,
                    bounds=(spec.low, spec.high),
                    unit=spec.unit,
                )
        return result

    def to_vector(self, params: Mapping[str, Any]) -> npt.NDArray[np.float64]:
        """Validate *params* and return them as a float64 vector in :attr:`params` order."""
        valid = self.validate(params)
        return np.array([valid[name] for name in self.param_names], dtype=np.float64)

    def from_vector(
        self, vector: Sequence[float] | npt.NDArray[np.floating[Any]]
    ) -> dict[str, float]:
        """Turn a vector (e.g. a pyribs solution) into a validated parameter dict.

        Raises:
            PhenomenonError: The vector has the wrong length, or a value is out of bounds.

        """
        array = np.asarray(vector, dtype=np.float64)
        if array.ndim != 1 or array.shape[0] != len(self.params):
            raise PhenomenonError(
                f"vector must have shape ({len(self.params)},) for parameters "
                f"{list(self.param_names)}, got shape {array.shape}",
                phenomenon=self.name,
            )
        return self.validate(dict(zip(self.param_names, array.tolist(), strict=True)))

    def strength_params(self, strength: float) -> dict[str, float]:
        """Map a scalar strength in ``[0, 1]`` to parameters (0 is the identity).

        The default interpolates linearly from :meth:`identity_params` to
        ``strength_target`` (integer parameters are rounded). Scenario files use this to
        ramp a phenomenon ("fog thickens from t = 40 s").

        Raises:
            PhenomenonError: *strength* is not a finite number in ``[0, 1]``.

        """
        s = self._check_strength(strength)
        identity = self.identity_params()
        target = {**identity, **self.strength_target}
        return self.validate(
            {name: (1.0 - s) * identity[name] + s * target[name] for name in identity}
        )

    # -- applying ------------------------------------------------------------------------

    def apply(self, image: Image, params: Mapping[str, Any], seed: int) -> Image:
        """Return a perturbed copy of *image*; *image* itself is never modified.

        Args:
            image: ``(H, W, 3)`` ``uint8`` RGB array.
            params: Parameter values by name (see :attr:`params`); optional ones may be omitted.
            seed: Non-negative integer; the only source of randomness.

        Returns:
            A new ``(H, W, 3)`` ``uint8`` array. Identical inputs give identical bytes.

        Raises:
            PhenomenonError: Bad image, parameters or seed, or :meth:`perturb` returned
                something that is not an image of the input's shape.

        """
        checked = check_image(self.name, image)
        valid = self.validate(params)
        self._check_seed(seed)
        frozen = checked.view()
        frozen.flags.writeable = False
        out = self.perturb(frozen, valid, int(seed))
        if not isinstance(out, np.ndarray) or out.dtype != np.uint8 or out.shape != checked.shape:
            got = f"{out.dtype} {out.shape}" if isinstance(out, np.ndarray) else type(out).__name__
            raise PhenomenonError(
                f"perturb() must return a uint8 array of shape {checked.shape}, got {got}",
                phenomenon=self.name,
            )
        if np.shares_memory(out, image) or not out.flags.writeable:
            out = out.copy()
        return out

    def occlusion(self, shape: Sequence[int], params: Mapping[str, Any], seed: int) -> Mask | None:
        """How much of each pixel :meth:`apply` replaces, or ``None`` when it hides nothing.

        A phenomenon that lays something opaque over the scene (a raindrop on the lens, a
        smudge) hides what is behind it; training and evaluation turn a box mostly hidden
        (mean mask over the box at least :data:`HIDDEN`) into an ignore box. The mask belongs
        to the same draw as :meth:`apply` with the same parameters and seed (same drops).

        Args:
            shape: The image's ``(height, width)`` (or its full ``shape``).
            params: Parameter values by name, as for :meth:`apply`.
            seed: The seed :meth:`apply` is given.

        Returns:
            A ``(height, width)`` ``float32`` map in ``[0, 1]`` (:data:`Mask`), or ``None``
            when the phenomenon reports no mask (the default: it only changes how the scene
            looks, e.g. fog or lighting; third-party phenomena need do nothing).

        Raises:
            PhenomenonError: Bad shape, parameters or seed, or :meth:`occlusion_mask`
                returned something that is not such a map.

        """
        dims = tuple(shape)[:2]
        if len(dims) != 2 or not all(
            isinstance(n, numbers.Integral) and not isinstance(n, bool) and n > 0 for n in dims
        ):
            raise PhenomenonError(
                f"shape must start with a positive (height, width), got {tuple(shape)!r}",
                phenomenon=self.name,
            )
        valid = self.validate(params)
        self._check_seed(seed)
        height, width = int(dims[0]), int(dims[1])
        mask = self.occlusion_mask(height, width, valid, int(seed))
        if mask is None:
            return None
        if (
            not isinstance(mask, np.ndarray)
            or mask.shape != (height, width)
            or not np.issubdtype(mask.dtype, np.floating)
        ):
            got = (
                f"{mask.dtype} {mask.shape}"
                if isinstance(mask, np.ndarray)
                else type(mask).__name__
            )
            raise PhenomenonError(
                f"occlusion_mask() must return None or a float array of shape "
                f"{(height, width)}, got {got}",
                phenomenon=self.name,
            )
        return np.clip(mask, 0.0, 1.0).astype(np.float32)

    def occlusion_mask(
        self, height: int, width: int, params: dict[str, float], seed: int
    ) -> Mask | None:
        """The hook behind :meth:`occlusion`; called only by it. Default: no mask (``None``).

        Override it in a phenomenon that replaces pixels. Compute the mask from the same
        geometry and random draws as :meth:`perturb` (share the code), so that the mask says
        exactly what the image shows: 1 where the pixel is wholly the phenomenon's, a blend
        weight on soft edges, 0 where the scene is untouched.

        Args:
            height: Image height in pixels.
            width: Image width in pixels.
            params: The output of :meth:`validate`.
            seed: Non-negative integer, as :meth:`perturb` gets it.

        """
        del height, width, params, seed
        return None

    @abstractmethod
    def perturb(self, image: Image, params: dict[str, float], seed: int) -> Image:
        """Compute the effect; called only by :meth:`apply`.

        Args:
            image: A read-only, C-contiguous ``(H, W, 3)`` ``uint8`` RGB array.
            params: The output of :meth:`validate`: every parameter present, in bounds,
                integers rounded, all ``float``.
            seed: Non-negative integer. Draw randomness only from
                ``np.random.default_rng(seed)`` (or ``np.random.SeedSequence(seed)``).

        Returns:
            A new ``uint8`` array with *image*'s shape. Return ``image.copy()`` for a no-op.

        """

    # -- helpers -------------------------------------------------------------------------

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"

    def _check_value(self, spec: ParamSpec, raw: object) -> float:
        where = f"expected {spec.name} in {spec.describe_bounds()}"
        context: dict[str, Any] = {
            "phenomenon": self.name,
            "parameter": spec.name,
            "value": raw,
            "bounds": (spec.low, spec.high),
            "unit": spec.unit,
        }
        if not _is_real(raw):
            raise PhenomenonError(
                f"parameter {spec.name!r} = {raw!r} is not a number; {where}", **context
            )
        value = float(raw)  # type: ignore[arg-type]  # numbers.Real is float-convertible
        if not math.isfinite(value):
            raise PhenomenonError(
                f"parameter {spec.name!r} = {value} is not a finite number; {where}", **context
            )
        if not spec.low <= value <= spec.high:
            raise PhenomenonError(
                f"parameter {spec.name!r} = {_fmt(value)} is out of bounds; {where}", **context
            )
        if spec.integer:
            value = float(math.floor(value + 0.5))
        return value

    def _check_seed(self, seed: object) -> None:
        if not isinstance(seed, numbers.Integral) or isinstance(seed, bool) or seed < 0:
            raise PhenomenonError(
                f"seed must be a non-negative integer, got {seed!r}", phenomenon=self.name
            )

    def _check_strength(self, strength: object) -> float:
        if not _is_real(strength) or not 0.0 <= float(strength) <= 1.0:  # type: ignore[arg-type]
            raise PhenomenonError(
                f"strength = {strength!r} must be a finite number in [0, 1] "
                "(0 = identity, 1 = full strength)",
                phenomenon=self.name,
                parameter="strength",
                value=strength,
                bounds=(0.0, 1.0),
            )
        return float(strength)  # type: ignore[arg-type]

    def _unknown_parameter(self, key: object) -> PhenomenonError:
        valid = ", ".join(f"{spec.name} in {spec.describe_bounds()}" for spec in self.params)
        return PhenomenonError(
            f"unknown parameter {key!r}; valid parameters: {valid}",
            phenomenon=self.name,
            parameter=str(key),
            value=key,
        )
