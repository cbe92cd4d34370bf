"""Safe YAML loading with line numbers, for every file a user writes.

PyYAML's ``SafeLoader`` already refuses language-specific tags (``!!python/object``);
on top of it this loader refuses what a hostile or careless file can do to a process:

* anchors and aliases (the "billion laughs" expansion) — a model file never needs them;
* files larger than ``max_bytes`` and nesting deeper than ``max_depth``;
* tags other than YAML's plain core types;
* duplicate mapping keys (PyYAML silently keeps the last one).

It returns plain Python data together with a :class:`LineMap` from element paths
(``("goals", 3, "utility")``) to 1-based line numbers, so that validation errors can name
the line of the element at fault.
"""

from __future__ import annotations

import os
import re
import stat
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml
from yaml.events import AliasEvent, CollectionStartEvent, ScalarEvent
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode
from yaml.reader import ReaderError

from anunnaki.errors import ModelFileError, validation_message

__all__ = ["MAX_BYTES", "MAX_DEPTH", "LineMap", "load_yaml", "read_text_limited"]

MAX_BYTES = 4_000_000
MAX_DEPTH = 64

_PLAIN_TAGS = {
    "tag:yaml.org,2002:str",
    "tag:yaml.org,2002:int",
    "tag:yaml.org,2002:float",
    "tag:yaml.org,2002:bool",
    "tag:yaml.org,2002:null",
    "tag:yaml.org,2002:map",
    "tag:yaml.org,2002:seq",
    "tag:yaml.org,2002:timestamp",
}

Path_ = tuple[str | int, ...]


class LineMap:
    """Maps element paths to the line where the element starts (1-based)."""

    def __init__(self) -> None:
        self._lines: dict[Path_, int] = {}

    def add(self, path: Path_, line: int) -> None:
        """Record that the element at ``path`` starts on ``line``."""
        self._lines.setdefault(path, line)

    def line(self, path: Sequence[str | int]) -> int | None:
        """Return the line of ``path``, or of its longest recorded prefix."""
        p = tuple(path)
        while True:
            if p in self._lines:
                return self._lines[p]
            if not p:
                return None
            p = p[:-1]


def read_text_limited(path: str | Path, *, max_bytes: int = MAX_BYTES) -> str:
    """Read a UTF-8 text file, refusing files over ``max_bytes`` before reading them.

    The file is opened without blocking and checked on the open descriptor: a named pipe or
    a device (``/dev/zero``) is refused, never read, even if it replaced a file after a
    check by name; at most ``max_bytes`` + 1 bytes are read, whatever the file grows to.
    """
    p = Path(path)
    try:
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as exc:
        raise ModelFileError(
            f"cannot read file: {exc.strerror}", path=p, hint="check the path"
        ) from exc
    info = os.fstat(fd)
    if not stat.S_ISREG(info.st_mode):  # a folder, a pipe, a device
        os.close(fd)
        raise ModelFileError("not a regular file", path=p, hint="give the path of a file")
    with os.fdopen(fd, "rb") as f:
        size = info.st_size
        if size <= max_bytes:
            data = f.read(max_bytes + 1)
            size = len(data)
    if size > max_bytes:
        raise ModelFileError(
            f"file is {size} bytes, over the limit of {max_bytes}",
            path=p,
            hint="model files are small; split it or check you passed the right file",
        )
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = exc.object[: exc.start].count(b"\n") + 1
        column = exc.start - (exc.object.rfind(b"\n", 0, exc.start) + 1) + 1
        raise ModelFileError(
            f"not UTF-8 text (byte 0x{exc.object[exc.start]:02x} at column {column})",
            path=p,
            line=line,
            hint="save the file as UTF-8",
        ) from exc
    return text.replace("\r\n", "\n").replace("\r", "\n")  # universal newlines, as read_text


