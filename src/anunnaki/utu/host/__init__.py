"""Utu's host: where the cycle (:mod:`anunnaki.utu.cycle`) meets the bus, threads and clocks.

* ``_nodes``: :class:`UtuNode` on :class:`anunnaki.bus.Node` — the operator desk, run-stop,
  liveliness and watchdog, written once — and the five stage nodes (one process each, or
  several in one process);
* ``_manager``: :class:`AutonomicManager`, the five stages run inline on one thread, handing
  each other their messages by direct call;
* ``_actuators``: how actions reach the managed system (over the bus, or recorded);
* ``_threads``: actions off the loop's path (worker threads);
* ``_intake``, ``_peers``, ``_notify``: a live step's intake budget, the watch over the
  nodes of other processes, notifications.

The public names are re-exported by :mod:`anunnaki.utu`.
"""
