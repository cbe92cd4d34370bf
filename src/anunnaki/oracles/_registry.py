"""The oracle slot, :data:`ORACLES`: built-ins, runtime registration, entry-point plugins.

Every plugin slot in Anunnaki takes a name or an object:
``ORACLES.create("ground_truth", window=30)`` or an oracle instance. Third-party packages
add oracles through the ``anunnaki.oracles`` entry-point group (the entry point names a
class); entry points are loaded on the first lookup of a name that is not a built-in, and
one that fails to import or is not an oracle class is logged and skipped, so a broken
plugin never takes the others down. A plugin cannot shadow a built-in or an explicitly
registered oracle.
"""

from __future__ import annotations

import inspect
import logging
from typing import Any

from anunnaki.oracles._base import Oracle, OracleError
from anunnaki.oracles._ground_truth import GroundTruthAssessor
from anunnaki.plugins import Registry, check_name

__all__ = ["BUILTIN_ORACLES", "ORACLES"]

logger = logging.getLogger("anunnaki.oracles")

#: The oracles that ship with Anunnaki.
BUILTIN_ORACLES: tuple[type[Any], ...] = (GroundTruthAssessor,)

# The oracles of the packages above this one (Enlil's learned oracle ``enlil``, the ROS
# bridge's ``light``) are not named here: they register by the entry-point group, in
# pyproject.toml, by their public names (tests/test_layers.py checks both).


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


#: The oracles: names -> classes (a :class:`~anunnaki.plugins.Registry`).
#: ``create("ground_truth", window=30)`` builds one (an instance passes through),
#: ``names()`` lists them, ``register`` (a class decorator) adds one; third parties and the
#: packages above this one by the entry-point group ``anunnaki.oracles``.
ORACLES: Registry[Oracle] = Registry(
    "oracle",
    group="anunnaki.oracles",
    kind=Oracle,
    check=_check_class,
    error=OracleError,
    logger="anunnaki.oracles",
)
for _cls in BUILTIN_ORACLES:
    ORACLES.register(_cls)