class _GuardedLoader(yaml.SafeLoader):
    """A SafeLoader that refuses aliases/anchors and limits nesting depth.

    Booleans are YAML 1.2's ``true``/``false`` only: YAML 1.1 also reads ``on``, ``off``,
    ``yes``, ``no`` (and ``y``/``n`` in keys of some tools) as booleans, which turns a payload
    field named ``on`` into ``True``.
    """

    yaml_implicit_resolvers = {  # noqa: RUF012 - PyYAML's own class-level table
        first: [(tag, rx) for tag, rx in resolvers if tag != "tag:yaml.org,2002:bool"]
        for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
    }

    max_depth = MAX_DEPTH
    source: str | None = None

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent: Node | None, index: Any) -> Node | None:
        event = self.peek_event()  # type: ignore[no-untyped-call]
        line = event.start_mark.line + 1 if event.start_mark is not None else None
        if isinstance(event, AliasEvent):
            raise ModelFileError(
                f"YAML alias '*{event.anchor}' is not allowed",
                path=self.source,
                line=line,
                hint="write the value out in full; anchors and aliases are refused",
            )
        if isinstance(event, ScalarEvent | CollectionStartEvent) and event.anchor is not None:
            raise ModelFileError(
                f"YAML anchor '&{event.anchor}' is not allowed",
                path=self.source,
                line=line,
                hint="remove the anchor; anchors and aliases are refused",
            )
        self._depth += 1
        if self._depth > self.max_depth:
            raise ModelFileError(
                f"nesting deeper than {self.max_depth} levels",
                path=self.source,
                line=line,
                hint="flatten the structure",
            )
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


_GuardedLoader.add_implicit_resolver(
    "tag:yaml.org,2002:bool",
    re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"),
    list("tTfF"),
)


def _construct(loader: _GuardedLoader, node: Node, path: Path_, lines: LineMap) -> Any:
    lines.add(path, node.start_mark.line + 1)
    if node.tag not in _PLAIN_TAGS:
        raise ModelFileError(
            f"YAML tag '{node.tag}' is not allowed",
            path=loader.source,
            line=node.start_mark.line + 1,
            element=_render_path(path),
            hint="use plain YAML values (strings, numbers, booleans, lists, mappings)",
        )
    if isinstance(node, MappingNode):
        out: dict[Any, Any] = {}
        for key_node, value_node in node.value:
            key = _construct(loader, key_node, path, lines)
            if isinstance(key, dict | list):
                raise ModelFileError(
                    "a mapping key must be a plain value",
                    path=loader.source,
                    line=key_node.start_mark.line + 1,
                    element=_render_path(path),
                )
            if key in out:
                raise ModelFileError(
                    f"duplicate key '{key}'",
                    path=loader.source,
                    line=key_node.start_mark.line + 1,
                    element=_render_path(path),
                    hint="each key may appear once in a mapping",
                )
            lines.add((*path, str(key)), key_node.start_mark.line + 1)
            out[key] = _construct(loader, value_node, (*path, str(key)), lines)
        return out
    if isinstance(node, SequenceNode):
        return [_construct(loader, item, (*path, i), lines) for i, item in enumerate(node.value)]
    assert isinstance(node, ScalarNode)
    try:
        return loader.construct_object(node, deep=True)
    except (ValueError, OverflowError) as exc:  # e.g. an int of 5,000 digits, 2024-13-45
        raise ModelFileError(
            f"cannot read value {node.value[:40]!r}: {exc}",
            path=loader.source,
            line=node.start_mark.line + 1,
            element=_render_path(path),
            hint="quote it to make it a string, or fix the number or date",
        ) from None


def _render_path(path: Sequence[str | int]) -> str:
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "<document>"


