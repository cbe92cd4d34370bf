"""What a tactic does: the action types, each one class that owns what it sends and says.

An action type is a :class:`TacticAction` subclass with its tag (``type: Literal["beep"] =
"beep"``), registered in :data:`ACTIONS`. The class alone decides:

* what it sends — :meth:`TacticAction.send` gives a :class:`ServiceRequest` (service,
  payload, how long to wait for the reply), a :class:`Publication` (topic, payload) or a
  :class:`Notice` (a message for a person): the three things an actuator does;
* what the decision log says of it — :meth:`TacticAction.describe`;
* how it is written in a file — its fields are the YAML keys; in XML the element is named by
  the tag, the fields are attributes, except a ``payload`` (``<field>`` elements) and the one
  named by ``XML_TEXT`` (the element's text).

Nothing else in Anunnaki switches over the action types: the file readers and writers, the
checks of ``anunnaki check`` that list endpoints, and Utu's executor all ask the class. A new
action type is one class and its tag::

    @ACTIONS.register
    class SetSpeed(TacticAction):
        type: Literal["set_speed"] = "set_speed"
        speed: float
        service: EndpointName = "set_speed"

        def send(self) -> ServiceRequest:
            return ServiceRequest(self.service, {"speed": self.speed}, timeout=1.0)

Third parties register theirs by the entry-point group ``anunnaki.actions`` (see
:mod:`anunnaki.plugins`); a file naming a type nobody registered gets an error that lists
the known ones.
"""

from __future__ import annotations

import re
import typing
from abc import abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Annotated, Any, ClassVar, Final, Literal, cast

from pydantic import Field, JsonValue, PlainValidator, SerializeAsAny, model_validator
from pydantic_core import PydanticCustomError

from anunnaki import topics
from anunnaki.plugins import PluginError, Registry
from anunnaki.tactics._values import (
    _EMAIL,
    _URL,
    ACTION_TYPES,
    EndpointName,
    Filled,
    Line,
    Payload,
    Seconds,
    Text,
    Token,
    _error,
    _Model,
)

__all__ = [
    "ACTIONS",
    "Action",
    "ChangeModeAction",
    "Notice",
    "NotifyAction",
    "Publication",
    "PublishAction",
    "RequestAction",
    "Send",
    "ServiceRequest",
    "SwapModelAction",
    "TacticAction",
    "action_hint",
    "action_types",
]

# --------------------------------------------------------------------------- what is sent


@dataclass(frozen=True)
class ServiceRequest:
    """A request to a service of the managed system.

    Attributes:
        service: The service, as the tactic names it (a logical name the binding maps, or a
            ROS-style name); Utu resolves it before the request goes out.
        payload: The request's JSON object.
        timeout: Seconds to wait for the reply; past it the action has failed.

    """

    service: str
    payload: dict[str, JsonValue] = field(default_factory=dict)
    timeout: float = 2.0


@dataclass(frozen=True)
class Publication:
    """One message on a topic of the managed system (the topic as the tactic names it)."""

    topic: str
    payload: dict[str, JsonValue] = field(default_factory=dict)


@dataclass(frozen=True)
class Notice:
    """A message for a person, sent by the notifier (e-mail, webhook or the log)."""

    channel: Literal["email", "webhook", "log"]
    to: str | None
    subject: str
    message: str


Send = ServiceRequest | Publication | Notice
"""What an action sends: the three things an actuator does (request, publish, notify)."""


def _same(name: str) -> str:
    return name


# --------------------------------------------------------------------------- the base


class TacticAction(_Model):
    """One action of a tactic: a frozen pydantic model that owns what it sends and says.

    Subclass it, give the tag and the fields, implement :meth:`send`, and register the
    class in :data:`ACTIONS` (see the module docstring). Override :meth:`describe` when the
    decision log should say more than the endpoint and payload.

    Attributes:
        type: The tag that names the type in files (``publish``, ``swap_model``, …);
            each subclass fixes it with ``Literal``.
        XML_TEXT: The field an XML element holds as its text (``notify``'s ``message``);
            ``None``: the element holds no text.

    """

    type: str
    XML_TEXT: ClassVar[str | None] = None

    @abstractmethod
    def send(self) -> Send:
        """What this action sends.

        A :class:`ServiceRequest`, :class:`Publication` or :class:`Notice`. Called when the
        action runs (and by ``anunnaki check``); it must not block or touch anything.
        """

    def endpoint(self) -> tuple[Literal["topic", "service"], str, dict[str, JsonValue]] | None:
        """Return ``(kind, name, payload)`` of what this action sends, ``None`` for a notice."""
        sent = self.send()
        if isinstance(sent, ServiceRequest):
            return "service", sent.service, dict(sent.payload)
        if isinstance(sent, Publication):
            return "topic", sent.topic, dict(sent.payload)
        return None

    def describe(self, resolve: Callable[[str], str] = _same) -> dict[str, Any]:
        """What the decision log says of this action (besides its ``type``).

        Args:
            resolve: Maps a topic or service as the tactic names it to the one used (the
                binding's logical names); the log names the resolved one.

        Returns:
            By default the endpoint and the payload (``{"service": …, "payload": …}`` or
            ``{"topic": …, "payload": …}``), or a notice's channel, recipient and subject.

        """
        sent = self.send()
        if isinstance(sent, ServiceRequest):
            return {"service": resolve(sent.service), "payload": dict(sent.payload)}
        if isinstance(sent, Publication):
            return {"topic": resolve(sent.topic), "payload": dict(sent.payload)}
        return {"channel": sent.channel, "to": sent.to, "subject": sent.subject}


