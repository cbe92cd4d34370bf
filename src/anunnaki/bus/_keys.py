"""The one mapping between ROS-style names and bus keys.

Robots and the paper speak ROS: topics such as ``/utu/oracle/output``. Zenoh speaks key
expressions, which may not start with ``/``. The mapping is a plain prefix::

    topic    /utu/oracle/output      <->  <namespace>/utu/oracle/output
    service  /lm_manager/swap_model  <->  <namespace>/srv/lm_manager/swap_model
    node     /utu_monitor            <->  <namespace>/node/utu_monitor   (liveliness tokens)

The namespace (default ``anunnaki``; may have several segments, e.g. ``anunnaki/rover1``)
isolates several systems that share one network. The first topic segment ``srv`` is reserved
so that the service sub-tree never overlaps a topic.

Names are ``/``-separated segments of ``[A-Za-z0-9_]``; a relative name (``rover/mode``) is
taken as absolute (the bus has no node namespaces). Subscription patterns may also use the
zenoh wildcards ``*`` (exactly one segment) and ``**`` (any number of segments, also none) as
whole segments. Patterns are canonicalised the way zenoh does (``**/**`` -> ``**``,
``**/*`` -> ``*/**``) so that both buses accept the same patterns.
"""

from __future__ import annotations

import re
from functools import lru_cache
from typing import Literal

from anunnaki.bus._errors import TopicNameError

__all__ = [
    "DEFAULT_NAMESPACE",
    "key_matches",
    "key_to_ros",
    "node_key",
    "ros_to_key",
    "service_key",
    "validate_name",
    "validate_namespace",
    "validate_pattern",
]

DEFAULT_NAMESPACE = "anunnaki"
SERVICE_SEGMENT = "srv"
NODE_SEGMENT = "node"

NameKind = Literal["topic", "service", "node"]

_SEGMENT = re.compile(r"[A-Za-z0-9_]+")
_RULE = "names are '/'-separated segments of [A-Za-z0-9_], with no empty segment"
_PATTERN_RULE = _RULE + "; '*' and '**' are allowed only as whole segments of a pattern"


def _segments(name: object, what: str, rule: str) -> list[str]:
    if not isinstance(name, str):
        raise TopicNameError(f"invalid {what} name {name!r}: not a string (rule: {rule})")
    body = name[1:] if name.startswith("/") else name
    if not body:
        raise TopicNameError(f"invalid {what} name {name!r}: empty name (rule: {rule})")
    return body.split("/")


def validate_name(name: str, kind: NameKind = "topic") -> str:
    """Check a concrete (wildcard-free) name and return it in absolute form.

    Args:
        name: A ROS-style name, e.g. ``/utu/oracle/output`` or ``rover/mode``.
        kind: ``"topic"``, ``"service"`` or ``"node"``; it only changes the wording of
            errors, and topics may not start with the reserved segment ``srv``.

    Returns:
        The name with a leading ``/``.

    Raises:
        TopicNameError: The name breaks a rule; the message names the name and the rule.

    """
    segments = _segments(name, kind, _RULE)
    for seg in segments:
        if seg in ("*", "**"):
            raise TopicNameError(
                f"invalid {kind} name {name!r}: wildcard {seg!r} in a concrete name "
                f"(rule: {kind}s that are published, served or held may not contain wildcards)"
            )
        _check_segment(name, seg, kind, _RULE)
    if kind == "topic" and segments[0] == SERVICE_SEGMENT:
        raise TopicNameError(
            f"invalid topic name {name!r}: the first segment {SERVICE_SEGMENT!r} is reserved "
            f"for services (rule: topics may not start with /{SERVICE_SEGMENT})"
        )
    return "/" + "/".join(segments)


def validate_pattern(pattern: str, kind: NameKind = "topic") -> str:
    """Check a subscription pattern and return it absolute and canonical.

    ``*`` matches exactly one segment and ``**`` any number of segments (also none), as in
    zenoh. ``/utu/**/**`` becomes ``/utu/**`` and ``/a/**/*`` becomes ``/a/*/**``.

    Raises:
        TopicNameError: The pattern breaks a rule.

    """
    segments = _segments(pattern, kind + " pattern", _PATTERN_RULE)
    for seg in segments:
        if seg not in ("*", "**"):
            _check_segment(pattern, seg, kind + " pattern", _PATTERN_RULE)
    return "/" + "/".join(_canonical(segments))


