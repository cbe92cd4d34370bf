"""Adaptation tactics: what Utu does when goals are violated (the paper's Fig. 10).

A tactic has preconditions (goal states or utility expressions, all of which must hold),
actions run in order (publish on a topic, request a service, change mode, swap a model,
notify a person) and postconditions (goal states expected within a deadline). Tactics are
written in XML, as in the paper, or in YAML; both forms read into the same frozen pydantic
models and write back out, so a file converts losslessly between them.

Reading::

    from anunnaki.tactics import load_tactics

    tactics = load_tactics("examples/rover/tactics.xml")  # or .yaml / .yml
    for tactic in tactics.by_priority():  # highest priority first
        ...

* :func:`load_tactics` ``(path) -> TacticSet`` picks the form by extension (``.xml``,
  ``.yaml``/``.yml``; otherwise a file whose text starts with ``<`` is XML).
* :func:`parse_tactics_xml` / :func:`parse_tactics_yaml` ``(text, *, source=None)`` read text.
* :func:`dump_tactics_xml` / :func:`dump_tactics_yaml` ``(tactic_set) -> str`` write it.

Every problem is a :class:`~anunnaki.errors.ModelFileError` that names the file, the line, the
element and what to do (``tactics.xml:12: tactics[fail-safe].actions[1]: an email notification
needs 'to': an e-mail address (hint: e.g. to: operator@example.com)``). Hostile files (XML
DTDs and entities, YAML aliases and language tags, over 4 MB, nested over
:data:`MAX_DEPTH`) are refused before anything is expanded.

The model: :class:`TacticSet` holds :class:`Tactic` objects; a :data:`Precondition` is a
:class:`GoalState` or an :class:`ExpressionCondition`; an :data:`Action` is an instance of a
:class:`TacticAction` registered in :data:`ACTIONS` — built in: :class:`PublishAction`,
:class:`RequestAction`, :class:`ChangeModeAction`, :class:`SwapModelAction`,
:class:`NotifyAction`. ``priority`` — higher runs first.

An action owns its behaviour: :meth:`TacticAction.send` says what it sends (a
:class:`ServiceRequest` with its timeout, a :class:`Publication` or a :class:`Notice`; together
:data:`Send`) and :meth:`TacticAction.describe` what the decision log says of it. A new action
type is one subclass with its tag, registered with ``@ACTIONS.register`` (or by the
entry-point group ``anunnaki.actions``); both file forms read and write it from its fields.
:data:`EndpointName` is the type of a topic or service field (a logical name the binding
maps, or a ROS-style name).

Where things were written: every element keeps a private :class:`SourceRef` (file, line),
read through its ``source`` property. It is not a field: it takes no part in equality
or dumps (a tactic read from XML equals the same tactic read from YAML), and elements
built in code have ``SourceRef(None, None)``. For ``anunnaki check``,
:meth:`TacticSet.referenced_goals` (goal id → ``[GoalReference(element, line)]``),
:meth:`TacticSet.referenced_endpoints` (``[EndpointReference(kind, name, payload, element,
line)]``) and :meth:`TacticSet.expressions` (``[ExpressionReference(expression, element,
line)]``) list what a set refers to; :class:`Tactic` has the same three for one tactic.

The file formats are described in ``docs/tactics.md``.
"""

from __future__ import annotations

from pathlib import Path

from anunnaki._safeyaml import read_text_limited
from anunnaki.errors import ModelFileError
from anunnaki.tactics._actions import (
    ACTIONS,
    Action,
    ChangeModeAction,
    Notice,
    NotifyAction,
    Publication,
    PublishAction,
    RequestAction,
    Send,
    ServiceRequest,
    SwapModelAction,
    TacticAction,
)
from anunnaki.tactics._schema import (
    ExpressionCondition,
    GoalState,
    Precondition,
    Tactic,
    TacticSet,
)
from anunnaki.tactics._values import (
    ACTION_TYPES,
    FORMAT_TAG,
    GOAL_STATES,
    MAX_DEPTH,
    MAX_PAYLOAD_DEPTH,
    NOTIFY_CHANNELS,
    EndpointName,
    EndpointReference,
    ExpressionReference,
    GoalReference,
    SourceRef,
)
from anunnaki.tactics._xml import FIELD_TYPES, dump_tactics_xml, parse_tactics_xml
from anunnaki.tactics._yaml import dump_tactics_yaml, parse_tactics_yaml

__all__ = [
    "ACTIONS",
    "ACTION_TYPES",
    "FIELD_TYPES",
    "FORMAT_TAG",
    "GOAL_STATES",
    "MAX_DEPTH",
    "MAX_PAYLOAD_DEPTH",
    "NOTIFY_CHANNELS",
    "Action",
    "ChangeModeAction",
    "EndpointName",
    "EndpointReference",
    "ExpressionCondition",
    "ExpressionReference",
    "GoalReference",
    "GoalState",
    "Notice",
    "NotifyAction",
    "Precondition",
    "Publication",
    "PublishAction",
    "RequestAction",
    "Send",
    "ServiceRequest",
    "SourceRef",
    "SwapModelAction",
    "Tactic",
    "TacticAction",
    "TacticSet",
    "dump_tactics_xml",
    "dump_tactics_yaml",
    "load_tactics",
    "parse_tactics_xml",
    "parse_tactics_yaml",
]


def load_tactics(path: str | Path) -> TacticSet:
    """Read a tactics file, XML or YAML.

    The form is chosen by extension: ``.xml`` is XML, ``.yaml`` and ``.yml`` are YAML; any
    other file is XML when its text starts with ``<`` and YAML otherwise.

    Args:
        path: The file (UTF-8, at most 4 MB).

    Returns:
        The tactic set; every element's ``source`` names this file and its line.

    Raises:
        ModelFileError: unreadable, hostile, malformed or invalid file, naming file and line.

    """
    p = Path(path)
    try:
        text = read_text_limited(p)
    except ModelFileError as exc:
        bad = exc.__cause__
        if exc.line is None and isinstance(bad, UnicodeDecodeError):
            # Name the line of the first undecodable byte, like every other error.
            line = bad.object[: bad.start].count(b"\n") + 1
            raise ModelFileError(
                exc.message, path=exc.path, line=line, element=exc.element, hint=exc.hint
            ) from None
        raise
    suffix = p.suffix.lower()
    if suffix == ".xml" or (
        suffix not in (".yaml", ".yml") and text.lstrip("\ufeff \t\r\n").startswith("<")
    ):
        return parse_tactics_xml(text, source=p)
    return parse_tactics_yaml(text, source=p)
