"""The native ROS 2 bridge against live rclpy nodes (ROS 2 Jazzy, Fast DDS), in a netns.

One loopback-only network namespace, one rclpy peer (tests/ros2/ros2_peer.py) and one bridge
(``python -m anunnaki.ros2 tests/ros2/bridge-live.yaml``) serve the whole module; this
process reaches the bridge's bus through a unix socket. Every mapped type goes bus → ROS 2 →
(the peer echoes it) → ROS 2 → bus, so one round trip checks both directions.
"""

from __future__ import annotations

import json
import math
import subprocess
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from ros2_support import DEADLINE, ROS2_PYTHON, Netns, Proc, need_ros2

from anunnaki.bus import Bus, ServiceError, open_bus
from anunnaki.messages import Image, ServiceReply
from anunnaki.rosbridge import ROS2_MESSAGE_TYPES, ROS2_SERVICE_TYPES

HERE = Path(__file__).parent
BRIDGE = HERE / "bridge-live.yaml"
# float32 fields: values a float32 holds exactly, so what comes back equals what went out
STAMP = {"stamp": 12.5, "frame_id": "base"}
MESSAGES: dict[str, dict[str, Any]] = {
    "bool": {"data": True},
    "string": {"data": "héllo, ROS 2"},
    "int32": {"data": -7},
    "int64": {"data": 2**40 + 3},
    "float32": {"data": 0.5},
    "float64": {"data": 1e-3},
    "range": {
        "header": STAMP,
        "radiation_type": 0,
        "field_of_view": 0.5,
        "min_range": 0.0625,
        "max_range": 4.0,
        "range": 0.25,
        "variance": 0.125,  # Jazzy's field (issue #31: the CDR size mismatch)
    },
    "battery": {
        "header": STAMP,
        "voltage": 12.5,
        "percentage": 0.75,
        "power_supply_status": 2,
        "present": True,
        "cell_voltage": [3.5, 4.0, 3.75],
        "location": "bay 1",
    },
    "fix": {
        "header": STAMP,
        "status": {"status": 0, "service": 1},
        "latitude": 48.137,
        "longitude": 11.575,
        "altitude": 519.0,
        "position_covariance": [float(i) for i in range(9)],
        "position_covariance_type": 2,
    },
    "twist": {"linear": {"x": 0.5, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 1.0}},
    "pose": {
        "header": STAMP,
        "pose": {
            "position": {"x": 1.0, "y": 2.0, "z": 0.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        },
    },
    "diagnostics": {
        "header": STAMP,
        "status": [
            {
                "level": 1,
                "name": "rover/camera",
                "message": "dim",
                "hardware_id": "cam0",
                "values": [{"key": "luma", "value": "42.5"}, {"key": "mode", "value": "auto"}],
            }
        ],
    },
}


class Live:
    """The namespace, the peer, the bridge and this process's bus, for the whole module."""

    def __init__(self, tmp: Path) -> None:
        self.ns = Netns(tmp)
        try:
            endpoint = self.ns.socket()
            self.bus: Bus = open_bus("zenoh", mode="peer", listen=[endpoint], connect=[])
            self.peer = self.ns.python(str(HERE / "ros2_peer.py"), name="peer", ready="peer ready")
            self.bridge: Proc = self.ns.bridge(BRIDGE, endpoint)
        except BaseException:
            self.close()
            raise

    def round_trip(self, name: str, message: Any) -> Any:
        """Publish on /bus/out/NAME until it comes back on /bus/in/NAME; what came back."""
        got: list[Any] = []
        done = threading.Event()

        def on(sample: Any) -> None:
            got.append(sample.message)
            done.set()

        sub = self.bus.subscribe(f"/bus/in/{name}", on)
        try:
            end = DEADLINE
            while not done.wait(0.2):  # discovery is asynchronous: send until it arrives
                end -= 0.2
                assert end > 0, f"{name} never came back; bridge said:\n" + "\n".join(
                    self.bridge.lines[-20:]
                )
                self.bus.publish(f"/bus/out/{name}", message)
        finally:
            sub.close()
        return got[0]

    def close(self) -> None:
        bus = getattr(self, "bus", None)
        self.ns.close()
        if bus is not None:
            bus.close()


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Live]:
    need_ros2()
    setup = Live(tmp_path_factory.mktemp("ros2"))
    try:
        yield setup
    finally:
        setup.close()


def same(sent: Any, got: Any, where: str = "") -> None:
    """Every field sent came back, equal (floats as float32 or float64 hold them)."""
    if isinstance(sent, dict):
        assert isinstance(got, dict), where
        for key, value in sent.items():
            same(value, got[key], f"{where}.{key}")
    elif isinstance(sent, list):
        assert len(sent) == len(got), where
        for i, (a, b) in enumerate(zip(sent, got, strict=True)):
            same(a, b, f"{where}[{i}]")
    elif isinstance(sent, float):
        assert math.isclose(sent, got, rel_tol=1e-6), f"{where}: {sent} != {got}"
    else:
        assert sent == got, f"{where}: {sent!r} != {got!r}"