def _check_segment(name: str, seg: str, what: str, rule: str) -> None:
    if seg == "":
        raise TopicNameError(f"invalid {what} name {name!r}: empty segment (rule: {rule})")
    if not _SEGMENT.fullmatch(seg):
        bad = sorted({c for c in seg if not (c.isascii() and (c.isalnum() or c == "_"))})
        raise TopicNameError(
            f"invalid {what} name {name!r}: segment {seg!r} contains {''.join(bad)!r} "
            f"(rule: {rule})"
        )


def _canonical(segments: list[str]) -> list[str]:
    """Zenoh's canonical form: no ``**/**``, and ``*`` before an adjacent ``**``."""
    out: list[str] = []
    for seg in segments:
        if seg == "**" and out and out[-1] == "**":
            continue
        if seg == "*" and out and out[-1] == "**":
            out.insert(len(out) - 1, "*")
            continue
        out.append(seg)
    return out


def validate_namespace(namespace: str) -> str:
    """Check a namespace (``anunnaki``, ``lab/rover1``): segments, no wildcard, no outer ``/``."""
    rule = "a namespace is '/'-separated segments of [A-Za-z0-9_], no leading or trailing '/'"
    if not isinstance(namespace, str) or not namespace:
        raise TopicNameError(f"invalid namespace {namespace!r}: empty (rule: {rule})")
    for seg in namespace.split("/"):
        if not _SEGMENT.fullmatch(seg):
            raise TopicNameError(
                f"invalid namespace {namespace!r}: bad segment {seg!r} (rule: {rule})"
            )
    return namespace


def ros_to_key(name: str, namespace: str = DEFAULT_NAMESPACE, *, pattern: bool = False) -> str:
    """Map a ROS-style topic name (or, with ``pattern=True``, a pattern) to a bus key.

    >>> ros_to_key("/utu/oracle/output")
    'anunnaki/utu/oracle/output'
    >>> ros_to_key("/utu/**", "lab/rover1", pattern=True)
    'lab/rover1/utu/**'
    """
    validate_namespace(namespace)
    absolute = validate_pattern(name) if pattern else validate_name(name, "topic")
    return namespace + absolute


def key_to_ros(key: str, namespace: str = DEFAULT_NAMESPACE) -> str:
    """Map a bus key back to its ROS-style topic name (the inverse of :func:`ros_to_key`).

    Patterns map back too (``anunnaki/utu/**`` -> ``/utu/**``).

    Raises:
        TopicNameError: The key is outside the namespace or does not map to a valid name.

    """
    validate_namespace(namespace)
    prefix = namespace + "/"
    if not isinstance(key, str) or not key.startswith(prefix):
        raise TopicNameError(
            f"invalid key {key!r}: not under the namespace {namespace!r} "
            f"(rule: keys are '<namespace>/<topic path>')"
        )
    return validate_pattern(key[len(prefix) - 1 :])


def service_key(name: str, namespace: str = DEFAULT_NAMESPACE) -> str:
    """Map a service name (``/lm/swap``) to its key (``<namespace>/srv/lm/swap``)."""
    validate_namespace(namespace)
    return f"{namespace}/{SERVICE_SEGMENT}{validate_name(name, 'service')}"


def node_key(name: str, namespace: str = DEFAULT_NAMESPACE) -> str:
    """Map a node name (``/utu_monitor``) to its liveliness key (``<ns>/node/utu_monitor``)."""
    validate_namespace(namespace)
    return f"{namespace}/{NODE_SEGMENT}{validate_name(name, 'node')}"


def lenient_name(key: str, prefix: str) -> str:
    """Best-effort ROS-style name of a key under ``prefix`` (for stats and logs, never raises)."""
    return "/" + key[len(prefix) :] if key.startswith(prefix) else key


def key_matches(pattern: str, key: str) -> bool:
    """Tell whether the zenoh-style key ``pattern`` (``*``, ``**``) matches the concrete ``key``.

    >>> key_matches("anunnaki/**/camera/**", "anunnaki/rover/camera/image")
    True
    >>> key_matches("anunnaki/*", "anunnaki/a/b")
    False
    """
    return _match(tuple(pattern.split("/")), tuple(key.split("/")))


@lru_cache(maxsize=4096)
def _match(pattern: tuple[str, ...], key: tuple[str, ...]) -> bool:
    if not pattern:
        return not key
    head = pattern[0]
    if head == "**":
        rest = pattern[1:]
        return any(_match(rest, key[i:]) for i in range(len(key) + 1))
    if not key:
        return False
    if head in ("*", key[0]):
        return _match(pattern[1:], key[1:])
    return False
