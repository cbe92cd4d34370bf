"""The one trace format: timestamped messages per topic, one JSON object per line (JSONL).

A trace records what a managed system published. ``anunnaki evaluate`` replays one against
a goal model, the scripted managed system publishes one onto the bus, and the decision log
exports its recorded inputs as one — so a run can always be turned back into a trace and
replayed. The format (version ``trace/1``)::

    {"anunnaki": "trace/1", "name": "rover-dim-light", "description": "…"}
    {"t": 0.0, "topic": "/rover/status", "msg": {"mode": "autonomous", "buzzer": false}}
    {"t": 0.1, "topic": "/rover/ultrasonic", "msg": {"range": 3.0}}
    {"t": 10.0, "phase": "degraded", "note": "light dims; the oracle reports category 1"}

* The first line may be a header (``"anunnaki": "trace/1"`` plus free metadata).
* A message record has ``t`` (seconds, any origin; non-decreasing through the file),
  ``topic`` (ROS-style name, starting with ``/``) and ``msg`` (a JSON object).
* A phase record has ``t`` and ``phase`` (a label) and an optional ``note``: it marks where a
  scripted condition begins, for people reading the output; it carries no data.
* Blank lines are ignored. Images are never stored in traces (guideline P1): a camera
  topic's record carries its metadata (sequence number, size), not pixels.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

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


@dataclass(frozen=True)
class Record:
    """One message: at time ``t`` (s), ``msg`` was published on ``topic``."""

    t: float
    topic: str
    msg: dict[str, Any]
    line: int | None = field(default=None, compare=False)

    def to_json(self) -> str:
        """One JSONL line (without the newline)."""
        return json.dumps({"t": self.t, "topic": self.topic, "msg": self.msg}, sort_keys=True)


@dataclass(frozen=True)
class Phase:
    """A labelled moment in a trace, e.g. where a scripted condition begins."""

    t: float
    phase: str
    note: str = ""
    line: int | None = field(default=None, compare=False)

    def to_json(self) -> str:
        """One JSONL line (without the newline)."""
        out: dict[str, Any] = {"t": self.t, "phase": self.phase}
        if self.note:
            out["note"] = self.note
        return json.dumps(out, sort_keys=True)


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


def _parse_line(text: str, path: str, lineno: int) -> dict[str, Any]:
    if len(text) > MAX_LINE:
        raise _fail(path, lineno, f"line longer than {MAX_LINE} characters")
    try:
        obj = json.loads(text, parse_constant=_reject_constant)
    except (json.JSONDecodeError, ValueError) as exc:
        raise _fail(
            path, lineno, f"not valid JSON: {exc}", "each line is one JSON object"
        ) from None
    except RecursionError:
        raise _fail(path, lineno, "JSON nested too deeply") from None
    if not isinstance(obj, dict):
        raise _fail(path, lineno, "a trace line must be a JSON object")
    return obj


def iter_trace(source: str | Path | IO[str]) -> Iterator[dict[str, Any] | Record | Phase]:
    """Stream a trace: yields the header (a dict) first if present, then records and phases.

    Raises:
        ModelFileError: a malformed line, naming the file and line and what to fix.

    """
    if isinstance(source, str | Path):
        path = str(source)
        try:
            fh: IO[str] = open(source, encoding="utf-8")  # noqa: SIM115 - closed below
        except OSError as exc:
            raise ModelFileError(f"cannot read trace: {exc.strerror}", path=path) from exc
        close = True
    else:
        path = getattr(source, "name", "<trace>")
        fh = source
        close = False
    try:
        last_t = -math.inf
        for lineno, raw in enumerate(fh, start=1):
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
                if lineno != 1 and last_t != -math.inf:
                    raise _fail(path, lineno, "the header must be the first line")
                yield obj
                continue
            yield _record(obj, path, lineno, last_t)
            last_t = float(obj["t"])
    except UnicodeDecodeError as exc:
        raise ModelFileError(
            f"not UTF-8 text (byte {exc.start})", path=path, hint="save the trace as UTF-8"
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
        if extra or not isinstance(obj["phase"], str):
            raise _fail(path, lineno, "a phase record has 't', 'phase' (text) and 'note' only")
        return Phase(float(t), obj["phase"], str(obj.get("note", "")), lineno)
    extra = set(obj) - {"t", "topic", "msg"}
    if extra:
        raise _fail(
            path,
            lineno,
            f"unknown key(s) {', '.join(sorted(extra))}",
            "a record has 't', 'topic' and 'msg'",
        )
    topic = obj.get("topic")
    if not isinstance(topic, str) or not topic.startswith("/"):
        raise _fail(
            path, lineno, "'topic' must be a ROS-style name starting with '/'", '"/rover/status"'
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


class TraceWriter:
    """Append records to a trace file; a context manager."""

    def __init__(self, path: str | Path, header: Mapping[str, Any] | None = None) -> None:
        self._fh = open(path, "w", encoding="utf-8")  # noqa: SIM115 - closed in close()
        head = {"anunnaki": FORMAT, **(header or {})}
        self._fh.write(json.dumps(head, sort_keys=True) + "\n")

    def write(self, item: Record | Phase) -> None:
        """Write one record or phase marker."""
        self._fh.write(item.to_json() + "\n")

    def message(self, t: float, topic: str, msg: Mapping[str, Any]) -> None:
        """Write one message record."""
        self.write(Record(t, topic, dict(msg)))

    def close(self) -> None:
        """Flush and close the file."""
        self._fh.close()

    def __enter__(self) -> TraceWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_trace(
    path: str | Path, items: Iterable[Record | Phase], header: Mapping[str, Any] | None = None
) -> None:
    """Write a whole trace."""
    with TraceWriter(path, header) as w:
        for item in items:
            w.write(item)
