"""Utility expressions: a small, safe language parsed with a real grammar.

Goal models attach expressions such as ``A1.buzzer == true``, ``A4.category >= 1`` or
``rate(A3)`` to goals and obstacles. They are parsed with lark (LALR, grammar in
``expression.lark``) and compiled into a tree of Python closures — nothing ever reaches
``eval``. The closures read attribute values from a flat list of *slots* owned by the
evaluator; :meth:`Expression.bind` asks the evaluator for the slot of each attribute
reference, so one parse serves any number of evaluators.

Values are ``bool``, ``int``/``float`` or ``str``, and ``None`` for *unknown* (a missing or
stale input). Unknown propagates:

* ``and`` / ``or`` / ``not`` follow three-valued (Kleene) logic generalised to truth
  degrees in [0, 1]: ``and`` is the minimum, ``or`` the maximum, ``not x`` is ``1 - x``;
  an unknown operand leaves the result unknown unless a known operand decides it
  (``false and ?`` is false, ``true or ?`` is true);
* every other operator is unknown when an operand is unknown, and also on a type clash
  (``'a' < 3``) or a division by zero;
* ``A has x`` is unknown while agent ``A`` is silent or stale, otherwise true when its
  latest message carried ``x``.

Size and depth are bounded (:data:`MAX_LENGTH` characters, :data:`MAX_DEPTH` levels,
:data:`MAX_NODES` nodes) so that a hostile model cannot exhaust the parser or the stack.
"""

from __future__ import annotations

import math
import operator
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, Final, Literal

from lark import Lark, Token, Tree
from lark.exceptions import LarkError, UnexpectedCharacters, UnexpectedInput, UnexpectedToken

from anunnaki.errors import ExpressionError

__all__ = [
    "ABSENT",
    "MAX_DEPTH",
    "MAX_LENGTH",
    "MAX_NODES",
    "AttrRef",
    "Expression",
    "compile_expression",
    "to_utility",
    "truth",
]

MAX_LENGTH: Final = 2000
MAX_DEPTH: Final = 32
MAX_NODES: Final = 400

Value = bool | int | float | str | None
Slots = list[Any]
Fn = Callable[[Slots], Value]
ValueType = Literal["bool", "number", "string", "any"]


class _Absent:
    """Slot marker: the agent is fresh but its latest message lacked the field."""

    _instance: _Absent | None = None

    def __new__(cls) -> _Absent:
        if cls._instance is None:
            cls._instance = super().__new__(cls)
        return cls._instance

    def __repr__(self) -> str:
        return "ABSENT"


ABSENT: Final = _Absent()


@dataclass(frozen=True, order=True)
class AttrRef:
    """A reference ``agent.attribute`` read by an expression."""

    agent: str
    attribute: str

    def __str__(self) -> str:
        return f"{self.agent}.{self.attribute}"


def truth(value: Value) -> float | None:
    """Return the truth degree of ``value`` in [0, 1], or ``None`` when unknown.

    Booleans map to 0/1, numbers are clamped to [0, 1], strings have no truth (unknown).
    """
    if value is None or isinstance(value, str):
        return None
    if value is True:
        return 1.0
    if value is False:
        return 0.0
    try:
        v = float(value)
    except OverflowError:  # an integer too large for a float
        return 1.0 if value > 0 else 0.0
    if math.isnan(v):
        return None
    return 0.0 if v < 0.0 else 1.0 if v > 1.0 else v


to_utility = truth
"""Map an expression value to a utility: booleans to 0/1, numbers clamped to [0, 1]."""

_grammar_lock = threading.Lock()
_parser: Lark | None = None


def _get_parser() -> Lark:
    global _parser  # noqa: PLW0603 - one immutable parser per process, built lazily
    with _grammar_lock:
        if _parser is None:
            text = resources.files("anunnaki.goals").joinpath("expression.lark").read_text()
            _parser = Lark(text, parser="lalr", propagate_positions=True)
        return _parser


def _is_num(v: Any) -> bool:
    # Booleans are not numbers here: ``true + 1`` and ``true >= 1`` are type clashes.
    t = type(v)
    return t is int or t is float


def _eq(x: Any, y: Any) -> bool:
    """Equality that keeps booleans apart from numbers (``true == 1`` is false)."""
    if (type(x) is bool) != (type(y) is bool):
        return False
    return bool(x == y)


def _ne(x: Any, y: Any) -> bool:
    return not _eq(x, y)


