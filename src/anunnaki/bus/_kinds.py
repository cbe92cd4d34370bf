"""The bus kinds: a slot like every other, ``"inproc"`` and ``"zenoh"`` built in.

A kind is a factory ``(config, *, clock, hub) -> Bus``: ``config`` the validated
:class:`~anunnaki.bus.BusConfig`, ``clock`` what the bus writes into envelopes (``None``:
wall time), ``hub`` the :class:`~anunnaki.bus.InprocHub` to join (the in-process kind
only). Another transport (e.g. a shared-memory bus) registers by the entry-point group
``anunnaki.buses`` and passes the bus contract suite (``tests/bus/test_contract.py``).

The slot sits below what names a kind (:class:`~anunnaki.bus.BusConfig` checks its ``kind``
here) and below the factories: the built-ins are registered by where they live
(``_open.open_inproc``, ``_zenoh.open_zenoh``) and imported when a bus of theirs is first
opened, so this module imports neither, and the configuration, the kinds and the transports
stand one above the other without a circle.
"""

from __future__ import annotations

from anunnaki.bus._api import Bus
from anunnaki.bus._errors import BusConfigError
from anunnaki.plugins import Registry

__all__ = ["BUS_KINDS"]

#: The bus kinds: name -> ``(config, *, clock, hub) -> Bus``.
BUS_KINDS: Registry[Bus] = Registry(
    "bus kind", group="anunnaki.buses", error=BusConfigError, logger="anunnaki.bus"
)
BUS_KINDS.register_lazy("inproc", "anunnaki.bus._open:open_inproc")
BUS_KINDS.register_lazy("zenoh", "anunnaki.bus._zenoh:open_zenoh")
