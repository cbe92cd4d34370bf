"""The XML form of tactics files, after the paper's Fig. 10.

Parsing is defused: :class:`defusedxml.ElementTree.DefusedXMLParser` refuses any DTD (so no
entity can be declared, let alone expanded: no "billion laughs", no external entities), the
text is limited to 4 MB and element nesting to :data:`~anunnaki.tactics.MAX_DEPTH`, checked as
each start tag is read. ElementTree keeps no line numbers, so the parser feeds a small tree
builder that asks the underlying expat parser for ``CurrentLineNumber`` at every start tag.

The tree is then read into the same plain data and line map as the YAML form, and validated by
:func:`~anunnaki.tactics._load.build_tactic_set`: both forms report the same problems the
same way. Payload fields are typed (``str``, ``int``, ``float``, ``bool``, ``json``); ``json``
is read with :func:`json.loads`, never evaluated.
"""

from __future__ import annotations

import json
import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final
from xml.parsers import expat

from defusedxml import DefusedXmlException, DTDForbidden, EntitiesForbidden
from defusedxml.ElementTree import DefusedXMLParser, ParseError
from pydantic import JsonValue

from anunnaki._safeyaml import MAX_BYTES, LineMap, element_path
from anunnaki.errors import ModelFileError
from anunnaki.tactics._actions import TacticAction, action_class, action_hint, action_types
from anunnaki.tactics._load import (
    build_tactic_set,
)
from anunnaki.tactics._schema import (
    ExpressionCondition,
    GoalState,
    Tactic,
    TacticSet,
)
from anunnaki.tactics._values import (
    MAX_DEPTH,
    tactic_element,
)

__all__ = ["FIELD_TYPES", "dump_tactics_xml", "parse_tactics_xml"]

FIELD_TYPES: Final = ("str", "int", "float", "bool", "json")
"""The types of a payload ``<field>``."""

_INT = re.compile(r"[+-]?[0-9]+")
_FLOAT = re.compile(r"[+-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?")
_HOSTILE_HINT = (
    "tactics files use no DTD, entities or external references; remove the <!DOCTYPE …> "
    "declaration and write values out in full"
)


def _attributes(cls: type[TacticAction]) -> list[str]:
    """An action element's attributes: its class's fields but the tag, payload and text."""
    return [n for n in cls.model_fields if n not in ("type", "payload", cls.XML_TEXT)]


@dataclass
class _Node:
    tag: str
    attrib: dict[str, str]
    line: int
    children: list[_Node] = field(default_factory=list)
    parts: list[str] = field(default_factory=list)
    text_line: int | None = None

    @property
    def text(self) -> str:
        return "".join(self.parts)


class _LineTreeBuilder:
    """An ElementTree parser target that builds :class:`_Node` trees with line numbers."""

    def __init__(self, source: str | Path | None) -> None:
        self.source = source
        self.expat: Any = None  # the parser's pyexpat object, set right after construction
        self.stack: list[_Node] = []
        self.root: _Node | None = None

    def start(self, tag: str, attrib: dict[str, str]) -> None:
        line = int(self.expat.CurrentLineNumber)
        if len(self.stack) >= MAX_DEPTH:
            raise ModelFileError(
                f"elements nested deeper than {MAX_DEPTH} levels",
                path=self.source,
                line=line,
                element=f"<{tag}>",
                hint="a tactics file is a few levels deep; check the file",
            )
        node = _Node(tag, dict(attrib), line)
        if self.stack:
            self.stack[-1].children.append(node)
        else:
            self.root = node
        self.stack.append(node)

    def end(self, tag: str) -> None:
        self.stack.pop()

    def data(self, text: str) -> None:
        if self.stack:
            node = self.stack[-1]
            node.parts.append(text)
            if node.text_line is None and text.strip():
                node.text_line = int(self.expat.CurrentLineNumber)

    def pi(self, target: str, data: str | None = None) -> None:
        raise ModelFileError(
            f"refused: a processing instruction (<?{target} …?>) is not allowed",
            path=self.source,
            line=int(self.expat.CurrentLineNumber),
            hint="a tactics file holds elements only: remove the <?…?> line (the XML "
            'declaration <?xml version="1.0"?> may stay)',
        )

    def close(self) -> _Node | None:
        return self.root