@pytest.mark.parametrize("name", sorted(MESSAGES))
def test_every_mapped_type_goes_both_ways(live: Live, name: str) -> None:
    got = live.round_trip(name, MESSAGES[name])
    same(MESSAGES[name], got.to_body())


def test_a_diagnostics_status_reaches_the_bus_as_flat_fields(live: Live) -> None:
    health: list[Any] = []
    sub = live.bus.subscribe("/bus/health/camera", lambda s: health.append(s.message.to_body()))
    try:
        live.round_trip("diagnostics", MESSAGES["diagnostics"])
        # the same ROS message feeds both entries; wait for the second
        end = DEADLINE
        while not health:
            end -= 0.05
            assert end > 0, "no /bus/health/camera"
            threading.Event().wait(0.05)
    finally:
        sub.close()
    assert health[0] == {
        "level": 1,
        "message": "dim",
        "hardware_id": "cam0",
        "luma": 42.5,
        "mode": "auto",
    }


def test_camera_frames_go_both_ways_as_image_and_compressed_image(live: Live) -> None:
    np = pytest.importorskip("numpy")
    pytest.importorskip("cv2")
    pixels = np.zeros((24, 32, 3), np.uint8)
    pixels[:, :16] = (200, 40, 10)
    pixels[8:, 16:] = (10, 40, 200)
    # raw: the bus frame becomes an rgb8 sensor_msgs/Image and comes back as a PNG, same pixels
    frame = Image.from_array(pixels, encoding="png", frame_id="cam", seq=3)
    back = live.round_trip("image", frame)
    assert isinstance(back, Image)
    assert (back.width, back.height, back.frame_id) == (32, 24, "cam")
    assert np.array_equal(back.to_array(), pixels)
    # compressed: the JPEG's bytes travel unchanged both ways
    jpeg = Image.from_array(pixels, encoding="jpeg", frame_id="cam")
    back = live.round_trip("compressed", jpeg)
    assert isinstance(back, Image)
    assert (back.encoding, back.data) == ("jpeg", jpeg.data)


def test_services_go_both_ways(live: Live) -> None:
    # bus → ROS 2: a tactic's request calls the robot's service
    reply = live.bus.request("/robot/set_flag", {"data": True}, timeout=DEADLINE)
    assert isinstance(reply, ServiceReply) and reply.ok
    assert reply.body == {"success": True, "message": "flag set to True"}
    with pytest.raises(ServiceError, match="flag set to False"):
        live.bus.request("/robot/set_flag", {"data": False}, timeout=DEADLINE)
    # a lifecycle transition (lifecycle_msgs/ChangeState), the bus field mapped into it
    reply = live.bus.request("/robot/activate", {"transition": 3}, timeout=DEADLINE)
    assert isinstance(reply, ServiceReply) and reply.ok
    with pytest.raises(ServiceError, match="refused"):
        live.bus.request("/robot/activate", {"transition": 4}, timeout=DEADLINE)
    # ROS 2 → bus: the bridge offers /bridge/trigger and answers it from a bus service
    calls: list[Any] = []

    def trigger(request: Any) -> ServiceReply:
        calls.append(request)
        return ServiceReply(ok=True, body={"message": "triggered on the bus"})

    service = live.bus.service("/bus/trigger", trigger)
    try:
        result = _command(live, "call-trigger", "/peer/result")
    finally:
        service.close()
    assert result == "True triggered on the bus"
    assert len(calls) == 1


def test_a_ros_call_that_comes_back_through_the_bridge_does_not_deadlock(live: Live) -> None:
    # ROS /bridge/set_flag → bus /robot/set_flag → ROS /peer/set_flag, all through the
    # bridge: its one executor thread awaits the bus reply instead of holding it, so the
    # peer's reply (which that thread takes) comes in, and the answer is the peer's
    assert _command(live, "call-chain", "/peer/result") == "True flag set to True"


def _command(live: Live, command: str, answer_topic: str) -> str:
    """Send the peer a command (until it answers on ``answer_topic``); its answer."""
    got: list[str] = []
    done = threading.Event()

    def on(sample: Any) -> None:
        got.append(sample.message.to_body()["data"])
        done.set()

    sub = live.bus.subscribe(answer_topic, on)
    try:
        live.bus.publish("/peer/command", {"data": command})
        left = DEADLINE
        while not done.wait(1.0):  # a command lost before discovery: send it again
            left -= 1.0
            assert left > 0, f"the peer never answered {command!r}"
            live.bus.publish("/peer/command", {"data": command})
    finally:
        sub.close()
    return got[0]


