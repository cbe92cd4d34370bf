"""ROS 2 bridge files: ROS 2's message table, QoS, distro, services served on ROS."""

from __future__ import annotations

import pytest

from anunnaki.errors import ModelFileError
from anunnaki.rosbridge import ROS2_MESSAGE_TYPES, parse_bridge


def test_a_ros2_file_is_checked_against_ros2s_messages() -> None:
    spec = parse_bridge(
        "anunnaki: ros2-bridge/1\n"
        "distro: jazzy\n"
        "topics:\n"
        "  - {ros: /us, type: sensor_msgs/Range, direction: to_bus,\n"
        "     fields: {range: range, variance: variance, t: header.stamp}}\n"
        "  - {ros: /diagnostics, type: diagnostic_msgs/DiagnosticArray, direction: to_bus}\n"
        "  - {ros: /cmd, type: std_msgs/String, direction: to_ros}\n"
        "services:\n"
        "  - {bus: /activate, ros: /cam/change_state, type: lifecycle_msgs/ChangeState,\n"
        "     fields: {transition: transition.id}}\n"
        "  - {bus: /bus/task, ros: /task, type: std_srvs/Trigger, serve: ros}\n"
    )
    assert spec.ros2 and spec.distro == "jazzy"
    # sensor streams read best effort, everything else reliable, unless stated
    assert [t.effective_qos for t in spec.topics] == ["sensor", "reliable", "reliable"]
    assert spec.services[1].serve == "ros"
    assert "variance" in dict(ROS2_MESSAGE_TYPES["sensor_msgs/Range"])


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (  # ROS 2's Header has no seq
            "anunnaki: ros2-bridge/1\ntopics:\n  - {ros: /us, type: sensor_msgs/Range, "
            "direction: to_bus, fields: {seq: header.seq}}\n",
            "sensor_msgs/Range has no field 'header.seq'",
        ),
        (  # ROS 1's Range has no variance
            "anunnaki: ros1-bridge/1\ntopics:\n  - {ros: /us, type: sensor_msgs/Range, "
            "direction: to_bus, fields: {v: variance}}\n",
            "sensor_msgs/Range has no field 'variance'",
        ),
        ("anunnaki: ros1-bridge/1\ndistro: jazzy\n", "a ROS 1 bridge file has no 'distro'"),
        (
            "anunnaki: ros1-bridge/1\ntopics:\n  - {ros: /a, type: std_msgs/Bool, "
            "direction: to_bus, qos: sensor}\n",
            "a ROS 1 topic has no 'qos'",
        ),
        (
            "anunnaki: ros1-bridge/1\nservices:\n  - {bus: /a, type: std_srvs/Trigger, "
            "serve: ros}\n",
            "the ROS 1 bridge serves on the bus only",
        ),
        ("anunnaki: ros2-bridge/1\ndistro: iron\n", "distro"),
        ("anunnaki: ros1-bridge/1\nheartbeat: 1.0\n", "a ROS 1 bridge file has no 'heartbeat'"),
        (  # a lease the scheduling alone would let lapse: file, line and key named
            "anunnaki: ros2-bridge/1\nheartbeat: 0.01\n",
            "bridge.yaml:2: heartbeat: the lease of the bridge's ROS 2 heartbeat is 0.01 s, "
            "outside 0.1..60 s",
        ),
        ("anunnaki: ros2-bridge/1\nheartbeat: .inf\n", "heartbeat: .* is inf s"),
        ("anunnaki: ros2-bridge/1\nheartbeat: true\n", "heartbeat: Input should be a valid"),
        ("anunnaki: ros2-bridge/1\nheartbeat: fast\n", "heartbeat: Input should be a valid"),
        (
            "anunnaki: ros2-bridge/1\nservices:\n  - {bus: /m, type: anunnaki_msgs/SetString}\n",
            "unknown ROS service type 'anunnaki_msgs/SetString'",
        ),
    ],
)
def test_mistakes_are_named(text: str, message: str) -> None:
    with pytest.raises(ModelFileError, match=message.replace("(", r"\(").replace(")", r"\)")):
        parse_bridge(text, source="bridge.yaml")