def _parse_tree(text: str, source: str | Path | None) -> _Node:
    try:
        raw = text.encode("utf-8")
    except UnicodeEncodeError as exc:
        raise ModelFileError(
            f"text holds a character UTF-8 cannot encode (at {exc.start})", path=source
        ) from None
    if len(raw) > MAX_BYTES:
        raise ModelFileError(
            f"document is {len(raw)} bytes, over the limit of {MAX_BYTES}",
            path=source,
            hint="tactics files are small; check you passed the right file",
        )
    builder = _LineTreeBuilder(source)
    # The document is UTF-8 whatever its declaration says: it was read (or given) as text.
    parser = DefusedXMLParser(target=builder, encoding="utf-8", forbid_dtd=True)
    builder.expat = pyexpat = parser.parser
    pyexpat.buffer_text = False  # deliver text as read, so its line is the current one
    try:
        parser.feed(raw)
        root = parser.close()
    except DefusedXmlException as exc:
        if isinstance(exc, DTDForbidden):
            what = f"a DTD (<!DOCTYPE {exc.name} …>) is not allowed"
        elif isinstance(exc, EntitiesForbidden):
            what = f"entity declaration {exc.name!r} is not allowed"
        else:
            what = "external references are not allowed"
        raise ModelFileError(
            f"refused: {what}",
            path=source,
            line=int(pyexpat.CurrentLineNumber),
            hint=_HOSTILE_HINT,
        ) from None
    except ParseError as exc:
        line, _column = exc.position
        raise ModelFileError(
            f"malformed XML: {expat.ErrorString(exc.code)}",
            path=source,
            line=line,
            hint="check that every tag is closed and that & and < in text are written "
            "&amp; and &lt;",
        ) from None
    if not isinstance(root, _Node):  # pragma: no cover - expat reports "no element found"
        raise ModelFileError("the document has no root element", path=source, line=1)
    return root


