"""The oracle registry: built-ins, runtime registration and entry-point plugins.

Every plugin slot in Anunnaki takes a name or an object: ``"ground_truth"`` or an oracle
instance. Third-party packages add oracles through the ``anunnaki.oracles`` entry-point
group (the entry point names a class); entry points are loaded lazily on the first lookup,
and one that fails to import or is not an oracle class is logged and skipped, so a broken
plugin never takes the others down. A plugin cannot shadow a built-in or an explicitly
registered oracle.
"""

from __future__ import annotations

import inspect
import logging
from typing import Any, TypeVar

from anunnaki.oracles._base import Oracle, OracleError
from anunnaki.oracles._ground_truth import GroundTruthAssessor
from anunnaki.plugins import Registry, check_name

__all__ = [
    "BUILTIN_ORACLES",
    "ENTRY_POINT_GROUP",
    "OracleRegistry",
    "available_oracles",
    "default_registry",
    "get_oracle",
    "register_oracle",
]

logger = logging.getLogger("anunnaki.oracles")

#: The entry-point group third-party oracles register under.
ENTRY_POINT_GROUP = "anunnaki.oracles"

#: The oracles that ship with Anunnaki.
BUILTIN_ORACLES: tuple[type[Any], ...] = (GroundTruthAssessor,)

# The oracles of the packages above this one (Enlil's learned oracle ``enlil``, the ROS
# bridge's ``light``) are not named here: they register by the entry-point group, in
# pyproject.toml, by their public names (tests/test_layers.py checks both).

C = TypeVar("C", bound=type[Any])


def _check_class(cls: object) -> type[Any]:
    """Return *cls* if it is a usable oracle class, else raise :class:`OracleError`."""
    if not isinstance(cls, type):
        raise OracleError(f"{cls!r} is not a class; register an oracle class")
    if inspect.isabstract(cls):
        missing = ", ".join(sorted(getattr(cls, "__abstractmethods__", ())))
        raise OracleError(f"{cls.__name__} is abstract; implement {missing}")
    if not callable(getattr(cls, "assess", None)):
        raise OracleError(
            f"{cls.__name__} is not an oracle: it has no assess(frame, *, seq, model_id) method"
        )
    check_name(getattr(cls, "name", None), what="oracle", error=OracleError)
    return cls


class OracleRegistry(Registry[Oracle]):
    """Maps names to oracle classes: the generic :class:`~anunnaki.plugins.Registry`.

    Args:
        builtins: Register :data:`BUILTIN_ORACLES` (default ``True``).
        entry_point_group: Entry-point group to load plugins from on the first lookup;
            ``None`` disables plugins.

    """

    def __init__(
        self, *, builtins: bool = True, entry_point_group: str | None = ENTRY_POINT_GROUP
    ) -> None:
        super().__init__(
            "oracle",
            group=entry_point_group,
            kind=Oracle,
            check=_check_class,
            error=OracleError,
            logger="anunnaki.oracles",
        )
        if builtins:
            for cls in BUILTIN_ORACLES:
                self.register(cls)

    def get(self, name_or_instance: str | Oracle, **options: Any) -> Oracle:
        """Return an oracle for a name (built with ``options``); pass instances through.

        Raises:
            OracleError: Unknown name (the message lists the valid names), options given
                with an instance, options the class does not take, or an argument that is
                neither a name nor an oracle.

        """
        oracle = self.create(name_or_instance, **options)
        if not isinstance(oracle, Oracle):  # pragma: no cover - _check_class makes this hold
            raise OracleError(f"oracle {name_or_instance!r} built an object without name/assess")
        return oracle


_DEFAULT = OracleRegistry()


def default_registry() -> OracleRegistry:
    """Return the process-wide registry used by the module-level functions."""
    return _DEFAULT


def register_oracle(cls: C, *, replace: bool = False) -> C:
    """Register *cls* in the default registry (also works as a class decorator)."""
    return _DEFAULT.register(cls, replace=replace)


def get_oracle(
    name_or_instance: str | Oracle, *, registry: OracleRegistry | None = None, **options: Any
) -> Oracle:
    """Return an oracle for a name or an instance; see :meth:`OracleRegistry.get`."""
    return (registry or _DEFAULT).get(name_or_instance, **options)


def available_oracles(*, registry: OracleRegistry | None = None) -> list[str]:
    """Return the sorted names of the registered oracles (built-ins and plugins)."""
    return (registry or _DEFAULT).names()