def load_yaml(
    source: str | Path,
    *,
    text: str | None = None,
    max_bytes: int = MAX_BYTES,
    max_depth: int = MAX_DEPTH,
) -> tuple[Any, LineMap]:
    """Load one YAML document safely.

    Args:
        source: The file to read, or a name for ``text`` in messages.
        text: The document itself; when ``None``, ``source`` is read.
        max_bytes: Refuse larger documents.
        max_depth: Refuse deeper nesting.

    Returns:
        The data (plain dicts, lists and scalars) and its :class:`LineMap`.

    Raises:
        ModelFileError: unreadable, hostile or malformed YAML, naming file and line.

    """
    if text is None:
        text = read_text_limited(source, max_bytes=max_bytes)
    elif len(text.encode("utf-8", "replace")) > max_bytes:
        raise ModelFileError(
            f"document over the limit of {max_bytes} bytes", path=source, hint="split it"
        )
    try:
        loader = _GuardedLoader(text)
    except ReaderError as exc:  # a control character: refused before parsing
        raise _reader_error(exc, text, source) from None
    loader.source = str(source)
    loader.max_depth = max_depth
    lines = LineMap()
    try:
        node = loader.get_single_node()
        if node is None:
            raise ModelFileError("the file is empty", path=source, hint="write a YAML mapping")
        return _construct(loader, node, (), lines), lines
    except ReaderError as exc:
        raise _reader_error(exc, text, source) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        raise ModelFileError(
            f"invalid YAML: {exc.problem or exc.context}",
            path=source,
            line=mark.line + 1 if mark else None,
            hint="check indentation, colons and quotes on that line",
        ) from None
    except yaml.YAMLError as exc:
        raise ModelFileError(f"invalid YAML: {exc}", path=source) from None
    except RecursionError:
        raise ModelFileError(
            "nesting too deep", path=source, hint="flatten the structure"
        ) from None
    finally:
        loader.dispose()


def _reader_error(exc: ReaderError, text: str, source: str | Path) -> ModelFileError:
    position = min(max(exc.position, 0), len(text))
    return ModelFileError(
        f"character U+{exc.character:04X} is not allowed in YAML",
        path=source,
        line=text.count("\n", 0, position) + 1,
        hint='remove it, or write it as an escape in a double-quoted string ("\\a")',
    )


def element_path(path: Sequence[str | int]) -> str:
    """Render a data path as ``goals[3].utility``."""
    return _render_path(path)


def describe_path(data: Any, loc: Sequence[str | int]) -> tuple[tuple[str | int, ...], str]:
    """Map a pydantic error location onto the loaded data.

    Returns the longest prefix of ``loc`` that exists in ``data`` (pydantic adds union tags
    that are not in the file) and a readable element name that uses ``id``/``name`` fields
    of list items: ``goals[G6].relax.tolerance`` rather than ``goals[5].relax.tolerance``.
    """
    real: list[str | int] = []
    text = ""
    node = data
    for part in loc:
        if isinstance(node, dict) and part in node:
            node = node[part]
            real.append(part)
            text += f".{part}" if text else str(part)
        elif isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node):
            item = node[part]
            label: str | int = part
            if isinstance(item, dict):
                ident = item.get("id", item.get("name"))
                if isinstance(ident, str | int) and not isinstance(ident, bool):
                    label = ident
            node = item
            real.append(part)
            text += f"[{label}]"
        elif (
            isinstance(part, str)
            and part not in ("function-after", "function-before")
            and not (isinstance(node, dict) and node.get("operator") == part)
        ):
            # A key that is missing from the file (e.g. a required field): name it.
            text += f".{part}" if text else part
    return tuple(real), text or "<document>"


def validation_error(
    exc: Any, data: Any, lines: LineMap | None, path: str | Path | None, hint: str | None = None
) -> ModelFileError:
    """Turn the first error of a pydantic ``ValidationError`` into a located ModelFileError."""
    errors = exc.errors(include_url=False)
    first = errors[0]
    real, element = describe_path(data, first["loc"])
    msg = validation_message(first)
    if first["type"] == "extra_forbidden":
        msg = f"unknown field '{first['loc'][-1]}'"
        hint = hint or "check the spelling; see the format in docs/"
    elif first["type"] == "missing":
        msg = f"missing required field '{first['loc'][-1]}'"
    elif first["type"] == "string_type" and not isinstance(first.get("input"), dict | list):
        # YAML reads 5, 1.0, true and 2024-01-01 as numbers, booleans and dates.
        value = first.get("input")
        shown = str(value).lower() if isinstance(value, bool) else str(value)
        hint = hint or f"put the value in quotes to make it text: '{shown}'"
    more = len(errors) - 1
    if more:
        msg += f" (and {more} more problem{'s' if more > 1 else ''})"
    return ModelFileError(
        msg,
        path=path,
        line=lines.line(real) if lines is not None else None,
        element=element,
        hint=hint,
    )