class _Reader:
    """Reads a :class:`_Node` tree into plain data and a line map."""

    def __init__(self, source: str | Path | None) -> None:
        self.source = source
        self.lines = LineMap()
        self.tactic_name: str | None = None

    def fail(
        self,
        message: str,
        node: _Node,
        path: Sequence[str | int],
        *,
        hint: str | None = None,
        line: int | None = None,
    ) -> ModelFileError:
        element: str | None
        if self.tactic_name is not None and len(path) >= 2 and path[0] == "tactics":
            element = tactic_element(self.tactic_name, path[2:])
        else:
            element = element_path(path) if path else None
        return ModelFileError(
            message,
            path=self.source,
            line=line if line is not None else node.line,
            element=element,
            hint=hint,
        )

    def attrs(
        self,
        node: _Node,
        path: tuple[str | int, ...],
        allowed: dict[str, str],
        required: Sequence[str] = (),
        *,
        record: bool = True,
    ) -> dict[str, Any]:
        for name in node.attrib:
            if name not in allowed:
                raise self.fail(
                    f"unknown attribute {name!r} on <{node.tag}>",
                    node,
                    path,
                    hint=f"<{node.tag}> takes " + (", ".join(allowed) or "no attributes"),
                )
        for name in required:
            if name not in node.attrib:
                raise self.fail(
                    f"<{node.tag}> needs the attribute {name!r}", node, path, hint=f"add {name}=…"
                )
        out: dict[str, Any] = {}
        for name, value in node.attrib.items():
            out[allowed[name]] = value
            if record:
                self.lines.add((*path, allowed[name]), node.line)
        return out

    def no_text(self, node: _Node, path: tuple[str | int, ...]) -> None:
        if node.text.strip():
            raise self.fail(
                f"unexpected text in <{node.tag}>",
                node,
                path,
                line=node.text_line,
                hint="text belongs in <description>, <expression>, <notify> and <field>",
            )

    def leaf(self, node: _Node, path: tuple[str | int, ...]) -> str:
        if node.children:
            child = node.children[0]
            raise self.fail(
                f"<{child.tag}> is not allowed inside <{node.tag}>",
                child,
                path,
                hint=f"<{node.tag}> holds text only",
            )
        return node.text

    def children(
        self, node: _Node, path: tuple[str | int, ...], allowed: Sequence[str], hint: str
    ) -> list[_Node]:
        self.no_text(node, path)
        for child in node.children:
            if child.tag not in allowed:
                raise self.fail(
                    f"<{child.tag}> is not allowed inside <{node.tag}>", child, path, hint=hint
                )
        return node.children

    # ----------------------------------------------------------------------- elements

    def read(self, root: _Node) -> dict[str, Any]:
        if "}" in root.tag:
            raise self.fail(
                "XML namespaces are not used in tactics files",
                root,
                (),
                hint="write the root element as plain <tactics>",
            )
        if root.tag != "tactics":
            raise self.fail(
                f"the root element is <{root.tag}>, expected <tactics>",
                root,
                (),
                hint="a tactics file is <tactics> holding <tactic> elements",
            )
        self.lines.add((), root.line)
        data = self.attrs(root, (), {"name": "name"})
        tactics: list[dict[str, Any]] = []
        data["tactics"] = tactics
        self.lines.add(("tactics",), root.line)
        nodes = self.children(root, (), ("tactic",), "<tactics> holds <tactic> elements")
        for i, node in enumerate(nodes):
            tactics.append(self.tactic(node, ("tactics", i)))
        self.tactic_name = None
        return data

    def tactic(self, node: _Node, path: tuple[str | int, ...]) -> dict[str, Any]:
        self.tactic_name = node.attrib.get("name", "").strip() or None
        self.lines.add(path, node.line)
        out = self.attrs(
            node,
            path,
            {n: n for n in ("name", "priority", "cooldown", "requires_approval")},
            ("name",),
        )
        sections = ("description", "preconditions", "actions", "postconditions", "conflicts")
        seen: set[str] = set()
        hint = "<tactic> holds " + ", ".join(f"<{s}>" for s in sections)
        for child in self.children(node, path, sections, hint):
            if child.tag in seen:
                raise self.fail(
                    f"<{child.tag}> appears twice in one <tactic>",
                    child,
                    path,
                    hint="merge them into one",
                )
            seen.add(child.tag)
            sub = (*path, child.tag)
            self.lines.add(sub, child.line)
            if child.tag == "description":
                self.attrs(child, sub, {})
                out["description"] = self.leaf(child, sub)
            elif child.tag == "preconditions":
                self.attrs(child, sub, {})
                out["preconditions"] = [
                    self.precondition(c, (*sub, j))
                    for j, c in enumerate(
                        self.children(
                            child,
                            sub,
                            ("goal", "expression"),
                            "a precondition is <goal id=… state=…/> or <expression>…</expression>",
                        )
                    )
                ]
            elif child.tag == "actions":
                self.attrs(child, sub, {})
                out["actions"] = [
                    self.action(c, (*sub, j))
                    for j, c in enumerate(self.children(child, sub, action_types(), action_hint()))
                ]
            elif child.tag == "postconditions":
                out.update(self.attrs(child, sub, {"deadline": "deadline"}))
                if "deadline" in out:
                    self.lines.add((*path, "deadline"), child.line)
                out["postconditions"] = [
                    self.goal(c, (*sub, j))
                    for j, c in enumerate(
                        self.children(
                            child, sub, ("goal",), "a postcondition is <goal id=… state=…/>"
                        )
                    )
                ]
            else:
                self.attrs(child, sub, {})
                names: list[Any] = []
                for j, c in enumerate(
                    self.children(child, sub, ("tactic",), "write <tactic name=…/> entries")
                ):
                    self.no_text(c, (*sub, j))
                    self.leaf(c, (*sub, j))
                    names.append(self.attrs(c, (*sub, j), {"name": "name"}, ("name",))["name"])
                    self.lines.add((*sub, j), c.line)
                out["conflicts"] = names
        return out

    def goal(self, node: _Node, path: tuple[str | int, ...]) -> dict[str, Any]:
        self.lines.add(path, node.line)
        self.no_text(node, path)
        self.leaf(node, path)
        return self.attrs(node, path, {"id": "goal", "state": "state"}, ("id", "state"))

    def precondition(self, node: _Node, path: tuple[str | int, ...]) -> dict[str, Any]:
        if node.tag == "goal":
            return self.goal(node, path)
        self.lines.add(path, node.line)
        self.lines.add((*path, "expression"), node.line)
        self.attrs(node, path, {})
        return {"expression": self.leaf(node, path)}

    def action(self, node: _Node, path: tuple[str | int, ...]) -> dict[str, Any]:
        self.lines.add(path, node.line)
        cls = action_class(node.tag)
        assert cls is not None  # children() let only the registered types through
        allowed = {name: name for name in _attributes(cls)}
        required = [name for name in allowed if cls.model_fields[name].is_required()]
        out: dict[str, Any] = {"type": node.tag}
        out.update(self.attrs(node, path, allowed, required))
        if "payload" in cls.model_fields:
            out["payload"] = self.payload(node, (*path, "payload"))
        elif cls.XML_TEXT is not None:
            out[cls.XML_TEXT] = self.leaf(node, path)
        else:
            self.no_text(node, path)
            self.leaf(node, path)
        return out

    def payload(self, node: _Node, path: tuple[str | int, ...]) -> dict[str, JsonValue]:
        self.lines.add(path, node.line)
        out: dict[str, JsonValue] = {}
        hint = "a payload is written as <field name=… type=…>value</field> elements"
        for child in self.children(node, path[:-1], ("field",), hint):
            spec = self.attrs(
                child, path, {"name": "name", "type": "type"}, ("name",), record=False
            )
            name = str(spec["name"])
            where = (*path, name)
            if name in out:
                raise self.fail(f"payload field {name!r} is given twice", child, where)
            self.lines.add(where, child.line)
            out[name] = self.value(child, where, str(spec.get("type", "str")))
        return out

    def value(self, node: _Node, path: tuple[str | int, ...], kind: str) -> JsonValue:
        text = self.leaf(node, path).strip()
        if kind not in FIELD_TYPES:
            raise self.fail(
                f"unknown field type {kind!r}",
                node,
                path,
                hint="field types: " + ", ".join(FIELD_TYPES),
            )
        if kind == "str":
            return text
        if kind == "int" and _INT.fullmatch(text):
            try:
                return int(text)
            except ValueError:  # over Python's 4300-digit limit
                raise self.fail("integer too long", node, path, hint="e.g. 42") from None
        if kind == "float" and _FLOAT.fullmatch(text):
            number = float(text)
            if math.isfinite(number):
                return number
        if kind == "bool" and text.lower() in ("true", "false"):
            return text.lower() == "true"
        if kind == "json":
            try:
                value: JsonValue = json.loads(text, parse_constant=_no_constant)
            except (ValueError, RecursionError) as exc:
                reason = exc.msg if isinstance(exc, json.JSONDecodeError) else str(exc)[:80]
                raise self.fail(
                    f"invalid JSON: {reason}", node, path, hint='e.g. [1, 2] or {"a": null}'
                ) from None
            return value
        raise self.fail(
            f"{text!r} is not a valid {kind}",
            node,
            path,
            hint={
                "int": "e.g. 42",
                "float": "a finite number, e.g. 0.5",
                "bool": "true or false",
            }[kind],
        )


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not allowed (payload numbers must be finite)")