_COMPARE: dict[str, Callable[[Any, Any], bool]] = {
    "==": _eq,
    "!=": _ne,
    "<": operator.lt,
    "<=": operator.le,
    ">": operator.gt,
    ">=": operator.ge,
}


def _arith_fn(op: str) -> Callable[[Any, Any], Value]:
    def add(a: Any, b: Any) -> Value:
        return a + b  # type: ignore[no-any-return]

    def sub(a: Any, b: Any) -> Value:
        return a - b  # type: ignore[no-any-return]

    def mul(a: Any, b: Any) -> Value:
        return a * b  # type: ignore[no-any-return]

    def div(a: Any, b: Any) -> Value:
        return None if b == 0 else a / b

    def mod(a: Any, b: Any) -> Value:
        return None if b == 0 else a % b

    return {"+": add, "-": sub, "*": mul, "/": div, "%": mod}[op]


class Expression:
    """A parsed, checked expression; :meth:`bind` turns it into a fast function.

    Attributes:
        text: The source text.
        refs: Every ``agent.attribute`` the expression reads (``has`` included).
        rated: Agents whose message rate ``rate(A)`` the expression reads.
        agents: Every agent named.
        value_type: The static type of the result, when it can be known.

    """

    __slots__ = ("_tree", "agents", "rated", "refs", "text", "value_type")

    def __init__(
        self,
        text: str,
        tree: Tree[Token],
        refs: frozenset[AttrRef],
        rated: frozenset[str],
        value_type: ValueType,
    ) -> None:
        self.text = text
        self._tree = tree
        self.refs = refs
        self.rated = rated
        self.agents = frozenset({r.agent for r in refs} | rated)
        self.value_type = value_type

    def __repr__(self) -> str:
        return f"Expression({self.text!r})"

    def bind(
        self,
        slot_of: Callable[[AttrRef], int],
        rate_slot_of: Callable[[str], int],
    ) -> Fn:
        """Compile to a function of the slot list.

        Args:
            slot_of: Gives the slot index of an attribute reference.
            rate_slot_of: Gives the slot index holding an agent's message rate (Hz).

        Returns:
            ``fn(slots) -> value``; ``None`` means unknown.

        """
        return _Compiler(slot_of, rate_slot_of).compile(self._tree)

    def evaluate(
        self,
        attributes: dict[str, Any],
        rates: dict[str, float] | None = None,
    ) -> Value:
        """Evaluate once against a mapping ``{"A1.mode": "manual", ...}`` (for tests, tools).

        A missing key is unknown; a value :data:`ABSENT` means the agent is fresh but the
        field was not in its latest message.
        """
        keys: list[str] = []
        slots: list[Any] = []

        def slot_of(ref: AttrRef) -> int:
            keys.append(str(ref))
            slots.append(attributes.get(str(ref)))
            return len(slots) - 1

        def rate_slot_of(agent: str) -> int:
            slots.append((rates or {}).get(agent))
            return len(slots) - 1

        return self.bind(slot_of, rate_slot_of)(slots)


