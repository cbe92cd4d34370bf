"""Reading a run's decision log: what ``anunnaki log``, ``explain`` and ``replay`` use.

A run's knowledge base (SQLite) holds every input, verdict, decision and the files in force;
:func:`open_run` opens one read-only (refusing a file that is not a run log with
:class:`~anunnaki.utu.RunLogError`), :func:`run_span` and :func:`run_models` say what it
covers, :func:`rebuild_goal_state` evaluates the goal model as it stood at an instant,
:func:`reading` and :func:`format_data` render a decision for people, :data:`KINDS` lists
the decision kinds, :func:`export_trace` writes the run as a trace, and
:func:`~anunnaki.utu.replay` runs the log again and compares. See docs/decision-log.md.
"""

from anunnaki.utu._replay import (
    KINDS,
    ReplayReport,
    RunLogError,
    export_trace,
    format_data,
    open_run,
    reading,
    rebuild_goal_state,
    replay,
    run_models,
    run_span,
)

__all__ = [
    "KINDS",
    "ReplayReport",
    "RunLogError",
    "export_trace",
    "format_data",
    "open_run",
    "reading",
    "rebuild_goal_state",
    "replay",
    "run_models",
    "run_span",
]