def test_a_malformed_message_is_refused_with_a_clear_error_and_the_loop_runs_on(
    live: Live,
) -> None:
    # from the bus: a string where ROS wants an int32
    live.bus.publish("/bus/out/int32", {"data": "seven"})
    line = live.bridge.wait_for("dropped a bus message on /bus/out/int32")
    assert "for /out/int32: 'data' is a int32, got 'seven'" in line
    # from ROS 2: an image in an encoding the bridge does not convert
    live.round_trip("string", {"data": "before"})  # the peer hears commands by now
    live.bus.publish("/peer/command", {"data": "bad-image"})
    line = live.bridge.wait_for("dropped a message from /in/image (sensor_msgs/Image)")
    assert "image encoding 'yuv422_16' is not converted" in line
    # the bridge carries on with the next message, both ways
    assert live.round_trip("int32", {"data": 8}).to_body() == {"data": 8}
    assert live.bridge.p.poll() is None


def test_a_peer_that_cannot_match_is_named_once(live: Live) -> None:
    # the bridge's topics carry no QoS event handlers (they cost every executor wake); its
    # own check names a best-effort publisher that its reliable subscription cannot match
    assert _command(live, "incompatible", "/peer/result") == "incompatible declared"
    line = live.bridge.wait_for("cannot match the bridge")
    assert "the publisher of /anunnaki_test_peer on /in/string" in line
    assert "(incompatible QoS: Best effort publisher and reliable subscription)" in line
    assert line.endswith(
        ": make the publisher reliable, or give the bridge file's entry for /in/string "
        "'qos: sensor' (best effort)"
    )  # with the fix
    # the peer's reliable publisher of the same topic still goes through
    assert live.round_trip("string", {"data": "after"}).to_body() == {"data": "after"}
    assert sum("/anunnaki_test_peer on /in/string" in ln for ln in live.bridge.lines) == 1


def _rclpy_node(name: str, *endpoints: tuple[str, str, str]) -> str:
    """Code of an rclpy node ``name`` with reliable ``(kind, type, topic)`` endpoints.

    It prints ``declared`` once they exist and runs until its SIGTERM.
    """
    code = [
        "import signal, rclpy",
        "from importlib import import_module",
        "from rclpy.qos import QoSProfile",
        "rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)",
        f"node = rclpy.create_node({name!r})",
        "q = QoSProfile(depth=10)",
        "kept = []",
    ]
    for kind, type_name, topic in endpoints:
        package, cls = type_name.split("/")
        make = f"import_module({package + '.msg'!r}).{cls}"
        args = f"{make}, {topic!r}, q" if kind == "publisher" else f"{make}, {topic!r}, print, q"
        code.append(f"kept.append(node.create_{kind}({args}))")
    code += ["print('declared', flush=True)", "signal.pause()"]
    return "\n".join(code) + "\n"


def test_a_peer_of_another_type_is_named_once_with_the_fix(live: Live) -> None:
    # a second rclpy node, in a process of its own (one DDS participant takes one type per
    # topic name, and the peer's is String on /in/string), publishes std_msgs/Int32 on the
    # bridge's std_msgs/String topic /in/string, and std_msgs/Bool on /in/bool: same QoS
    # both, so only the first one's type keeps it from matching
    wrong = _rclpy_node(
        "anunnaki_type_probe",
        ("publisher", "std_msgs/Int32", "/in/string"),
        ("publisher", "std_msgs/Bool", "/in/bool"),
    )
    probe = live.ns.python("-c", wrong, name="type-probe", ready="declared")
    try:
        line = live.bridge.wait_for("/anunnaki_type_probe on")
        assert line.endswith(
            "the publisher of /anunnaki_type_probe on /in/string cannot match the bridge "
            "(its type is std_msgs/msg/Int32, the bridge's std_msgs/msg/String); no message "
            "will pass between them: give the publisher the type std_msgs/String, or the "
            "bridge file's entry for /in/string 'type: std_msgs/Int32'"
        ), line
        # a subscription of the wrong type on /out/int32, declared only now: the check that
        # names it is a later one than the check that named the probe's publisher, and it
        # looks at /in/string and /in/bool first (the bridge file's order); neither is named
        late = _rclpy_node(
            "anunnaki_type_probe_sub", ("subscription", "std_msgs/String", "/out/int32")
        )
        second = live.ns.python("-c", late, name="type-probe-sub", ready="declared")
        try:
            line = live.bridge.wait_for("/anunnaki_type_probe_sub on")
        finally:
            second.stop()
    finally:
        probe.stop()
    assert line.endswith(
        "the subscription of /anunnaki_type_probe_sub on /out/int32 cannot match the bridge "
        "(its type is std_msgs/msg/String, the bridge's std_msgs/msg/Int32); no message will "
        "pass between them: give the subscription the type std_msgs/Int32, or the bridge "
        "file's entry for /out/int32 'type: std_msgs/String'"
    ), line
    assert sum("/anunnaki_type_probe on" in ln for ln in live.bridge.lines) == 1
    assert not any("on /in/bool" in ln for ln in live.bridge.lines)