class _Compiler:
    """Turns a checked parse tree into nested closures over the slot list."""

    def __init__(
        self, slot_of: Callable[[AttrRef], int], rate_slot_of: Callable[[str], int]
    ) -> None:
        self.slot_of = slot_of
        self.rate_slot_of = rate_slot_of

    def _compare_attr_literal(
        self,
        left: Tree[Token],
        right: Tree[Token],
        op: Callable[[Any, Any], bool],
        equality: bool,
    ) -> Fn:
        i = self.slot_of(AttrRef(str(left.children[0]), str(left.children[1])))
        lit = self.compile(right)([])
        absent = ABSENT
        if equality:

            def cmp_eq(s: Slots) -> Value:
                x = s[i]
                if x is None or x is absent:
                    return None
                return op(x, lit)

            return cmp_eq
        numeric = _is_num(lit)
        lit_type = type(lit)

        def cmp_lit(s: Slots) -> Value:
            x = s[i]
            if x is None or x is absent:
                return None
            tx = type(x)
            if (numeric and (tx is int or tx is float)) or tx is lit_type:
                return op(x, lit)
            return None

        return cmp_lit

    def compile(self, node: Tree[Token] | Token) -> Fn:
        if isinstance(node, Token):  # pragma: no cover - grammar never yields bare tokens
            raise AssertionError(node)
        rule = node.data
        kids = node.children
        if rule in _LITERALS:
            return _literal(rule, kids)
        if rule in ("attr", "has", "has_no", "rate"):
            return self._compile_read(rule, kids)
        if rule in ("neg", "not_", "and_", "or_"):
            return self._compile_logic(rule, kids)
        if rule == "compare":
            return self._compile_compare(kids)
        if rule in ("in_", "not_in"):
            return self._compile_member(rule, kids)
        if rule == "arith":
            return self._compile_arith(kids)
        if rule == "call":
            name = str(kids[0])
            fs = [self.compile(k) for k in kids[1:]]
            return _call_fn(name, fs)
        raise AssertionError(f"unhandled rule {rule}")  # pragma: no cover

    def _compile_read(self, rule: str, kids: list[Tree[Token] | Token]) -> Fn:
        """An attribute's value, whether it is present, or a topic's rate."""
        if rule == "rate":
            r = self.rate_slot_of(str(kids[0]))
            return lambda s: s[r]
        i = self.slot_of(AttrRef(str(kids[0]), str(kids[1])))
        if rule == "attr":

            def read(s: Slots) -> Value:
                v = s[i]
                return None if v is ABSENT else v

            return read
        want = rule == "has"

        def has(s: Slots) -> Value:
            v = s[i]
            if v is None:
                return None
            return (v is not ABSENT) == want

        return has

    def _compile_logic(self, rule: str, kids: list[Tree[Token] | Token]) -> Fn:
        """Negation, ``not`` and the Kleene ``and``/``or``."""
        if rule in ("and_", "or_"):
            fs = [self.compile(k) for k in kids]
            return _and_fn(fs) if rule == "and_" else _or_fn(fs)
        f = self.compile(kids[0])
        if rule == "neg":

            def neg_fn(s: Slots) -> Value:
                v = f(s)
                return -v if isinstance(v, int | float) else None

            return neg_fn

        def not_fn(s: Slots) -> Value:
            v = f(s)
            if v is True or v is False:
                return not v
            t = truth(v)
            return None if t is None else 1.0 - t

        return not_fn

    def _compile_compare(self, kids: list[Tree[Token] | Token]) -> Fn:
        op = _COMPARE[str(kids[1])]
        equality = str(kids[1]) in ("==", "!=")
        left, right = kids[0], kids[2]
        if (
            isinstance(left, Tree)
            and left.data == "attr"
            and isinstance(right, Tree)
            and right.data in _LITERALS
        ):
            # The common case, ``A.x >= 0.5``: one slot read against a literal.
            return self._compare_attr_literal(left, right, op, equality)
        a = self.compile(left)
        b = self.compile(right)

        def cmp(s: Slots) -> Value:
            x = a(s)
            if x is None:
                return None
            y = b(s)
            if y is None:
                return None
            if equality or (_is_num(x) and _is_num(y)) or (type(x) is type(y)):
                return op(x, y)
            return None  # a type clash: unknown

        return cmp

    def _compile_member(self, rule: str, kids: list[Tree[Token] | Token]) -> Fn:
        f = self.compile(kids[0])
        lst = kids[1]
        assert isinstance(lst, Tree)
        items = tuple(self.compile(k)([]) for k in lst.children if k is not None)
        want_in = rule == "in_"

        def member(s: Slots) -> Value:
            v = f(s)
            if v is None:
                return None
            return any(_eq(v, item) for item in items) == want_in

        return member

    def _compile_arith(self, kids: list[Tree[Token] | Token]) -> Fn:
        a = self.compile(kids[0])
        b = self.compile(kids[2])
        fn = _arith_fn(str(kids[1]))

        def arith(s: Slots) -> Value:
            x = a(s)
            y = b(s)
            if _is_num(x) and _is_num(y):
                r = fn(x, y)
                return None if r is None or (isinstance(r, float) and not math.isfinite(r)) else r
            return None

        return arith


_LITERALS: Final = frozenset({"number", "neg_number", "string", "true", "false"})


def _literal(rule: str, kids: list[Tree[Token] | Token]) -> Fn:
    """A constant: a number, a string or a boolean."""
    if rule == "number":
        num = _number(kids[0])
        return lambda s: num
    if rule == "neg_number":
        neg = -_number(kids[0])
        return lambda s: neg
    if rule == "string":
        text = str(kids[0])[1:-1]
        return lambda s: text
    if rule == "true":
        return lambda s: True
    return lambda s: False


