"""The phenomena slot, :data:`PHENOMENA`: built-ins, runtime registration, entry points.

Every plugin slot in Anunnaki takes a name or an object (``"fog"`` or ``Fog()``):
``PHENOMENA.create`` turns either into an instance. Third-party packages add phenomena
through the ``anunnaki.phenomena`` entry-point group; entry points are loaded lazily on the
first lookup, and one that fails to import or is not a :class:`Phenomenon` subclass is
logged and skipped, so a broken plugin never takes the others down. A plugin cannot shadow
a built-in or an explicitly registered phenomenon (it is skipped with a warning).

A name with ``+`` is a composition: ``PHENOMENA.create("fog+raindrop")`` is
``compose("fog", "raindrop")``. This module resolves the names and builds the
:class:`~anunnaki.phenomena.Composition` (which knows phenomena, not the slot).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TypeAlias, cast

from anunnaki.phenomena._base import ParamSpec, Phenomenon, PhenomenonError
from anunnaki.phenomena._color import HSL, Brightness
from anunnaki.phenomena._composition import Composition, Step
from anunnaki.phenomena._fog import Fog
from anunnaki.phenomena._raindrop import Raindrop
from anunnaki.phenomena._sensor import MotionBlur, Noise
from anunnaki.phenomena._weather import Rain, Snow
from anunnaki.plugins import Registry, check_name

__all__ = ["BUILTIN_PHENOMENA", "PHENOMENA", "StepLike", "compose"]

#: The phenomena that ship with Anunnaki.
BUILTIN_PHENOMENA: tuple[type[Phenomenon], ...] = (
    Brightness,
    Fog,
    HSL,
    MotionBlur,
    Noise,
    Rain,
    Raindrop,
    Snow,
)

#: What a step of :func:`compose` may be: a name, an instance, or either with pinned params.
StepLike: TypeAlias = "str | Phenomenon | tuple[str | Phenomenon, Mapping[str, float]]"


def _check_class(cls: object) -> type[Phenomenon]:
    """Return *cls* if it is a usable phenomenon class, else raise :class:`PhenomenonError`."""
    if not (isinstance(cls, type) and issubclass(cls, Phenomenon)):
        raise PhenomenonError(f"{cls!r} is not a subclass of anunnaki.phenomena.Phenomenon")
    name = check_name(getattr(cls, "name", None), what="phenomenon", error=PhenomenonError)
    params = getattr(cls, "params", None)
    if not isinstance(params, tuple) or not all(isinstance(p, ParamSpec) for p in params):
        raise PhenomenonError("params must be a tuple of ParamSpec", phenomenon=name)
    names = [p.name for p in params]
    if len(set(names)) != len(names):
        raise PhenomenonError(f"duplicate parameter names in {names}", phenomenon=name)
    unknown = set(cls.strength_target) - set(names)
    if unknown:
        raise PhenomenonError(
            f"strength_target names unknown parameters {sorted(unknown)}", phenomenon=name
        )
    return cls


def _step(step: StepLike) -> Step:
    """A step with its name (if any) resolved in :data:`PHENOMENA`."""
    if isinstance(step, str):
        return PHENOMENA.create(step)
    if isinstance(step, tuple) and len(step) == 2 and isinstance(step[0], str):
        return (PHENOMENA.create(step[0]), step[1])
    return cast(Step, step)  # an instance, or a malformed step the composition reports


def compose(*steps: StepLike) -> Composition:
    """Return a :class:`Composition` of *steps*, e.g. ``compose("fog", "raindrop")``.

    Each step is a name in :data:`PHENOMENA`, a :class:`Phenomenon`, or either with pinned
    parameters, ``("rain", {"slant": 20})``.

    Raises:
        PhenomenonError: No steps, an unknown name (listing the valid ones), or invalid
            pinned parameters.

    """
    return Composition(*(_step(step) for step in steps))


#: The phenomena: names -> classes (a :class:`~anunnaki.plugins.Registry`). ``create("fog")``
#: or ``create(Fog())`` gives an instance, ``create("fog+raindrop")`` a composition;
#: ``names()`` lists the valid names, ``register`` (a class decorator) adds one.
PHENOMENA: Registry[Phenomenon] = Registry(
    "phenomenon",
    group="anunnaki.phenomena",
    kind=Phenomenon,
    check=_check_class,
    error=PhenomenonError,
    hint="combine them with '+', e.g. 'fog+raindrop'",
    logger="anunnaki.phenomena",
    combine=lambda parts: Composition(*parts),
    separator="+",
)
for _cls in BUILTIN_PHENOMENA:
    PHENOMENA.register(_cls)
