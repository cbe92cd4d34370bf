"""The bridge file: the rover's loads; unknown types and bad field mappings name file and line."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest
from ros1_support import need_ros

from anunnaki.errors import ModelFileError
from anunnaki.ros1 import MESSAGE_TYPES, load_bridge, parse_bridge

ROOT = Path(__file__).parents[2]
BRIDGE = ROOT / "examples" / "rover" / "ros1" / "bridge.yaml"

HEAD = "anunnaki: ros1-bridge/1\n"


def test_the_rovers_bridge_file_loads() -> None:
    spec = load_bridge(BRIDGE)
    camera = [t for t in spec.topics if t.ros == "/camera/image_raw"]
    assert [t.as_image for t in camera] == [True, False]
    assert camera[0].bus_topic == "/rover/camera/image"
    state = [t for t in spec.topics if t.bus_topic == "/rover/controller/state"]
    assert sorted(f for t in state for f in t.fields) == [
        "bumper_pressed",
        "buzzer_on",
        "control_mode",
        "lights_on",
    ]
    (mode, stop) = spec.services
    assert (mode.ros_service, mode.type, mode.fields) == (
        "/rover/controller/set_mode",
        "anunnaki_msgs/SetString",
        {"mode": "data"},
    )
    assert stop.type == "std_srvs/Trigger"


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        (
            "topics:\n  - {ros: /a, type: std_msgs/Float99, direction: to_bus}\n",
            "<bridge>:4: topics[/a].type: unknown ROS message type 'std_msgs/Float99' (hint: "
            "the bridge converts: geometry_msgs/Point",
        ),
        (
            "topics:\n  - ros: /range\n    type: sensor_msgs/Range\n    direction: to_bus\n"
            "    fields:\n      distance: rnage\n",
            "<bridge>:8: topics[/range].fields.distance: sensor_msgs/Range has no field 'rnage' "
            "(hint: its fields: header.seq, header.stamp, header.frame_id, radiation_type,",
        ),
        (
            "topics:\n  - {ros: /cam, type: sensor_msgs/Image, direction: to_bus,\n"
            "     fields: {pixels: data}}\n",
            "<bridge>:5: topics[/cam].fields.pixels: 'data' is the image's bytes; they travel "
            "as the bus's Image, not a field",
        ),
        (
            "topics:\n  - {ros: /a, type: std_msgs/Bool, direction: to_bus, bus: /s}\n"
            "  - {ros: /b, type: std_msgs/Bool, direction: to_bus, bus: /s}\n",
            "<bridge>:5: topics[/b].fields.data: bus field 'data' of /s comes from two ROS "
            "topics (/a and /b)",
        ),
        (
            "topics:\n  - {ros: /a, type: std_msgs/Bool, direction: sideways}\n",
            "<bridge>:4: topics[0].direction: Input should be 'to_bus' or 'to_ros'",
        ),
        (
            "topics:\n  - {ros: a/b, type: std_msgs/Bool, direction: to_bus}\n",
            "<bridge>:4: topics[0].ros: String should match pattern",
        ),
        (
            "services:\n  - {bus: /mode, type: std_srvs/SetString}\n",
            "<bridge>:4: services[/mode].type: unknown ROS service type 'std_srvs/SetString' "
            "(hint: the bridge calls: anunnaki_msgs/SetString, std_srvs/Empty,",
        ),
        (
            "services:\n  - bus: /mode\n    type: std_srvs/SetBool\n    fields: {mode: value}\n",
            "<bridge>:6: services[/mode].fields.mode: std_srvs/SetBool request has no field "
            "'value' (hint: its fields: data)",
        ),
        (
            "topics:\n  - {ros: /a, type: std_msgs/Bool, direction: to_bus, rate: 5}\n",
            "<bridge>:4: topics[0].rate: unknown field 'rate'",
        ),
    ],
)
def test_bad_bridge_files_are_refused_with_file_line_and_element(body: str, expected: str) -> None:
    with pytest.raises(ModelFileError) as caught:
        parse_bridge(HEAD + "name: b\n" + body)
    assert str(caught.value).startswith(expected), str(caught.value)


def test_a_file_of_another_kind_is_named_as_such(tmp_path: Path) -> None:
    path = tmp_path / "binding.yaml"
    path.write_text("anunnaki: binding/1\nplatform: x\n")
    with pytest.raises(ModelFileError) as caught:
        load_bridge(path)
    assert str(caught.value) == (
        f"{path}:1: anunnaki: not a bridge file: 'anunnaki' is 'binding/1' (hint: start the "
        "file with 'anunnaki: ros2-bridge/1' (ROS 2) or 'anunnaki: ros1-bridge/1' (ROS 1))"
    )


def test_every_type_the_issue_names_is_converted() -> None:
    named = {
        "std_msgs/Bool",
        "std_msgs/String",
        "std_msgs/Int32",
        "std_msgs/Int64",
        "std_msgs/Float32",
        "std_msgs/Float64",
        "std_msgs/Header",
        "sensor_msgs/Image",
        "sensor_msgs/CompressedImage",
        "sensor_msgs/Range",
        "sensor_msgs/BatteryState",
        "sensor_msgs/NavSatFix",
        "geometry_msgs/Twist",
        "geometry_msgs/PoseStamped",
    }
    assert named <= set(MESSAGE_TYPES)


def test_the_type_table_matches_debians_generated_messages() -> None:
    need_ros()
    script = (
        "import importlib, json\n"
        f"names = {sorted(MESSAGE_TYPES)!r}\n"
        "out = {}\n"
        "for n in names:\n"
        "    pkg, name = n.split('/')\n"
        "    cls = getattr(importlib.import_module(pkg + '.msg'), name)\n"
        "    out[n] = [list(p) for p in zip(cls.__slots__, cls._slot_types)]\n"
        "print(json.dumps(out))\n"
    )
    done = subprocess.run(
        ["/usr/bin/python3", "-c", script], capture_output=True, text=True, check=True
    )
    debian = json.loads(done.stdout)
    assert {n: [list(f) for f in fields] for n, fields in MESSAGE_TYPES.items()} == debian