def _and_fn(fs: Sequence[Fn]) -> Fn:
    def and_fn(s: Slots) -> Value:
        lo = 1.0
        unknown = False
        all_bool = True
        for f in fs:
            v = f(s)
            if v is False:
                return False
            if v is not True:
                all_bool = False
                t = truth(v)
                if t is None:
                    unknown = True
                elif t < lo:
                    lo = t
        if lo == 0.0:
            return 0.0
        if unknown:
            return None
        return True if all_bool else lo

    return and_fn


def _or_fn(fs: Sequence[Fn]) -> Fn:
    def or_fn(s: Slots) -> Value:
        hi = 0.0
        unknown = False
        all_bool = True
        for f in fs:
            v = f(s)
            if v is True:
                return True
            if v is not False:
                all_bool = False
                t = truth(v)
                if t is None:
                    unknown = True
                elif t > hi:
                    hi = t
        if hi == 1.0:
            return 1.0
        if unknown:
            return None
        return False if all_bool else hi

    return or_fn


def _call_fn(name: str, fs: Sequence[Fn]) -> Fn:
    if name == "abs":
        (f,) = fs

        def abs_fn(s: Slots) -> Value:
            v = f(s)
            return abs(v) if isinstance(v, int | float) else None

        return abs_fn
    pick = min if name == "min" else max

    def minmax(s: Slots) -> Value:
        vals = [f(s) for f in fs]
        if all(_is_num(v) for v in vals):
            return pick(vals)  # type: ignore[type-var]
        return None

    return minmax


def _number(tok: Token | Tree[Token]) -> int | float:
    text = str(tok)
    try:
        return int(text)
    except ValueError:
        return float(text)


class _Checker:
    """Walks a parse tree once: bounds, references, arities and static types."""

    def __init__(self, text: str, where: dict[str, Any]) -> None:
        self.text = text
        self.where = where
        self.refs: set[AttrRef] = set()
        self.rated: set[str] = set()
        self.nodes = 0

    def fail(self, message: str, hint: str | None = None) -> ExpressionError:
        return ExpressionError(f"{message} in expression '{self.text}'", hint=hint, **self.where)

    def check(self, node: Tree[Token], depth: int = 0) -> ValueType:
        self.nodes += 1
        if depth > MAX_DEPTH or self.nodes > MAX_NODES:
            raise self.fail(
                f"expression deeper than {MAX_DEPTH} levels or larger than {MAX_NODES} nodes",
                "split it into several goals",
            )
        rule = node.data
        kids = node.children
        sub = [k for k in kids if isinstance(k, Tree)]
        types = [self.check(k, depth + 1) for k in sub if k.data != "list"]
        if rule in _LEAF_TYPES:
            if rule in ("number", "neg_number"):
                self._check_number(kids[0])
            return _LEAF_TYPES[rule]
        if rule in ("attr", "has", "has_no"):
            self.refs.add(AttrRef(str(kids[0]), str(kids[1])))
            return "any" if rule == "attr" else "bool"
        if rule == "rate":
            self.rated.add(str(kids[0]))
            return "number"
        vtype = self._check_operator(rule, kids, types)
        if rule in ("arith", "neg", "call") and _constant(node):
            self._check_constant(node)
        elif rule == "arith" and str(kids[1]) in ("/", "%") and _constant(sub[-1]):
            self._check_divisor(str(kids[1]), sub[-1])
        return vtype

    def _check_number(self, token: Token | Tree[Token]) -> None:
        value, text = _number(token), str(token)
        if not math.isfinite(value) or abs(value) > _MAX_NUMBER:
            raise self.fail(
                f"number {text[:20]}{'…' if len(text) > 20 else ''} is out of range",
                f"numbers in expressions lie within ±{_MAX_NUMBER:.0e}",
            )

    def _check_constant(self, node: Tree[Token]) -> None:
        """A part without references is computed now: one that is always unknown is a bug."""
        try:
            value = _Compiler(lambda ref: 0, lambda agent: 0).compile(node)([])
        except (ArithmeticError, ValueError):
            value = None
        if value is None:
            part = self.text[node.meta.start_pos : node.meta.end_pos] if not node.meta.empty else ""
            raise self.fail(
                f"'{part or node.data}' is always unknown (a division by zero or a result "
                "beyond the number range)",
                "fix the constant; an expression that can never be known never satisfies its goal",
            )

    def _check_divisor(self, op: str, divisor: Tree[Token]) -> None:
        if _Compiler(lambda ref: 0, lambda agent: 0).compile(divisor)([]) == 0:
            raise self.fail(
                f"'{op} 0' is always unknown (a division by zero)",
                "fix the divisor; an expression that can never be known never satisfies its goal",
            )

    def _check_operator(
        self, rule: str, kids: list[Tree[Token] | Token], types: list[ValueType]
    ) -> ValueType:
        """The type of an operator's result from its operands' types (or a refusal)."""
        if rule in ("neg", "arith"):
            if "string" in types or "bool" in types:
                raise self.fail(
                    "arithmetic on a string or boolean", "arithmetic takes numbers only"
                )
            return "number"
        if rule in ("not_", "and_", "or_"):
            if "string" in types:
                raise self.fail(
                    "'and', 'or' and 'not' take booleans or numbers in [0, 1], not strings",
                    "compare the string first, e.g. A1.mode == 'manual'",
                )
            return "bool" if all(t == "bool" for t in types) else "any"
        if rule == "compare":
            op = str(kids[1])
            a, b = types
            if op not in ("==", "!=") and "any" not in (a, b) and a != b:
                raise self.fail(f"'{op}' compares a {a} with a {b}")
            return "bool"
        if rule in ("in_", "not_in"):
            return "bool"
        if rule == "call":
            name = str(kids[0])
            if name == "abs" and len(types) != 1:
                raise self.fail("abs() takes exactly one argument")
            if "string" in types or "bool" in types:
                raise self.fail(f"{name}() takes numbers only")
            return "number"
        raise AssertionError(f"unhandled rule {rule}")  # pragma: no cover