def test_the_bridges_topics_carry_no_qos_event_handlers(live: Live) -> None:
    probe = live.ns.python(
        "-c",
        "import rclpy\n"
        "from rclpy.event_handler import EventHandler\n"
        "from anunnaki.bus import open_bus\n"
        "from anunnaki.ros2._native import Ros2Bridge, import_rclpy\n"
        "from anunnaki.rosbridge import load_bridge\n"
        "rclpy.init()\n"
        "node = rclpy.create_node('anunnaki_event_probe')\n"
        "def handlers():\n"
        "    return sum(isinstance(w, EventHandler) for w in node.waitables)\n"
        "bare = handlers()  # the node's own (/rosout, /parameter_events)\n"
        f"spec = load_bridge({str(BRIDGE)!r})\n"
        "with open_bus('inproc') as bus, Ros2Bridge(spec, bus, node, import_rclpy()):\n"
        "    added = handlers() - bare\n"
        "    print(f'{len(spec.topics)} topics, {added} event handlers added', flush=True)\n"
        "node.destroy_node()\n"
        "rclpy.shutdown()\n",
        name="event-probe",
    )
    try:
        line = probe.wait_for("event handlers added")
        assert line.endswith("31 topics, 0 event handlers added"), line
    finally:
        probe.stop()


def test_sigterm_stops_the_bridge_cleanly(live: Live) -> None:
    live.bridge.p.terminate()
    assert live.bridge.p.wait(timeout=DEADLINE) == 0
    live.bridge.wait_for("ros2 bridge stopped: {")
    assert not any("Traceback" in line for line in live.bridge.lines), live.bridge.lines


def _in_ros2_env(code: str) -> str:
    need_ros2()
    done = subprocess.run(
        [str(ROS2_PYTHON), "-c", code], capture_output=True, text=True, check=False, cwd=HERE
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_the_ros2_table_is_jazzys_messages() -> None:
    # the table that checks ros2-bridge files with no ROS installed, against rclpy's classes
    out = _in_ros2_env(
        "import json\n"
        "from anunnaki.ros2._native import message_class, service_class\n"
        "from anunnaki.ros2._rclpy_convert import ros1_style_type as t\n"
        "from anunnaki.rosbridge import ROS2_MESSAGE_TYPES, ROS2_SERVICE_TYPES\n"
        "m = {n: [[f, t(v)] for f, v in message_class(n).get_fields_and_field_types().items()]\n"
        "     for n in ROS2_MESSAGE_TYPES}\n"
        "s = {n: [[[f, t(v)] for f, v in c.get_fields_and_field_types().items()]\n"
        "         for c in (service_class(n).Request, service_class(n).Response)]\n"
        "     for n in ROS2_SERVICE_TYPES}\n"
        "print(json.dumps([m, s]))\n"
    )
    messages, services = json.loads(out)
    time_types = {"builtin_interfaces/Time": "time", "builtin_interfaces/Duration": "duration"}
    for name, fields in ROS2_MESSAGE_TYPES.items():
        assert [(f, time_types.get(v, v)) for f, v in messages[name]] == list(fields), name
    for name, (request, response) in ROS2_SERVICE_TYPES.items():
        assert [tuple(f) for f in services[name][0]] == list(request), name
        assert [tuple(f) for f in services[name][1]] == list(response), name


def test_the_ros2_env_keeps_lark_1_and_the_core_imports_no_rclpy() -> None:
    # lark-parser 0.12 (ROS's) and lark 1.3 (ours) share lark/: the env holds lark 1.3 alone,
    # and both ROS's IDL parser and the goal grammar parse with it
    out = _in_ros2_env(
        "import sys, lark\n"
        "from anunnaki.goals import compile_expression\n"
        "compile_expression(\"camera.luma > 40 and mode.value == 'auto'\")\n"
        "import anunnaki.cli.main, anunnaki.launch, anunnaki.utu, anunnaki.ros2\n"
        "core_clean = 'rclpy' not in sys.modules\n"
        "from rosidl_parser.parser import parse_idl_string\n"
        "parse_idl_string('module m { module msg { struct S { int32 x; }; }; };')\n"
        "print(lark.__version__, core_clean)\n"
    )
    version, core_clean = out.split()
    assert version.startswith("1.") and core_clean == "True"
