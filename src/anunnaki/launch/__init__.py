"""Launching: a launch file's Utu nodes, on which bus, against which managed system.

The top of the house: it wires Utu (``anunnaki.utu``), the bus and a managed system — a
plugin chosen by ``kind`` in the launch file (:data:`anunnaki.managed.MANAGED`:
``scripted``, ``sim``, ``ros1``, ``ros2``, or a third party's under the ``anunnaki.managed``
entry-point group) — so that Utu itself never imports a simulator, a detector or an
oracle::

    from anunnaki.launch import load_launch, run_launch

    result = run_launch(load_launch("examples/rover/utu.yaml"), speed=5)
    print(result.reason, len(result.decisions))

* :func:`load_launch` / :func:`parse_launch` read and check a launch file (guideline B5:
  every error names file, line and element) into a :class:`Launch`;
* :func:`check_launch` runs the same loader for ``anunnaki check``: every finding instead
  of the first, nothing started;
* :func:`run_launch` runs it: the nodes in this process or one process each (the
  supervisor starts, watches and stops them), readiness (C9), the managed system, one line
  per decision, a clean stop on a signal.

See docs/running.md.
"""

from anunnaki.launch._check import check_launch
from anunnaki.launch._mailsink import MailSink, ReceivedMail
from anunnaki.launch._runner import RunResult, format_decision, run_launch
from anunnaki.launch._schema import (
    Launch,
    LaunchConfig,
    LaunchError,
    NodeSettings,
    load_launch,
    parse_launch,
)
from anunnaki.launch._supervisor import Children, child_bus_config, signals_to, wait_ready

__all__ = [
    "Children",
    "Launch",
    "LaunchConfig",
    "LaunchError",
    "MailSink",
    "NodeSettings",
    "ReceivedMail",
    "RunResult",
    "check_launch",
    "child_bus_config",
    "format_decision",
    "load_launch",
    "parse_launch",
    "run_launch",
    "signals_to",
    "wait_ready",
]