#: The largest magnitude of a number in an expression (an IEEE double's range, with margin).
_MAX_NUMBER: Final = 1e300

#: Rules whose value depends on the run (a subtree without them is a constant).
_READS: Final = frozenset({"attr", "has", "has_no", "rate"})


def _constant(node: Tree[Token]) -> bool:
    return not any(t.data in _READS for t in node.iter_subtrees())


#: The type of each literal rule.
_LEAF_TYPES: Final[dict[str, ValueType]] = {
    "number": "number",
    "neg_number": "number",
    "string": "string",
    "true": "bool",
    "false": "bool",
}


def compile_expression(
    text: str,
    *,
    path: str | Path | None = None,
    line: int | None = None,
    element: str | None = None,
) -> Expression:
    """Parse and check a utility expression.

    Args:
        text: The expression, e.g. ``"A4.category >= 1"``.
        path: File the expression comes from (for error messages).
        line: Line of the element in that file.
        element: The element, e.g. ``goals[G14].utility``.

    Raises:
        ExpressionError: a syntax error (with the column), an expression over the size or
            depth bounds, or a static type clash.

    """
    where: dict[str, Any] = {"path": path, "line": line, "element": element}
    if not isinstance(text, str) or not text.strip():
        raise ExpressionError("empty expression", hint="write e.g. A1.buzzer == true", **where)
    if len(text) > MAX_LENGTH:
        raise ExpressionError(
            f"expression longer than {MAX_LENGTH} characters",
            hint="split it into several goals",
            **where,
        )
    if text.count("(") + text.count("[") > MAX_DEPTH:
        raise ExpressionError(
            f"more than {MAX_DEPTH} brackets", hint="split it into several goals", **where
        )
    try:
        tree = _get_parser().parse(text)
    except UnexpectedInput as exc:
        col = getattr(exc, "column", None)
        if isinstance(exc, UnexpectedToken):
            at_end = exc.token.type == "$END"
            got = "end of expression" if at_end else f"'{exc.token}'"
            msg = f"unexpected {got}"
            if at_end:
                col = len(text.rstrip()) + 1
        elif isinstance(exc, UnexpectedCharacters):
            pos = exc.pos_in_stream if exc.pos_in_stream is not None else 0
            msg = f"unexpected character '{text[pos]}'"
        else:  # pragma: no cover - UnexpectedEOF with LALR
            msg = "unexpected end of expression"
        pointer = f"{text}\n{' ' * ((col or 1) - 1)}^"
        raise ExpressionError(
            f"syntax error at column {col}: {msg}\n{pointer}",
            hint=(
                "expressions look like  A1.mode == 'manual' and not (A4.category >= 1); "
                "see docs/goal-models.md"
            ),
            **where,
        ) from None
    except LarkError as exc:  # pragma: no cover - defensive
        raise ExpressionError(f"cannot parse expression: {exc}", **where) from None
    checker = _Checker(text, where)
    vtype = checker.check(tree)
    return Expression(text, tree, frozenset(checker.refs), frozenset(checker.rated), vtype)
