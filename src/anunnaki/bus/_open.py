"""Opening a bus: :func:`open_bus`, and the factory of the in-process kind.

:func:`open_bus` validates the options into a :class:`~anunnaki.bus.BusConfig` and asks the
kind's factory in :data:`~anunnaki.bus.BUS_KINDS` for the bus.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pydantic import ValidationError

from anunnaki.bus._api import Bus
from anunnaki.bus._config import BusConfig
from anunnaki.bus._errors import BusConfigError
from anunnaki.bus._executor import Executor
from anunnaki.bus._inproc import InprocBus, InprocHub
from anunnaki.bus._kinds import BUS_KINDS
from anunnaki.errors import validation_message

__all__ = ["open_bus", "open_inproc"]


def open_inproc(
    config: BusConfig, *, clock: Callable[[], float] | None = None, hub: InprocHub | None = None
) -> Bus:
    """The ``"inproc"`` kind: an in-process bus on ``hub`` (default: a new private hub)."""
    return InprocBus(hub=hub, namespace=config.namespace, name=config.name, clock=clock)


def open_bus(
    kind: str | BusConfig = "inproc",
    /,
    *,
    clock: Callable[[], float] | None = None,
    hub: InprocHub | None = None,
    executor: Executor | None = None,
    **options: Any,
) -> Bus:
    """Open a bus.

    Args:
        kind: A name in :data:`BUS_KINDS` (``"inproc"``, ``"zenoh"``, a plugin's), or a
            whole :class:`BusConfig` (e.g. from :meth:`BusConfig.from_file`).
        clock: Returns the time written into envelopes (default ``time.time``).
        hub: For ``"inproc"``: the :class:`InprocHub` to join (buses on one hub meet);
            default a new private hub.
        executor: For ``"inproc"``: deliver on this :class:`Executor`'s thread, in
            publication order, instead of the bus's own threads (a simulated run; a new
            hub is made for it unless ``hub`` is given, which must then have it).
        **options: :class:`BusConfig` fields (``mode``, ``listen``, ``connect``,
            ``multicast_scouting``, ``tls``, ``access_control``, ``namespace``, ``name``,
            ``zenoh``), overriding those of a given config.

    Returns:
        The open bus; close it, or use it as a context manager.

    Raises:
        BusConfigError: An invalid option, naming the field (an unknown kind lists the
            valid ones).
        MissingExtraError: ``"zenoh"`` without eclipse-zenoh installed.
        BusConnectError: The zenoh session could not be opened.

    """
    try:
        if isinstance(kind, BusConfig):
            base = kind.model_dump(exclude_unset=True)
            config = BusConfig.model_validate({**base, **options})
        else:
            config = BusConfig.model_validate({**options, "kind": kind})
    except ValidationError as exc:
        first = exc.errors(include_url=False)[0]
        where = ".".join(str(p) for p in first["loc"]) or "config"
        more = len(exc.errors()) - 1
        extra = f" (and {more} more problem{'s' if more > 1 else ''})" if more else ""
        raise BusConfigError(f"bus option {where}: {validation_message(first)}{extra}") from None
    if executor is not None:
        if config.kind != "inproc":
            raise BusConfigError(
                f"only the inproc bus delivers on an executor; a {config.kind} bus has the "
                "transport's threads (leave executor out)"
            )
        if hub is None:
            hub = InprocHub(executor=executor)
        elif hub.executor is not executor:
            raise BusConfigError("this hub delivers on another executor: give the hub's own")
    return BUS_KINDS.factory(config.kind)(config, clock=clock, hub=hub)