def _tag_of(cls: Any) -> object:
    """The tag a class registers under: its ``type`` field's default."""
    fields = getattr(cls, "model_fields", None)
    info = fields.get("type") if isinstance(fields, Mapping) else None
    return None if info is None else info.default


def _check_action(cls: object) -> type[TacticAction]:
    """A registrable action class, or :class:`~anunnaki.plugins.PluginError` saying the fix."""
    if not (isinstance(cls, type) and issubclass(cls, TacticAction)):
        raise PluginError(f"{cls!r} is not a subclass of anunnaki.tactics.TacticAction")
    tag = _tag_of(cls)
    info = cls.model_fields["type"]
    if not isinstance(tag, str) or typing.get_args(info.annotation) != (tag,):
        raise PluginError(
            f"{cls.__name__} has no tag: give it one as "
            f'type: Literal["{_snake(cls.__name__)}"] = "{_snake(cls.__name__)}"'
        )
    reserved = {"type", "payload", cls.XML_TEXT}
    for name, info in cls.model_fields.items():
        if name not in reserved and not _scalar(info.annotation):
            raise PluginError(
                f"{cls.__name__}.{name}: an action's fields other than 'payload' are "
                "scalars (text, numbers, booleans), so both file forms can hold them"
            )
    return cls


def _snake(name: str) -> str:
    return re.sub(r"(?<!^)(?=[A-Z])", "_", name.removesuffix("Action")).lower()


_SCALARS: Final = (str, int, float, bool, type(None))


def _scalar(annotation: Any) -> bool:
    """Whether every type ``annotation`` admits is a scalar (an XML attribute can hold it)."""
    if annotation in _SCALARS:
        return True
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if origin is Annotated:
        return _scalar(args[0])
    if origin is Literal:
        return all(isinstance(a, _SCALARS) for a in args)
    if args and origin in (typing.Union, type(int | None)):
        return all(_scalar(a) for a in args)
    return False


#: The action types: tag -> :class:`TacticAction` subclass. A slot like every other
#: (:class:`~anunnaki.plugins.Registry`): ``ACTIONS.register`` (a class decorator; another
#: class under a taken tag is an error), ``ACTIONS.names()``; third parties' types by the
#: entry-point group ``anunnaki.actions``.
ACTIONS: Registry[TacticAction] = Registry(
    "action type",
    group="anunnaki.actions",
    kind=TacticAction,
    check=_check_action,
    key=_tag_of,
    logger="anunnaki.tactics",
)


def action_types() -> list[str]:
    """The action types a file may use: the built-ins in their order, then the others sorted."""
    names = ACTIONS.names()
    return [*(n for n in ACTION_TYPES if n in names), *(n for n in names if n not in ACTION_TYPES)]


def action_hint() -> str:
    """The hint for a wrong action type: the types a file may use."""
    return "valid action types: " + ", ".join(action_types())


def action_class(tag: str) -> type[TacticAction] | None:
    """The class registered for ``tag``, or ``None``."""
    if tag not in ACTIONS:
        return None
    return cast(type[TacticAction], ACTIONS.factory(tag))


def _validate_action(value: Any) -> TacticAction:
    """An action from a file's mapping, by the class its ``type`` names (or one built in code).

    The class validates the rest, so a problem inside an action is reported at its field.
    """
    if isinstance(value, TacticAction):
        return value
    if not isinstance(value, Mapping):
        raise PydanticCustomError(
            "model_attributes_type", "an action is a mapping with a 'type' and its fields"
        )
    if "type" not in value:
        raise PydanticCustomError("union_tag_not_found", "the action has no 'type'")
    tag = value["type"]
    cls = action_class(tag) if isinstance(tag, str) else None
    if cls is None:
        raise PydanticCustomError(
            "union_tag_invalid", "unknown action type {tag}", {"tag": str(tag)}
        )
    return cls.model_validate(value)


Action = Annotated[SerializeAsAny[TacticAction], PlainValidator(_validate_action)]
"""An action: an instance of a registered :class:`TacticAction`, told apart by its ``type``."""


# --------------------------------------------------------------------------- the built-ins


