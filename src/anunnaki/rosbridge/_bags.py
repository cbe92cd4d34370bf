"""Rosbags in and out: a recorded robot as a trace, and a run as a bag (``rosbags``, pure Python).

**In.** :func:`read_bag` reads a ROS 1 bag (``.bag``) or a ROS 2 bag (a folder with
``metadata.yaml``, or its ``.db3``/``.mcap``) with ``rosbags.highlevel.AnyReader`` and turns
each message of a bridged topic into a trace :class:`~anunnaki.trace.Record` through the
**same** bridge file as the live bridge (type check, field mapping, merging of several ROS
topics into one bus topic). Camera frames are left out (guideline P1: traces hold what is
derived from frames, never the frames); an image entry with ``fields`` (its header, its
size) is kept. ``anunnaki evaluate MODEL -b BINDING -t run.bag --bridge bridge.yaml`` then
replays the robot's recording against the goal model; a bag :func:`write_bag` wrote needs no
bridge file (its topics are the bus's, its messages their JSON). A ROS 2 bag goes through the same
ROS 1 bridge file; a mapped field its type lacks (ROS 2's Header has no ``seq``) is left out.

**Out.** :func:`write_bag` writes a run's inputs (one ``std_msgs/String`` topic per input
topic, the message as JSON) and its decisions (``/utu/decisions``, JSON) to a ROS 1 bag
(``rosbag``/``rqt_bag``) or a rosbag2 folder in MCAP or SQLite 3 (``ros2 bag``, Foxglove);
``anunnaki log RUN.db --export-bag OUT.bag`` (or ``OUT`` for a rosbag2 folder).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any, Literal

from anunnaki import topics
from anunnaki.errors import AnunnakiError, MissingExtraError, ModelFileError
from anunnaki.rosbridge._schema import BridgeSpec, TopicBridge
from anunnaki.rosbridge._tobus import ToBus
from anunnaki.trace import Record

__all__ = [
    "BagStorage",
    "bag_message_to_dict",
    "bag_storage",
    "is_bag",
    "read_bag",
    "write_bag",
]


_TIME_TYPES = {"builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration"}

#: What a run's records are written as in a bag: the record's JSON in a string.
_STRING = "std_msgs/msg/String"


def _rosbags() -> Any:
    try:
        import rosbags.highlevel
        import rosbags.rosbag1
        import rosbags.rosbag2
        import rosbags.typesys
    except ImportError:
        raise MissingExtraError("rosbags", "ros") from None
    return rosbags


def is_bag(path: str | Path) -> bool:
    """Whether ``path`` looks like a ROS 1 or ROS 2 bag (not a JSONL trace)."""
    p = Path(path)
    if p.is_dir():
        return (p / "metadata.yaml").exists()
    return p.suffix in {".bag", ".db3", ".mcap"}


def bag_message_to_dict(msg: Any) -> dict[str, Any]:
    """A rosbags message (a dataclass) as plain data, times as float seconds.

    rosbags keeps the type name (``__msgtype__``) and the constants (``ULTRASOUND``) as
    dataclass fields too; they are no message fields and are left out.
    """
    return {
        f.name: _plain(getattr(msg, f.name))
        for f in dataclasses.fields(msg)
        if not f.name.startswith("__") and not f.name.isupper()
    }


def _plain(v: Any) -> Any:
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        if getattr(v, "__msgtype__", "") in _TIME_TYPES:
            return float(getattr(v, "sec")) + float(getattr(v, "nanosec")) / 1e9  # noqa: B009
        return bag_message_to_dict(v)
    if hasattr(v, "tolist"):  # numpy arrays: uint8 data as bytes, the rest as lists
        return bytes(v.tobytes()) if str(getattr(v, "dtype", "")) == "uint8" else v.tolist()
    if isinstance(v, list | tuple):
        return [_plain(x) for x in v]
    return v


def _ros1_type(msgtype: str) -> str:
    """``sensor_msgs/msg/Range`` (rosbags, ROS 2) → ``sensor_msgs/Range`` (ROS 1)."""
    return msgtype.replace("/msg/", "/")


def read_bag(path: str | Path, spec: BridgeSpec | None = None) -> list[Record]:
    """The bridged topics of a bag as trace records, in time order (seconds since the epoch).

    Without ``spec`` the bag must be one :func:`write_bag` wrote (every topic a
    ``std_msgs/String`` holding a bus message as JSON): its inputs come back on their own
    topics, as they were recorded, and its decisions (``topics.BAG_DECISIONS``) are left out.

    Raises:
        ModelFileError: The bag cannot be read, a bridged topic has another type in it, or
            (without ``spec``) it is not a bag of a run.
        MissingExtraError: ``rosbags`` is not installed.

    """
    rb = _rosbags()
    if spec is None:
        return _read_run_bag(rb, Path(path))
    entries: dict[str, list[TopicBridge]] = {}
    for t in spec.topics:
        if t.direction == "to_bus" and not t.as_image:
            entries.setdefault(t.ros, []).append(t)
    to_bus = ToBus(spec, strict=False)
    records: list[Record] = []
    try:
        with rb.highlevel.AnyReader([Path(path)]) as reader:
            wanted = [c for c in reader.connections if c.topic in entries]
            for c in wanted:
                _check_type(path, c.topic, _ros1_type(c.msgtype), entries[c.topic])
            for connection, stamp, raw in reader.messages(connections=wanted):
                data = bag_message_to_dict(reader.deserialize(raw, connection.msgtype))
                for t in entries[connection.topic]:
                    fields = to_bus.fields(t, data)
                    if fields is not None:
                        records.append(Record(stamp / 1e9, t.bus_topic, fields))
    except (rb.highlevel.AnyReaderError, OSError) as exc:
        raise ModelFileError(f"cannot read the bag: {exc}", path=str(path)) from None
    return records


def _read_run_bag(rb: Any, path: Path) -> list[Record]:
    """The inputs of a bag :func:`write_bag` wrote, as it recorded them."""
    records: list[Record] = []
    try:
        with rb.highlevel.AnyReader([path]) as reader:
            foreign = sorted(
                f"{c.topic} ({_ros1_type(c.msgtype)})"
                for c in reader.connections
                if c.msgtype != _STRING
            )
            if foreign:
                raise ModelFileError(
                    f"not a bag of an Anunnaki run: {', '.join(foreign[:3])} "
                    "is no std_msgs/String of JSON",
                    path=str(path),
                    hint="give --bridge BRIDGE.yaml, which maps its topics and fields to the "
                    "bus's (docs/ros.md)",
                )
            wanted = [c for c in reader.connections if c.topic != topics.BAG_DECISIONS]
            for connection, stamp, raw in reader.messages(connections=wanted):
                text = reader.deserialize(raw, connection.msgtype).data
                try:
                    msg = json.loads(text)
                except json.JSONDecodeError:
                    msg = None
                if not isinstance(msg, dict):
                    raise ModelFileError(
                        f"{connection.topic} holds a string that is no JSON object "
                        f"({text[:40]!r}): not a bag of an Anunnaki run",
                        path=str(path),
                        hint="give --bridge BRIDGE.yaml, which maps its topics to the bus's",
                    )
                records.append(Record(stamp / 1e9, connection.topic, msg))
    except (rb.highlevel.AnyReaderError, OSError) as exc:
        raise ModelFileError(f"cannot read the bag: {exc}", path=str(path)) from None
    return records


def _check_type(path: str | Path, topic: str, found: str, entries: list[TopicBridge]) -> None:
    for t in entries:
        if t.type != found:
            raise ModelFileError(
                f"{topic} is {found} in the bag, but the bridge file says {t.type}",
                path=str(path),
                element=f"topics[{topic}].type",
                hint="fix the type in the bridge file, or record the topic the robot publishes",
            )


#: How :func:`write_bag` stores a run: a ROS 1 bag, or a rosbag2 folder (MCAP or SQLite 3).
BagStorage = Literal["ros1", "mcap", "sqlite3"]


def bag_storage(path: str | Path, storage: str | None = None) -> BagStorage:
    """The storage :func:`write_bag` uses for ``path``.

    ``storage`` if given, else ``ros1`` for a ``.bag`` path, else a rosbag2 folder in MCAP
    (what ``ros2 bag record`` writes by default since Iron).

    Raises:
        AnunnakiError: An unknown storage name.

    """
    if storage is None:
        return "ros1" if Path(path).suffix == ".bag" else "mcap"
    if storage not in ("ros1", "mcap", "sqlite3"):
        raise AnunnakiError(f"unknown bag storage {storage!r}: ros1, mcap or sqlite3")
    return storage  # type: ignore[return-value]


def write_bag(
    path: str | Path,
    inputs: Iterable[Record],
    decisions: Iterable[tuple[float, Mapping[str, Any]]] = (),
    *,
    overwrite: bool = False,
    storage: str | None = None,
) -> int:
    """Write a run to a bag: inputs on their topics, decisions on ``topics.BAG_DECISIONS``.

    A ROS 1 bag (``path`` ends in ``.bag``, or ``storage="ros1"``), or a rosbag2 folder
    (``storage`` ``mcap``, the default otherwise, or ``sqlite3``; ``metadata.yaml`` version 9,
    as ROS 2 Jazzy's ``ros2 bag`` writes). Every message is a ``std_msgs/String`` holding
    the JSON of the message (the bus's messages have no fixed ROS type), so :func:`read_bag`
    reads its inputs back without a bridge file, and a ROS 2 node that plays the bag gets
    them as ``std_msgs/msg/String``. Returns how many messages were written.

    Raises:
        AnunnakiError: The bag exists already (and not ``overwrite``), or cannot be written.

    """
    rb = _rosbags()
    kind = bag_storage(path, storage)
    out = Path(path)
    if out.exists():
        if not overwrite:
            raise AnunnakiError(f"{out} exists already; give another name, or --force")
        _remove_bag(out)
    rows = list(_in_time_order(inputs, decisions))
    if kind == "ros1":
        return _write_ros1(rb, out, rows)
    return _write_ros2(rb, out, rows, kind)


def _remove_bag(out: Path) -> None:
    """Remove an old bag: a file, or a rosbag2 folder (never any other folder)."""
    if not out.is_dir():
        out.unlink()
        return
    if not (out / "metadata.yaml").exists():
        raise AnunnakiError(f"{out} is a folder but no rosbag2 (no metadata.yaml): not replaced")
    import shutil

    shutil.rmtree(out)


def _write_strings(
    writer: Any,
    store: Any,
    serialize: Callable[[Any, str], Any],
    rows: list[tuple[float, str, Any]],
) -> int:
    """Each row as a ``std_msgs/String`` holding its JSON, one connection per topic."""
    string = store.types[_STRING]
    connections: dict[str, Any] = {}
    for t, topic, body in rows:
        if topic not in connections:
            connections[topic] = writer.add_connection(topic, _STRING, typestore=store)
        raw = serialize(string(data=json.dumps(body)), _STRING)
        writer.write(connections[topic], max(0, round(t * 1e9)), raw)
    return len(rows)


def _write_ros1(rb: Any, out: Path, rows: list[tuple[float, str, Any]]) -> int:
    store = rb.typesys.get_typestore(rb.typesys.Stores.ROS1_NOETIC)
    try:
        with rb.rosbag1.Writer(out) as writer:
            return _write_strings(writer, store, store.serialize_ros1, rows)
    except (rb.rosbag1.WriterError, OSError) as exc:
        raise AnunnakiError(f"cannot write the bag {out}: {exc}") from None


def _write_ros2(rb: Any, out: Path, rows: list[tuple[float, str, Any]], kind: str) -> int:
    # std_msgs/String is the same in every ROS 2 distribution; Jazzy's store describes it
    store = rb.typesys.get_typestore(rb.typesys.Stores.ROS2_JAZZY)
    plugin = rb.rosbag2.StoragePlugin.MCAP if kind == "mcap" else None
    options: dict[str, Any] = {"version": 9}
    if plugin is not None:
        options["storage_plugin"] = plugin
    try:
        with rb.rosbag2.Writer(out, **options) as writer:
            return _write_strings(writer, store, store.serialize_cdr, rows)
    except (rb.rosbag2.WriterError, OSError) as exc:
        raise AnunnakiError(f"cannot write the bag {out}: {exc}") from None


def _in_time_order(
    inputs: Iterable[Record], decisions: Iterable[tuple[float, Mapping[str, Any]]]
) -> Iterator[tuple[float, str, Any]]:
    rows = [(r.t, r.topic, r.msg) for r in inputs]
    rows += [(t, topics.BAG_DECISIONS, dict(d)) for t, d in decisions]
    rows.sort(key=lambda row: row[0])
    return iter(rows)