def parse_tactics_xml(text: str, *, source: str | Path | None = None) -> TacticSet:
    """Parse the XML form of a tactics file (the paper's Fig. 10).

    Args:
        text: The document.
        source: The file it came from, for messages and ``source`` references.

    Raises:
        ModelFileError: hostile, malformed or invalid XML, naming file, line and element.

    """
    reader = _Reader(source)
    data = reader.read(_parse_tree(text, source))
    return build_tactic_set(data, reader.lines, source)


# --------------------------------------------------------------------------- writing


def _number(value: float) -> str:
    if value.is_integer() and abs(value) < 1e15:
        return str(int(value))
    return repr(value)


def _field(parent: ET.Element, name: str, value: JsonValue) -> None:
    element = ET.SubElement(parent, "field", name=name)
    if isinstance(value, bool):
        element.set("type", "bool")
        element.text = "true" if value else "false"
    elif isinstance(value, int):
        element.set("type", "int")
        element.text = str(value)
    elif isinstance(value, float):
        element.set("type", "float")
        element.text = repr(value)
    elif isinstance(value, str) and value == value.strip():
        element.text = value
    else:
        element.set("type", "json")
        element.text = json.dumps(value, ensure_ascii=False)


def _goal(parent: ET.Element, goal: GoalState) -> None:
    ET.SubElement(parent, "goal", id=goal.goal, state=goal.state)


