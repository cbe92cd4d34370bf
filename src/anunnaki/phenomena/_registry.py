"""The phenomenon registry: built-ins, runtime registration and entry-point plugins.

Every plugin slot in Anunnaki takes a name or an object (``"fog"`` or ``Fog()``); this module
turns either into an instance. Third-party packages add phenomena through the
``anunnaki.phenomena`` entry-point group; entry points are loaded lazily on the first lookup,
and one that fails to import or is not a :class:`Phenomenon` subclass is logged and skipped,
so a broken plugin never takes the others down. A plugin cannot shadow a built-in or an
explicitly registered phenomenon (it is skipped with a warning).

A name with ``+`` is a composition: ``get_phenomenon("fog+raindrop")`` is
``compose("fog", "raindrop")``.
"""

from __future__ import annotations

import inspect
import logging
import re
from typing import TypeVar

from anunnaki.phenomena._base import ParamSpec, Phenomenon, PhenomenonError
from anunnaki.phenomena._color import HSL, Brightness
from anunnaki.phenomena._composition import Composition
from anunnaki.phenomena._fog import Fog
from anunnaki.phenomena._raindrop import Raindrop
from anunnaki.phenomena._sensor import MotionBlur, Noise
from anunnaki.phenomena._weather import Rain, Snow
from anunnaki.plugins import Registry

__all__ = [
    "BUILTIN_PHENOMENA",
    "ENTRY_POINT_GROUP",
    "PhenomenonRegistry",
    "available_phenomena",
    "default_registry",
    "get_phenomenon",
    "register_phenomenon",
]

logger = logging.getLogger("anunnaki.phenomena")

#: The entry-point group third-party phenomena register under.
ENTRY_POINT_GROUP = "anunnaki.phenomena"

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

_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

P = TypeVar("P", bound=type[Phenomenon])


def _check_class(cls: object) -> type[Phenomenon]:
    """Return *cls* if it is a usable phenomenon class, else raise :class:`PhenomenonError`."""
    if not (isinstance(cls, type) and issubclass(cls, Phenomenon)):
        raise PhenomenonError(f"{cls!r} is not a subclass of anunnaki.phenomena.Phenomenon")
    if inspect.isabstract(cls):
        missing = ", ".join(sorted(getattr(cls, "__abstractmethods__", ())))
        raise PhenomenonError(f"{cls.__name__} is abstract; implement {missing}")
    name = getattr(cls, "name", None)
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise PhenomenonError(
            f"{cls.__name__}.name must be an identifier such as 'fog', got {name!r}"
        )
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


class PhenomenonRegistry(Registry[Phenomenon]):
    """Maps names to phenomenon classes: the generic :class:`~anunnaki.plugins.Registry`.

    A name with ``+`` is a composition (``"fog+raindrop"``), built by the registry's
    ``combine`` hook.

    Args:
        builtins: Register :data:`BUILTIN_PHENOMENA` (default ``True``).
        entry_point_group: Entry-point group to load plugins from on the first lookup;
            ``None`` disables plugins.

    """

    def __init__(
        self, *, builtins: bool = True, entry_point_group: str | None = ENTRY_POINT_GROUP
    ) -> None:
        super().__init__(
            "phenomenon",
            group=entry_point_group,
            kind=Phenomenon,
            check=_check_class,
            error=PhenomenonError,
            hint="combine them with '+', e.g. 'fog+raindrop'",
            logger="anunnaki.phenomena",
            combine=lambda parts: Composition(*parts, registry=self),
            separator="+",
        )
        if builtins:
            for cls in BUILTIN_PHENOMENA:
                self.register(cls)

    def get(self, name_or_instance: str | Phenomenon) -> Phenomenon:
        """Return an instance for a name (``"fog"``, ``"fog+raindrop"``); pass instances through.

        Raises:
            PhenomenonError: Unknown name (the message lists the valid names) or an
                argument that is neither a string nor a :class:`Phenomenon`.

        """
        return self.create(name_or_instance)


_DEFAULT = PhenomenonRegistry()


def default_registry() -> PhenomenonRegistry:
    """Return the process-wide registry used by the module-level functions."""
    return _DEFAULT


def register_phenomenon(cls: P, *, replace: bool = False) -> P:
    """Register *cls* in the default registry (also works as a class decorator)."""
    return _DEFAULT.register(cls, replace=replace)


def get_phenomenon(
    name_or_instance: str | Phenomenon, *, registry: PhenomenonRegistry | None = None
) -> Phenomenon:
    """Return a phenomenon for a name or an instance; see :meth:`PhenomenonRegistry.get`."""
    return (registry or _DEFAULT).get(name_or_instance)


def available_phenomena(*, registry: PhenomenonRegistry | None = None) -> list[str]:
    """Return the sorted names of the registered phenomena (built-ins and plugins)."""
    return (registry or _DEFAULT).names()