@ACTIONS.register
class PublishAction(TacticAction):
    """Publish one message on a topic of the managed system."""

    type: Literal["publish"] = "publish"
    topic: EndpointName
    payload: Payload

    def send(self) -> Publication:
        """The message, on the topic."""
        return Publication(self.topic, dict(self.payload))


@ACTIONS.register
class RequestAction(TacticAction):
    """Call a service of the managed system and wait up to ``timeout`` seconds for the reply."""

    type: Literal["request"] = "request"
    service: EndpointName
    payload: Payload = Field(default_factory=dict)
    timeout: Annotated[Seconds, Field(gt=0)] = 2.0

    def send(self) -> ServiceRequest:
        """The payload, to the service, waiting ``timeout`` seconds."""
        return ServiceRequest(self.service, dict(self.payload), self.timeout)


@ACTIONS.register
class ChangeModeAction(TacticAction):
    """Ask the managed system to change mode: a request ``{"mode": mode}`` to ``service``.

    The reply is awaited ``REPLY_TIMEOUT`` (2 s): a platform changes mode at once.
    """

    type: Literal["change_mode"] = "change_mode"
    mode: Token
    service: EndpointName
    REPLY_TIMEOUT: ClassVar[float] = 2.0

    def send(self) -> ServiceRequest:
        """``{"mode": mode}`` to the service."""
        return ServiceRequest(self.service, {"mode": self.mode}, self.REPLY_TIMEOUT)

    def describe(self, resolve: Callable[[str], str] = _same) -> dict[str, Any]:
        """The service and the mode."""
        return {"service": resolve(self.service), "mode": self.mode}


@ACTIONS.register
class SwapModelAction(TacticAction):
    """Ask the model manager to swap the model of a learning-enabled component.

    Give exactly one of ``model`` (a model id in the registry) or ``domain`` (the manager picks
    the model robustified for that domain, e.g. ``fog``). The reply is awaited
    ``REPLY_TIMEOUT`` (5 s): the manager loads the model before it answers.
    """

    type: Literal["swap_model"] = "swap_model"
    lec: Token = "detector"
    model: Token | None = None
    domain: Token | None = None
    service: EndpointName = topics.SWAP
    REPLY_TIMEOUT: ClassVar[float] = 5.0

    @model_validator(mode="after")
    def _one_target(self) -> SwapModelAction:
        if (self.model is None) == (self.domain is None):
            both = self.model is not None
            raise _error(
                "swap_target",
                "give either 'model' or 'domain', not both"
                if both
                else "say what to swap to: 'model' or 'domain'",
                hint="model is a model id (e.g. detector-fog-v2); domain lets the manager pick "
                "(e.g. fog)",
            )
        return self

    def send(self) -> ServiceRequest:
        """``{"lec": …, "model": …}`` or ``{"lec": …, "domain": …}`` to the model manager."""
        payload: dict[str, JsonValue] = {"lec": self.lec}
        if self.model is not None:
            payload["model"] = self.model
        else:
            payload["domain"] = self.domain
        return ServiceRequest(self.service, payload, self.REPLY_TIMEOUT)

    def describe(self, resolve: Callable[[str], str] = _same) -> dict[str, Any]:
        """The service, the component and what it is swapped to."""
        return {
            "service": resolve(self.service),
            "lec": self.lec,
            "model": self.model,
            "domain": self.domain,
        }


#: The channels that need a recipient: its pattern, the wording of the error, an example.
_RECIPIENTS: Final[dict[str, tuple[re.Pattern[str], str, str, str]]] = {
    "email": (_EMAIL, "an email notification", "an e-mail address", "operator@example.com"),
    "webhook": (
        _URL,
        "a webhook notification",
        "an http(s) URL",
        "https://hooks.example.com/rover",
    ),
}


@ACTIONS.register
class NotifyAction(TacticAction):
    """Tell a person: an e-mail, a webhook call, or a log record.

    ``to`` is required for ``email`` (an address) and ``webhook`` (an http(s) URL); for ``log``
    it optionally names the logger.
    """

    type: Literal["notify"] = "notify"
    channel: Literal["email", "webhook", "log"]
    to: Token | None = None
    subject: Line = ""
    message: Annotated[Text, Filled]
    XML_TEXT: ClassVar[str | None] = "message"

    @model_validator(mode="after")
    def _recipient(self) -> NotifyAction:
        rule = _RECIPIENTS.get(self.channel)
        if rule is None:
            return self
        pattern, notification, what, example = rule
        if self.to is None or not pattern.fullmatch(self.to):
            raise _error(
                "notify_to",
                f"{notification} needs 'to': {what}"
                if self.to is None
                else f"{self.to!r} is not {what}",
                hint=f"e.g. to: {example}",
                where=("to",),
            )
        return self

    def send(self) -> Notice:
        """The notice: channel, recipient, subject and message."""
        return Notice(self.channel, self.to, self.subject, self.message)