def test_the_heartbeat_lease_defaults_to_one_second_on_the_bridges_own_topic() -> None:
    spec = parse_bridge("anunnaki: ros2-bridge/1\nname: rover_bridge\n")
    assert (spec.heartbeat_lease, spec.heartbeat_topic) == (1.0, "/rover_bridge/heartbeat")
    assert parse_bridge("anunnaki: ros2-bridge/1\nheartbeat: 2\n").heartbeat_lease == 2.0


def test_a_diagnostics_status_becomes_flat_fields_a_binding_reads() -> None:
    from anunnaki.rosbridge import ToBus

    spec = parse_bridge(
        "anunnaki: ros2-bridge/1\ntopics:\n"
        "  - {ros: /diagnostics, type: diagnostic_msgs/DiagnosticArray, direction: to_bus,\n"
        "     bus: /health/camera, status: rover/camera}\n"
        "  - {ros: /diagnostics, type: diagnostic_msgs/DiagnosticArray, direction: to_bus,\n"
        "     bus: /health/battery, status: rover/battery, fields: {soc: charge, ok: healthy}}\n"
    )
    camera, battery = spec.topics
    array = {
        "header": {"stamp": 1.0, "frame_id": ""},
        "status": [
            {
                "level": 1,
                "name": "rover/camera",
                "message": "dim",
                "hardware_id": "cam0",
                "values": [{"key": "luma", "value": "42.5"}, {"key": "frames", "value": "7"}],
            },
            {
                "level": 0,
                "name": "rover/battery",
                "message": "",
                "hardware_id": "",
                "values": [{"key": "charge", "value": "0.8"}, {"key": "healthy", "value": "True"}],
            },
        ],
    }
    to_bus = ToBus(spec, strict=True)
    assert to_bus.message(camera, array) == {
        "level": 1,
        "message": "dim",
        "hardware_id": "cam0",
        "luma": 42.5,
        "frames": 7,
    }
    assert to_bus.message(battery, array) == {"soc": 0.8, "ok": True}
    assert to_bus.message(camera, {"header": {}, "status": []}) is None  # nothing published
    with pytest.raises(ModelFileError, match="'status' picks one status of a diagnostics array"):
        parse_bridge(
            "anunnaki: ros2-bridge/1\ntopics:\n"
            "  - {ros: /d, type: std_msgs/String, direction: to_bus, status: x}\n"
        )


def test_service_values_translate_a_mode_name() -> None:
    from anunnaki.rosbridge import ConversionError

    spec = parse_bridge(
        "anunnaki: ros2-bridge/1\nservices:\n"
        "  - {bus: /set_mode, ros: /manual, type: std_srvs/SetBool, fields: {mode: data},\n"
        "     values: {mode: {manual: true, autonomous: false}}}\n"
        "  - {bus: /camera/state, ros: /camera/change_state, type: lifecycle_msgs/ChangeState,\n"
        "     fields: {state: transition.id}, values: {state: {active: 3, inactive: 4}}}\n"
    )
    set_mode, lifecycle = spec.services
    assert set_mode.ros_request({"mode": "manual"}) == {"data": True}
    assert set_mode.ros_request({"mode": "autonomous", "reason": "G3"}) == {"data": False}
    assert lifecycle.ros_request({"state": "inactive"}) == {"transition": {"id": 4}}
    with pytest.raises(ConversionError, match="mode 'parked' is not one of autonomous, manual"):
        set_mode.ros_request({"mode": "parked"})
    with pytest.raises(ModelFileError, match="'values' translates 'speed', which is no field"):
        parse_bridge(
            "anunnaki: ros2-bridge/1\nservices:\n"
            "  - {bus: /m, type: std_srvs/SetBool, values: {speed: {fast: true}}}\n"
        )
