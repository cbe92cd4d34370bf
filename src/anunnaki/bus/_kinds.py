"""The bus kinds: a slot like every other, ``"inproc"`` and ``"zenoh"`` built in.

A kind is a factory ``(config, *, clock, hub) -> Bus``: ``config`` the validated
:class:`~anunnaki.bus.BusConfig`, ``clock`` what the bus writes into envelopes (``None``:
wall time), ``hub`` the :class:`~anunnaki.bus.InprocHub` to join (the in-process kind
only). Another transport (e.g. a shared-memory bus) registers by the entry-point group
``anunnaki.buses`` and passes the bus contract suite (``tests/bus/test_contract.py``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from anunnaki.bus._api import Bus
from anunnaki.bus._errors import BusConfigError
from anunnaki.bus._inproc import InprocBus, InprocHub
from anunnaki.plugins import Registry

if TYPE_CHECKING:
    from anunnaki.bus._config import BusConfig

__all__ = ["BUS_KINDS"]


def inproc(
    config: BusConfig, *, clock: Callable[[], float] | None = None, hub: InprocHub | None = None
) -> Bus:
    """An in-process bus on ``hub`` (default: a new private hub)."""
    return InprocBus(hub=hub, namespace=config.namespace, name=config.name, clock=clock)


def zenoh(
    config: BusConfig, *, clock: Callable[[], float] | None = None, hub: InprocHub | None = None
) -> Bus:
    """A zenoh session (eclipse-zenoh is imported here, when one is opened)."""
    if hub is not None:
        raise BusConfigError("hub only applies to the inproc bus")
    from anunnaki.bus._zenoh import ZenohBus  # the zenoh extra, imported on first use

    return ZenohBus(config, clock=clock)


#: The bus kinds: name -> ``(config, *, clock, hub) -> Bus``.
BUS_KINDS: Registry[Bus] = Registry(
    "bus kind", group="anunnaki.buses", error=BusConfigError, logger="anunnaki.bus"
)
BUS_KINDS.register(inproc)
BUS_KINDS.register(zenoh)
