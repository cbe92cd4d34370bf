"""The JSONL trace format: writing, reading, streaming, and every line it refuses."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest

from anunnaki.errors import ModelFileError
from anunnaki.trace import (
    FORMAT,
    Phase,
    Record,
    Trace,
    TraceWriter,
    iter_trace,
    read_trace,
    write_trace,
)

ROVER_TRACE = Path(__file__).parents[1] / "examples" / "rover" / "trace.jsonl"

ITEMS: list[Record | Phase] = [
    Phase(0.0, "nominal", "all sensors nominal"),
    Record(0.0, "/rover/status", {"mode": "autonomous", "buzzer": False}),
    Record(0.1, "/rover/ultrasonic", {"range": 3.0}),
    Record(0.1, "/camera/image_info", {"header": {"seq": 1, "frame": "cam"}, "size": [128, 96]}),
    Phase(10.0, "dim-light"),
    Record(10.0, "/utu/oracle/output", {"category": 1, "confidence": 0.9, "context": None}),
    Record(12, "/rover/status", {"mode": "manual", "note": "naïve ünïcode ✓"}),
]


def parse(text: str) -> Trace:
    return read_trace(io.StringIO(text))


def refused(text: str) -> ModelFileError:
    with pytest.raises(ModelFileError) as info:
        parse(text)
    return info.value


# -- round trip -------------------------------------------------------------------------


def test_write_then_read_gives_the_same_items(tmp_path: Path) -> None:
    path = tmp_path / "t.jsonl"
    write_trace(path, ITEMS, {"name": "rt", "description": "round trip", "seed": 7})
    trace = read_trace(path)
    assert trace.items == ITEMS
    assert trace.header == {
        "anunnaki": FORMAT,
        "name": "rt",
        "description": "round trip",
        "seed": 7,
    }
    assert trace.records == [x for x in ITEMS if isinstance(x, Record)]
    assert trace.phases == [x for x in ITEMS if isinstance(x, Phase)]
    # the line each item came from is kept, and takes no part in equality
    assert [x.line for x in trace.items] == list(range(2, 2 + len(ITEMS)))
    # writing what was read gives the same bytes
    again = tmp_path / "again.jsonl"
    write_trace(again, trace.items, trace.header)
    assert again.read_bytes() == path.read_bytes()


def test_the_rover_example_reads_and_writes_back_byte_for_byte(tmp_path: Path) -> None:
    trace = read_trace(ROVER_TRACE)
    assert trace.header["name"] == "rover-phases"
    assert len(trace.records) == 718
    assert [p.phase for p in trace.phases] == [
        "nominal",
        "ultrasonic-4.8Hz",
        "pedestrian-near",
        "dim-light",
        "manual",
        "ultrasonic-silent",
    ]
    out = tmp_path / "copy.jsonl"
    write_trace(out, trace.items, trace.header)
    assert out.read_text() == ROVER_TRACE.read_text()


def test_record_to_json_sorts_keys_at_every_level() -> None:
    a = Record(1.5, "/a", {"z": 1, "a": {"y": 2, "b": [3, {"d": 4, "c": 5}]}})
    b = Record(1.5, "/a", {"a": {"b": [3, {"c": 5, "d": 4}], "y": 2}, "z": 1})
    assert a.to_json() == b.to_json()
    assert a.to_json() == (
        '{"msg": {"a": {"b": [3, {"c": 5, "d": 4}], "y": 2}, "z": 1}, "t": 1.5, "topic": "/a"}'
    )
    assert Phase(2.0, "p").to_json() == '{"phase": "p", "t": 2.0}'  # no empty note
    assert Phase(2.0, "p", "n").to_json() == '{"note": "n", "phase": "p", "t": 2.0}'


@pytest.mark.parametrize(
    "item",
    [
        Record(0.0, "/a", {"x": float("nan")}),
        Record(0.0, "/a", {"x": [1.0, float("inf")]}),
        Record(float("inf"), "/a", {}),
        Phase(float("nan"), "p"),
    ],
    ids=["nan-in-msg", "inf-in-list", "inf-time", "nan-phase-time"],
)
def test_non_finite_numbers_are_refused_on_writing(item: Record | Phase, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="finite"):
        item.to_json()
    path = tmp_path / "t.jsonl"
    with pytest.raises(ValueError, match="finite"), TraceWriter(path) as w:
        w.write(item)
    assert path.read_text() == '{"anunnaki": "trace/1"}\n'  # nothing half-written


def test_non_finite_numbers_are_refused_on_reading() -> None:
    err = refused('{"t": 0, "topic": "/a", "msg": {"x": NaN}}\n')
    assert err.line == 1
    assert "not valid JSON: NaN is not valid JSON" in err.message
    assert refused('{"t": 0, "topic": "/a", "msg": {"x": -Infinity}}\n').line == 1
    err = refused('{"t": 0, "topic": "/a", "msg": {"x": [1e999]}}\n')
    assert err.message == "'msg' holds a non-finite number"
    err = refused('{"t": 1e999, "topic": "/a", "msg": {}}\n')
    assert err.message == "'t' must be a finite number of seconds"


# -- the writer -------------------------------------------------------------------------


def test_trace_writer_is_a_context_manager_that_closes_the_file(tmp_path: Path) -> None:
    path = tmp_path / "t.jsonl"
    with TraceWriter(path, {"name": "w"}) as w:
        w.message(0.0, "/a", {"x": 1})
        w.write(Phase(1.0, "later", "a note"))
        w.message(1.0, "/b", {"y": True})
    assert w._fh.closed
    lines = path.read_text().splitlines()
    assert json.loads(lines[0]) == {"anunnaki": FORMAT, "name": "w"}
    assert lines[1:] == [
        '{"msg": {"x": 1}, "t": 0.0, "topic": "/a"}',
        '{"note": "a note", "phase": "later", "t": 1.0}',
        '{"msg": {"y": true}, "t": 1.0, "topic": "/b"}',
    ]


def test_trace_writer_closes_the_file_when_the_block_raises(tmp_path: Path) -> None:
    with pytest.raises(RuntimeError), TraceWriter(tmp_path / "t.jsonl") as w:
        w.message(0.0, "/a", {})
        raise RuntimeError
    assert w._fh.closed
    assert len(read_trace(tmp_path / "t.jsonl").records) == 1


def test_the_header_cannot_override_the_format_tag(tmp_path: Path) -> None:
    path = tmp_path / "t.jsonl"
    write_trace(path, [], {"anunnaki": "trace/9", "name": "x"})
    assert read_trace(path).header == {"anunnaki": FORMAT, "name": "x"}


@pytest.mark.parametrize(
    ("items", "match"),
    [
        ([Record(1.0, "/a", {}), Record(0.5, "/a", {})], "time goes backwards"),
        ([Record(0.0, "a/b", {})], "not a ROS-style topic name"),
        ([Record(0.0, "/a b", {})], "not a ROS-style topic name"),
        ([Phase(0.0, "")], "non-empty label"),
        ([Record(True, "/a", {})], "finite number"),  # type: ignore[arg-type]
    ],
)
def test_the_writer_refuses_what_the_reader_would_refuse(
    items: list[Record | Phase], match: str, tmp_path: Path
) -> None:
    path = tmp_path / "t.jsonl"
    with pytest.raises(ValueError, match=match), TraceWriter(path) as w:
        for item in items:
            w.write(item)
    read_trace(path)  # what was written before the refusal still reads


# -- reading: header, phases, blank lines, streaming -----------------------------------


def test_the_header_is_optional() -> None:
    trace = parse('{"t": 0, "topic": "/a", "msg": {}}\n')
    assert trace.header == {}
    assert trace.records == [Record(0.0, "/a", {})]


def test_the_header_may_follow_blank_lines_but_nothing_else() -> None:
    assert parse('\n\n{"anunnaki": "trace/1", "name": "x"}\n').header["name"] == "x"
    err = refused('{"t": 0, "phase": "p"}\n{"anunnaki": "trace/1"}\n')
    assert (err.line, err.message) == (2, "the header must be the first line")


def test_a_second_header_is_refused() -> None:
    err = refused('{"anunnaki": "trace/1", "a": 1}\n{"anunnaki": "trace/1", "b": 2}\n')
    assert err.line == 2
    assert err.message == "a second header (the first is on line 1)"


def test_an_unknown_format_version_is_refused() -> None:
    err = refused('{"anunnaki": "trace/2"}\n')
    assert err.message == "unsupported trace format 'trace/2'"
    assert err.hint == "this version reads 'trace/1'"


def test_phases_carry_a_label_and_an_optional_note() -> None:
    trace = parse('{"t": 0, "phase": "nominal"}\n{"t": 5, "phase": "fog", "note": "dense"}\n')
    assert trace.phases == [Phase(0.0, "nominal", ""), Phase(5.0, "fog", "dense")]
    assert trace.records == []


@pytest.mark.parametrize(
    "line",
    [
        '{"t": 0, "phase": "x", "note": null}',
        '{"t": 0, "phase": "x", "note": 5}',
        '{"t": 0, "phase": ""}',
        '{"t": 0, "phase": 3}',
        '{"t": 0, "phase": "x", "topic": "/a"}',
    ],
)
def test_malformed_phases_are_refused(line: str) -> None:
    err = refused(line + "\n")
    assert err.line == 1
    assert err.message.startswith("a phase record has 't', 'phase'")


def test_blank_and_whitespace_lines_are_ignored_and_lines_are_still_counted() -> None:
    text = '\n   \n{"t": 0, "topic": "/a", "msg": {}}\r\n\t\n{"t": 1, "topic": "/a", "msg": {}}\n\n'
    trace = parse(text)
    assert [r.line for r in trace.records] == [3, 5]
    assert parse("").items == []


def test_a_byte_order_mark_is_skipped(tmp_path: Path) -> None:
    path = tmp_path / "bom.jsonl"
    path.write_bytes(b'\xef\xbb\xbf{"anunnaki": "trace/1"}\n{"t": 0, "topic": "/a", "msg": {}}\n')
    assert read_trace(path).header == {"anunnaki": FORMAT}
    assert parse('\ufeff{"t": 0, "topic": "/a", "msg": {}}\n').records[0].t == 0.0


def test_iter_trace_streams_lazily(tmp_path: Path) -> None:
    path = tmp_path / "t.jsonl"
    good = '{"t": 0, "topic": "/a", "msg": {"k": 0}}\n'
    path.write_text('{"anunnaki": "trace/1"}\n' + good * 3 + "this line is broken\n")
    it = iter_trace(path)
    assert next(it) == {"anunnaki": FORMAT}
    first = next(it)
    assert isinstance(first, Record)
    assert first.line == 2
    assert sum(1 for _ in zip(range(2), it, strict=False)) == 2  # nothing past line 4 read yet
    with pytest.raises(ModelFileError, match=r"t\.jsonl:5: trace record: not valid JSON"):
        next(it)


def test_iter_trace_closes_the_file_when_the_consumer_stops_early(tmp_path: Path) -> None:
    path = tmp_path / "t.jsonl"
    write_trace(path, ITEMS)
    it = iter_trace(path)
    next(it)
    next(it)
    it.close()  # the generator's finally closes the file; filterwarnings=error would
    # turn a leaked file into a ResourceWarning failure


def test_iter_trace_reads_a_text_stream_and_names_it() -> None:
    stream = io.StringIO(
        '{"t": 0, "topic": "/a", "msg": {}}\n{"t": -1, "topic": "/a", "msg": {}}\n'
    )
    stream.name = "stdin"  # type: ignore[misc]
    with pytest.raises(ModelFileError) as info:
        list(iter_trace(stream))
    assert str(info.value).startswith("stdin:2: trace record: time goes backwards (-1 after 0.0)")


# -- reading: what is refused -------------------------------------------------------------


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("[1, 2]", "a trace line must be a JSON object"),
        ('{"t": 0, "topic": "/a", "msg": {}', "not valid JSON"),
        ('{"t": "0", "topic": "/a", "msg": {}}', "'t' must be a finite number of seconds"),
        ('{"t": true, "topic": "/a", "msg": {}}', "'t' must be a finite number of seconds"),
        ('{"topic": "/a", "msg": {}}', "'t' must be a finite number of seconds"),
        ('{"t": 0, "topic": "a", "msg": {}}', "'topic' must be a ROS-style name"),
        ('{"t": 0, "topic": "/", "msg": {}}', "'topic' must be a ROS-style name"),
        ('{"t": 0, "topic": "/a b", "msg": {}}', "'topic' must be a ROS-style name"),
        ('{"t": 0, "topic": 5, "msg": {}}', "'topic' must be a ROS-style name"),
        ('{"t": 0, "topic": "/a", "msg": [1]}', "'msg' must be a JSON object"),
        ('{"t": 0, "topic": "/a"}', "'msg' must be a JSON object"),
        ('{"t": 0, "topic": "/a", "msg": {}, "image": "..."}', "unknown key(s) image"),
        ('{"t": 0, "t": 1, "topic": "/a", "msg": {}}', "duplicate key 't'"),
        ('{"t": 0, "topic": "/a", "msg": {"x": 1, "x": 2}}', "duplicate key 'x'"),
        ("[" * 100_000 + "]" * 100_000, "JSON nested too deeply"),
    ],
)
def test_bad_lines_name_file_line_and_problem(line: str, message: str, tmp_path: Path) -> None:
    path = tmp_path / "bad.jsonl"
    path.write_text('{"anunnaki": "trace/1"}\n\n' + line + "\n")
    with pytest.raises(ModelFileError) as info:
        read_trace(path)
    err = info.value
    assert err.message.startswith(message)
    assert str(err).startswith(f"{path}:3: trace record: ")


def test_time_going_backwards_is_refused_and_equal_times_are_fine() -> None:
    same = parse(
        '{"t": 1, "topic": "/a", "msg": {}}\n'
        '{"t": 1, "phase": "p"}\n'
        '{"t": 1.0, "topic": "/b", "msg": {}}\n'
    )
    assert [x.t for x in same.items] == [1.0, 1.0, 1.0]
    err = refused('{"t": 1, "topic": "/a", "msg": {}}\n{"t": 0.5, "topic": "/a", "msg": {}}\n')
    assert (err.line, err.message) == (2, "time goes backwards (0.5 after 1.0)")
    assert err.hint == "sort the records by 't'"
    # any origin: negative times are fine as long as they do not go backwards
    assert parse('{"t": -5, "topic": "/a", "msg": {}}\n').records[0].t == -5.0


def test_non_utf8_is_refused_naming_the_line(tmp_path: Path) -> None:
    path = tmp_path / "latin1.jsonl"
    good = b'{"t": 0, "topic": "/a", "msg": {"s": "ok"}}\n'
    path.write_bytes(
        good * 2000 + '{"t": 1, "topic": "/a", "msg": {"s": "café"}}\n'.encode("latin-1")
    )
    with pytest.raises(ModelFileError) as info:
        read_trace(path)
    assert str(info.value) == (
        f"{path}:2001: not UTF-8 text (byte 0xe9 at column 42) (hint: save the trace as UTF-8)"
    )


def test_an_overlong_line_is_refused_without_reading_it_whole(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import anunnaki.trace as trace_module

    monkeypatch.setattr(trace_module, "MAX_LINE", 100)
    path = tmp_path / "long.jsonl"
    path.write_text('{"t": 0, "topic": "/a", "msg": {"s": "' + "x" * 500 + '"}}\n')
    with pytest.raises(ModelFileError, match=r"long\.jsonl:1: trace record: line longer than 100"):
        read_trace(path)


def test_a_missing_file_is_an_error_naming_it(tmp_path: Path) -> None:
    with pytest.raises(ModelFileError, match=r"nope\.jsonl: cannot read trace"):
        read_trace(tmp_path / "nope.jsonl")
    with pytest.raises(ModelFileError, match="cannot read trace"):
        read_trace(tmp_path)
