"""What the bus gets of a ROS message (``ToBus``), the one rule of both bridges and the bags."""

from __future__ import annotations

import itertools
import threading
from pathlib import Path

import pytest

from anunnaki.messages import Image
from anunnaki.ros1 import ConversionError, ToBus, TopicBridge, load_bridge

BRIDGE = Path(__file__).parents[2] / "examples" / "rover" / "ros1" / "bridge.yaml"


def entry(ros: str, bus: str | None = None) -> TopicBridge:
    """The rover's bridge file's entry for ROS topic ``ros`` (onto ``bus``, if several)."""
    (found,) = [
        t
        for t in load_bridge(BRIDGE).topics
        if t.ros == ros and t.direction == "to_bus" and bus in (None, t.bus_topic)
    ]
    return found


def test_topics_feeding_one_bus_topic_publish_their_latest_values_merged() -> None:
    to_bus = ToBus(load_bridge(BRIDGE))
    mode, lights = entry("/rover/controller/mode"), entry("/rover/controller/lights")
    assert to_bus.message(mode, {"data": "autonomous"}) == {"control_mode": "autonomous"}
    both = {"control_mode": "autonomous", "lights_on": True}
    assert to_bus.message(lights, {"data": True}) == both
    assert to_bus.message(mode, {"data": "manual"}) == {**both, "control_mode": "manual"}
    # a bus topic fed by one ROS topic carries its own fields only
    assert to_bus.message(entry("/ultrasonic/range"), {"range": 0.5, "min_range": 0.02}) == {
        "range": 0.5
    }


def test_a_returned_message_is_a_copy_never_the_merged_state() -> None:
    to_bus = ToBus(load_bridge(BRIDGE))
    first = to_bus.fields(entry("/rover/controller/mode"), {"data": "autonomous"})
    first["control_mode"] = "changed by a subscriber"
    again = to_bus.fields(entry("/rover/controller/bumper"), {"data": False})
    assert again == {"control_mode": "autonomous", "bumper_pressed": False}


def test_a_missing_mapped_field_is_an_error_only_when_strict() -> None:
    info = entry("/camera/image_raw", "/camera/image_info")
    ros2_header = {"header": {"stamp": 1.0, "frame_id": "camera"}, "width": 4, "height": 2}
    with pytest.raises(KeyError):
        ToBus(load_bridge(BRIDGE)).message(info, ros2_header)
    got = ToBus(load_bridge(BRIDGE), strict=False).message(info, ros2_header)
    assert got == {"width": 4, "height": 2}  # ROS 2's Header has no seq: left out


def test_a_camera_entry_becomes_the_bus_image_and_a_bad_frame_is_refused() -> None:
    camera = entry("/camera/image_raw", "/rover/camera/image")
    raw = {
        "header": {"seq": 3, "stamp": 12.5, "frame_id": "camera"},
        "height": 2, "width": 4, "encoding": "rgb8", "is_bigendian": 0, "step": 12,
        "data": bytes(range(24)),
    }  # fmt: skip
    image = ToBus(load_bridge(BRIDGE)).message(camera, raw)
    assert isinstance(image, Image) and (image.width, image.height) == (4, 2)
    with pytest.raises(ConversionError):
        ToBus(load_bridge(BRIDGE)).message(camera, {**raw, "data": b"\x00" * 5})


def test_merging_from_many_threads_loses_no_field() -> None:
    """ROS calls back each topic on its own thread: a message never drops a field seen before."""
    to_bus = ToBus(load_bridge(BRIDGE))
    names = ("mode", "buzzer_on", "bumper", "lights")
    entries = [entry(f"/rover/controller/{name}") for name in names]
    seen: dict[str, list[set[str]]] = {t.ros: [] for t in entries}
    start = threading.Barrier(len(entries))

    def feed(t: TopicBridge) -> None:
        start.wait()
        for i in range(200):
            value = "x" if t.type == "std_msgs/String" else bool(i % 2)
            seen[t.ros].append(set(to_bus.fields(t, {"data": value})))

    threads = [threading.Thread(target=feed, args=(t,)) for t in entries]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    for fields in seen.values():
        assert len(fields) == 200
        assert all(before <= after for before, after in itertools.pairwise(fields))
    every = {"control_mode", "buzzer_on", "bumper_pressed", "lights_on"}
    assert set(to_bus.fields(entries[0], {"data": "y"})) == every
    assert sum(fields[-1] == every for fields in seen.values()) >= 1  # the last to finish
