"""The one trace format: timestamped messages per topic, one JSON object per line (JSONL).

A trace records what a managed system published. ``anunnaki evaluate`` replays one against
a goal model, the scripted managed system publishes one onto the bus, and the decision log
exports its recorded inputs as one — so a run can always be turned back into a trace and
replayed. The format (version ``trace/1``)::

    {"anunnaki": "trace/1", "name": "rover-dim-light", "description": "…"}
    {"t": 0.0, "topic": "/rover/status", "msg": {"mode": "autonomous", "buzzer": false}}
    {"t": 0.1, "topic": "/rover/ultrasonic", "msg": {"range": 3.0}}
    {"t": 10.0, "phase": "degraded", "note": "light dims; the oracle reports category 1"}

* The first line may be a header (``"anunnaki": "trace/1"`` plus free metadata); at most one.
* A message record has ``t`` (seconds, any origin; non-decreasing through the file),
  ``topic`` (ROS-style name, starting with ``/``) and ``msg`` (a JSON object).
* A phase record has ``t`` and ``phase`` (a label) and an optional ``note`` (text): it marks
  where a scripted condition begins, for people reading the output; it carries no data.
* Blank lines are ignored; a UTF-8 byte-order mark before the first line is skipped. Numbers
  are finite (no ``NaN``/``Infinity``) and a key appears once per object. Images are never
  stored in traces (guideline P1): a camera topic's record carries its metadata (sequence
  number, size), not pixels.

The reader refuses a bad line with a :class:`~anunnaki.errors.ModelFileError` naming file and
line; the writer refuses (``ValueError``) to write what the reader would refuse, so whatever
:class:`TraceWriter` writes reads back equal. See docs/traces.md.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from anunnaki._closing import Closing
from anunnaki.errors import ModelFileError

__all__ = [
    "FORMAT",
    "Phase",
    "Record",
    "Trace",
    "TraceWriter",
    "iter_trace",
    "read_trace",
    "write_trace",
]

FORMAT = "trace/1"
MAX_LINE = 1_000_000
"""Longest line accepted, in bytes (characters when reading a text stream)."""

TOPIC = re.compile(r"(/[A-Za-z0-9_]+)+")
"""A ROS-style topic name, as in goal models and bindings: ``/utu/oracle/output``."""


@dataclass(frozen=True)
class Record:
    """One message: at time ``t`` (s), ``msg`` was published on ``topic``."""

    t: float
    topic: str
    msg: dict[str, Any]
    line: int | None = field(default=None, compare=False)

    def to_json(self) -> str:
        """One JSONL line (without the newline), keys sorted at every level.

        Raises:
            ValueError: the record holds a non-finite number (JSON has no NaN or infinity).

        """
        return _dumps({"t": float(self.t), "topic": self.topic, "msg": self.msg}, self)


@dataclass(frozen=True)
class Phase:
    """A labelled moment in a trace, e.g. where a scripted condition begins."""

    t: float
    phase: str
    note: str = ""
    line: int | None = field(default=None, compare=False)

    def to_json(self) -> str:
        """One JSONL line (without the newline)."""
        out: dict[str, Any] = {"t": float(self.t), "phase": self.phase}
        if self.note:
            out["note"] = self.note
        return _dumps(out, self)


def _dumps(obj: Mapping[str, Any], what: object) -> str:
    try:
        return json.dumps(obj, sort_keys=True, allow_nan=False)
    except ValueError:
        name = what if isinstance(what, str) else repr(what)
        raise ValueError(
            f"cannot write {name}: a trace holds finite numbers only (JSON has no NaN or "
            "infinity); replace the value, e.g. by null"
        ) from None


@dataclass
class Trace:
    """A whole trace held in memory."""

    header: dict[str, Any]
    items: list[Record | Phase]

    @property
    def records(self) -> list[Record]:
        """The message records, in order."""
        return [r for r in self.items if isinstance(r, Record)]

    @property
    def phases(self) -> list[Phase]:
        """The phase markers, in order."""
        return [r for r in self.items if isinstance(r, Phase)]


def _fail(path: str, line: int, message: str, hint: str | None = None) -> ModelFileError:
    return ModelFileError(message, path=path, line=line, element="trace record", hint=hint)


def _finite(obj: Any) -> bool:
    if isinstance(obj, float):
        return math.isfinite(obj)
    if isinstance(obj, dict):
        return all(_finite(v) for v in obj.values())
    if isinstance(obj, list):
        return all(_finite(v) for v in obj)
    return True


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not valid JSON")


class _DuplicateKeyError(ValueError):
    pass


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out = dict(pairs)
    if len(out) != len(pairs):
        seen: set[str] = set()
        for key, _ in pairs:
            if key in seen:
                raise _DuplicateKeyError(key)
            seen.add(key)
    return out


def _parse_line(text: str, path: str, lineno: int) -> dict[str, Any]:
    try:
        obj = json.loads(text, parse_constant=_reject_constant, object_pairs_hook=_unique_keys)
    except _DuplicateKeyError as exc:
        raise _fail(
            path, lineno, f"duplicate key '{exc}'", "each key may appear once in an object"
        ) from None
    except (json.JSONDecodeError, ValueError) as exc:
        raise _fail(
            path, lineno, f"not valid JSON: {exc}", "each line is one JSON object"
        ) from None
    except RecursionError:
        raise _fail(path, lineno, "JSON nested too deeply") from None
    if not isinstance(obj, dict):
        raise _fail(path, lineno, "a trace line must be a JSON object")
    return obj


def _file_lines(fh: IO[bytes], path: str) -> Iterator[tuple[int, str]]:
    """Numbered lines of a file, each decoded on its own so a bad byte names its line."""
    lineno = 0
    while True:
        raw = fh.readline(MAX_LINE + 1)
        if not raw:
            return
        lineno += 1
        if len(raw) > MAX_LINE:
            raise _fail(path, lineno, f"line longer than {MAX_LINE} bytes")
        if lineno == 1 and raw.startswith(b"\xef\xbb\xbf"):
            raw = raw[3:]  # a UTF-8 byte-order mark
        try:
            yield lineno, raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise ModelFileError(
                f"not UTF-8 text (byte 0x{raw[exc.start]:02x} at column {exc.start + 1})",
                path=path,
                line=lineno,
                hint="save the trace as UTF-8",
            ) from None


def _stream_lines(fh: IO[str], path: str) -> Iterator[tuple[int, str]]:
    for lineno, text in enumerate(fh, start=1):
        if len(text) > MAX_LINE:
            raise _fail(path, lineno, f"line longer than {MAX_LINE} characters")
        yield lineno, text.lstrip("\ufeff") if lineno == 1 else text


def iter_trace(source: str | Path | IO[str]) -> Iterator[dict[str, Any] | Record | Phase]:
    """Stream a trace: yields the header (a dict) first if present, then records and phases.

    Args:
        source: A path, or an open text stream (``io.StringIO``, ``sys.stdin``).

    Raises:
        ModelFileError: a malformed line, naming the file and line and what to fix.

    """
    fh: IO[bytes] | IO[str]
    if isinstance(source, str | Path):
        path = str(source)
        try:
            fh = open(source, "rb")  # noqa: SIM115 - closed below
        except OSError as exc:
            raise ModelFileError(
                f"cannot read trace: {exc.strerror}", path=path, hint="check the path"
            ) from exc
        lines = _file_lines(fh, path)
        close = True
    else:
        path = str(getattr(source, "name", "<trace>"))
        fh = source
        lines = _stream_lines(source, path)
        close = False
    try:
        last_t = -math.inf
        header_line: int | None = None
        started = False
        for lineno, raw in lines:
            text = raw.strip()
            if not text:
                continue
            obj = _parse_line(text, path, lineno)
            if "anunnaki" in obj:
                if obj["anunnaki"] != FORMAT:
                    raise _fail(
                        path,
                        lineno,
                        f"unsupported trace format {obj['anunnaki']!r}",
                        f"this version reads '{FORMAT}'",
                    )
                if header_line is not None:
                    raise _fail(
                        path,
                        lineno,
                        f"a second header (the first is on line {header_line})",
                        "a trace has at most one header",
                    )
                if started:
                    raise _fail(path, lineno, "the header must be the first line")
                header_line = lineno
                yield obj
                continue
            item = _record(obj, path, lineno, last_t)
            started = True
            last_t = item.t
            yield item
    except UnicodeDecodeError as exc:  # a text stream that was not opened as UTF-8
        raise ModelFileError(
            f"not UTF-8 text ({exc.reason})", path=path, hint="save the trace as UTF-8"
        ) from None
    finally:
        if close:
            fh.close()


def _record(obj: dict[str, Any], path: str, lineno: int, last_t: float) -> Record | Phase:
    t = obj.get("t")
    if isinstance(t, bool) or not isinstance(t, int | float) or not math.isfinite(t):
        raise _fail(path, lineno, "'t' must be a finite number of seconds", 'e.g. "t": 1.25')
    if t < last_t:
        raise _fail(
            path,
            lineno,
            f"time goes backwards ({t} after {last_t})",
            "sort the records by 't'",
        )
    if "phase" in obj:
        extra = set(obj) - {"t", "phase", "note"}
        label, note = obj["phase"], obj.get("note", "")
        if extra or not isinstance(label, str) or not label or not isinstance(note, str):
            raise _fail(
                path,
                lineno,
                "a phase record has 't', 'phase' (a non-empty label) and 'note' (text) only",
                '{"t": 10.0, "phase": "dim-light", "note": "the light dims"}',
            )
        return Phase(float(t), label, note, lineno)
    extra = set(obj) - {"t", "topic", "msg"}
    if extra:
        raise _fail(
            path,
            lineno,
            f"unknown key(s) {', '.join(sorted(extra))}",
            "a record has 't', 'topic' and 'msg'",
        )
    topic = obj.get("topic")
    if not isinstance(topic, str) or not TOPIC.fullmatch(topic):
        raise _fail(
            path,
            lineno,
            f"'topic' must be a ROS-style name starting with '/', got {topic!r}",
            "letters, digits and '_' in '/'-separated parts, e.g. \"/rover/status\"",
        )
    msg = obj.get("msg")
    if not isinstance(msg, dict):
        raise _fail(path, lineno, "'msg' must be a JSON object", '"msg": {"range": 2.5}')
    if not _finite(msg):
        raise _fail(path, lineno, "'msg' holds a non-finite number")
    return Record(float(t), topic, msg, lineno)


def read_trace(source: str | Path | IO[str]) -> Trace:
    """Read a whole trace into memory (see :func:`iter_trace`)."""
    header: dict[str, Any] = {}
    items: list[Record | Phase] = []
    for item in iter_trace(source):
        if isinstance(item, dict):
            header = item
        else:
            items.append(item)
    return Trace(header, items)


class TraceWriter(Closing):
    """Write a trace file, header first; a context manager.

    Every item is checked as the reader checks it — ``t`` finite and not going backwards,
    ``topic`` a ROS-style name, ``msg`` a mapping of finite JSON values, a phase a non-empty
    label — and refused with ``ValueError`` before anything is written.

    Args:
        path: The file to (over)write.
        header: Free metadata (``name``, ``description``, …); ``anunnaki: trace/1`` is added.

    """

    def __init__(self, path: str | Path, header: Mapping[str, Any] | None = None) -> None:
        head = _dumps({**(header or {}), "anunnaki": FORMAT}, "the header")
        self._last_t = -math.inf
        self._fh = open(path, "w", encoding="utf-8")  # noqa: SIM115 - closed in close()
        self._fh.write(head + "\n")

    def write(self, item: Record | Phase) -> None:
        """Write one record or phase marker.

        Raises:
            ValueError: the item would not read back (see the class docstring).

        """
        t = item.t
        if isinstance(t, bool) or not isinstance(t, int | float) or not math.isfinite(t):
            raise ValueError(f"cannot write {item!r}: 't' must be a finite number of seconds")
        if t < self._last_t:
            raise ValueError(
                f"cannot write {item!r}: time goes backwards ({t} after {self._last_t})"
            )
        if isinstance(item, Record):
            if not isinstance(item.topic, str) or not TOPIC.fullmatch(item.topic):
                raise ValueError(
                    f"cannot write {item!r}: {item.topic!r} is not a ROS-style topic name "
                    "such as /rover/status"
                )
            if not isinstance(item.msg, Mapping):
                raise ValueError(f"cannot write {item!r}: 'msg' must be a mapping")
        elif not isinstance(item.phase, str) or not item.phase or not isinstance(item.note, str):
            raise ValueError(f"cannot write {item!r}: a phase needs a non-empty label")
        line = item.to_json()
        self._last_t = t
        self._fh.write(line + "\n")

    def message(self, t: float, topic: str, msg: Mapping[str, Any]) -> None:
        """Write one message record."""
        self.write(Record(t, topic, dict(msg)))

    def close(self) -> None:
        """Flush and close the file."""
        self._fh.close()


def write_trace(
    path: str | Path, items: Iterable[Record | Phase], header: Mapping[str, Any] | None = None
) -> None:
    """Write a whole trace."""
    with TraceWriter(path, header) as w:
        for item in items:
            w.write(item)