def _tactic(parent: ET.Element, tactic: Tactic) -> None:
    element = ET.SubElement(parent, "tactic", name=tactic.name)
    if tactic.priority:
        element.set("priority", str(tactic.priority))
    if tactic.cooldown:
        element.set("cooldown", _number(tactic.cooldown))
    if tactic.requires_approval:
        element.set("requires_approval", "true")
    if tactic.description:
        ET.SubElement(element, "description").text = tactic.description
    pre = ET.SubElement(element, "preconditions")
    for cond in tactic.preconditions:
        if isinstance(cond, ExpressionCondition):
            ET.SubElement(pre, "expression").text = cond.expression
        else:
            _goal(pre, cond)
    actions = ET.SubElement(element, "actions")
    for action in tactic.actions:
        _action(actions, action)
    default_deadline = Tactic.model_fields["deadline"].default
    if tactic.postconditions or tactic.deadline != default_deadline:
        post = ET.SubElement(element, "postconditions", deadline=_number(tactic.deadline))
        for goal in tactic.postconditions:
            _goal(post, goal)
    if tactic.conflicts:
        conflicts = ET.SubElement(element, "conflicts")
        for name in tactic.conflicts:
            ET.SubElement(conflicts, "tactic", name=name)


def _attribute(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return _number(value)
    return str(value)


def _action(parent: ET.Element, action: TacticAction) -> None:
    """Write an action as its class says: the tag, the attributes set, payload, text."""
    cls = type(action)
    act = ET.SubElement(parent, action.type)
    for name in _attributes(cls):
        value = getattr(action, name)
        info = cls.model_fields[name]
        if value is not None and (info.is_required() or value != info.default):
            act.set(name, _attribute(value))
    if "payload" in cls.model_fields:
        payload: dict[str, JsonValue] = getattr(action, "payload", {})
        for name, value in payload.items():
            _field(act, name, value)
    if cls.XML_TEXT is not None:
        act.text = getattr(action, cls.XML_TEXT)


def dump_tactics_xml(tactic_set: TacticSet) -> str:
    """Write a tactic set in the XML form; :func:`parse_tactics_xml` reads it back equal."""
    root = ET.Element("tactics")
    if tactic_set.name is not None:
        root.set("name", tactic_set.name)
    for tactic in tactic_set.tactics:
        _tactic(root, tactic)
    ET.indent(root, space="  ")
    body = ET.tostring(root, encoding="unicode")
    return f'<?xml version="1.0" encoding="UTF-8"?>\n{body}\n'
