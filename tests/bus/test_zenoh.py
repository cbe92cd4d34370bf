"""What only the zenoh bus can show: real processes, foreign senders, the bytes on the wire."""

from __future__ import annotations

import json
import os
import signal
import struct
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest
from bus_helpers import Collector, free_port, run_python, wait_for

from anunnaki.bus import Bus, BusConfigError, BusConnectError, BusTimeout, TlsConfig, open_bus
from anunnaki.messages import Generic, Image, RunStop

zenoh = pytest.importorskip("zenoh")

PNG = b"\x89PNG\r\n\x1a\n" + bytes(32)


@pytest.fixture
def bus() -> Iterator[Bus]:
    with open_bus("zenoh", name="test") as b:
        yield b


@pytest.fixture
def raw(bus: Bus) -> Iterator[Any]:
    """A plain zenoh session connected to ``bus``: a foreign program on the network."""
    conf = zenoh.Config()
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", "[]")
    conf.insert_json5("connect/endpoints", json.dumps(list(bus.endpoints)))
    session = zenoh.open(conf)
    yield session
    session.close()


def test_defaults_are_loopback_and_no_multicast(bus: Bus) -> None:
    assert len(bus.endpoints) == 1
    assert bus.endpoints[0].startswith("tcp/127.0.0.1:")
    conf = bus.config.to_zenoh()  # type: ignore[attr-defined]
    assert conf["scouting"]["multicast"]["enabled"] is False
    assert conf["mode"] == "peer"


def test_foreign_garbage_is_dropped_and_counted(bus: Bus, raw: Any) -> None:
    got = Collector()
    bus.subscribe("/sensors/**", got)
    pub = raw.declare_publisher("anunnaki/sensors/imu")
    assert wait_for(lambda: pub.matching_status)
    time.sleep(0.02)  # zenoh's route settle after matching (see Publisher.wait_for_subscribers)
    pub.put(b"\xff\xfe garbage")
    pub.put(json.dumps({"v": 1, "type": "Generic"}).encode())
    pub.delete()
    ok = {"v": 1, "type": "Generic", "t": 0.5, "seq": 0, "sender": "foreign", "body": {"a": 1}}
    pub.put(json.dumps(ok).encode())
    assert got.wait(1)
    assert got.samples[0].sender == "foreign"
    assert got.messages == [Generic(data={"a": 1})]
    assert wait_for(lambda: bus.stats().malformed == {"/sensors/imu": 3})


def test_wire_format_as_a_foreign_program_sees_it(bus: Bus, raw: Any) -> None:
    samples: list[Any] = []
    arrived = threading.Condition()

    def on_sample(sample: Any) -> None:
        with arrived:
            samples.append(sample)
            arrived.notify_all()

    raw.declare_subscriber("anunnaki/**", zenoh.handlers.Callback(on_sample, indirect=False))
    pubs = [bus.publisher(t) for t in ("/rover/sensors", "/rover/camera/image", "/utu/run_stop")]
    assert all(p.wait_for_subscribers(5) for p in pubs)
    pubs[0].put({"mode": "autonomous", "buzzer": False})
    pubs[1].put(Image(encoding="png", width=4, height=2, data=PNG, frame_id="cam"))
    pubs[2].put(RunStop(reason="pedestrian", caller="/op"))
    with arrived:
        assert arrived.wait_for(lambda: len(samples) == 3, 5)
    by_key = {str(s.key_expr): s for s in samples}

    generic = by_key["anunnaki/rover/sensors"]
    text = generic.payload.to_bytes().decode()
    assert str(generic.encoding).startswith("application/json")
    assert " " not in text  # compact
    doc = json.loads(text)
    assert list(doc) == ["v", "type", "t", "seq", "sender", "body"]
    assert doc["v"] == 1 and doc["type"] == "Generic" and doc["sender"] == "test"
    assert doc["seq"] == 0 and isinstance(doc["t"], float)
    assert doc["body"] == {"mode": "autonomous", "buzzer": False}
    assert generic.priority == zenoh.Priority.DATA
    assert generic.congestion_control == zenoh.CongestionControl.BLOCK

    image = by_key["anunnaki/rover/camera/image"]
    data = image.payload.to_bytes()
    (n,) = struct.unpack(">I", data[:4])
    header = json.loads(data[4 : 4 + n])
    assert header["type"] == "Image"
    assert "data" not in header["body"]
    assert data[4 + n :] == PNG  # raw bytes, no base64
    assert image.priority == zenoh.Priority.DATA_LOW
    assert image.congestion_control == zenoh.CongestionControl.DROP

    stop = by_key["anunnaki/utu/run_stop"]
    assert stop.priority == zenoh.Priority.REAL_TIME
    assert stop.congestion_control == zenoh.CongestionControl.BLOCK
    assert stop.express is True


def test_client_without_router_fails_clearly() -> None:
    port = free_port()
    with pytest.raises(BusConnectError, match=f"tcp/127.0.0.1:{port}"):
        open_bus("zenoh", mode="client", connect=[f"tcp/127.0.0.1:{port}"])


def test_missing_tls_file_is_a_config_error(tmp_path: Any) -> None:
    tls = TlsConfig(root_ca=tmp_path / "nope.pem", mutual=False)
    with pytest.raises(BusConfigError, match=r"tls\.root_ca: file not found"):
        open_bus("zenoh", mode="client", connect=["tls/127.0.0.1:1"], tls=tls)


def test_import_does_not_load_zenoh_and_missing_extra_is_explained() -> None:
    code = textwrap.dedent(
        """
        import sys
        import anunnaki.bus as bus
        assert "zenoh" not in sys.modules, "import anunnaki.bus loaded zenoh"
        with bus.open_bus("inproc") as b:
            b.publish("/x", {})
        sys.modules["zenoh"] = None  # as if eclipse-zenoh were not installed
        try:
            bus.open_bus("zenoh")
        except ImportError as exc:
            print(type(exc).__name__, exc)
        """
    )
    result = run_python(code)
    assert result.returncode == 0, result.stderr
    assert "MissingExtraError" in result.stdout
    assert "pip install 'anunnaki[bus]'" in result.stdout


CHILD = """
import sys, threading
from anunnaki.bus import open_bus
from anunnaki.messages import ModeReply
bus = open_bus("zenoh", connect=[sys.argv[1]], name="child")
bus.service("/child/set_mode", lambda r: ModeReply(mode=r.mode, accepted=True))
bus.liveliness_token("/child")
print("ready", flush=True)
threading.Event().wait()  # hold everything until killed
"""


@pytest.mark.slow
def test_sigkilled_process_vanishes_from_liveliness(bus: Bus) -> None:
    events = Collector()
    bus.watch_liveliness(lambda node, alive: events((node, alive)))
    from anunnaki.messages import ModeReply, ModeRequest

    with subprocess.Popen(
        [sys.executable, "-c", CHILD, bus.endpoints[0]], stdout=subprocess.PIPE, text=True
    ) as child:
        try:
            assert child.stdout is not None
            assert child.stdout.readline().strip() == "ready"
            assert events.wait(1, timeout=10)
            assert events.samples[0] == ("/child", True)
            assert "/child" in bus.alive_nodes()
            reply = bus.request("/child/set_mode", ModeRequest(mode="manual"), timeout=5)
            assert reply == ModeReply(mode="manual", accepted=True)
            os.kill(child.pid, signal.SIGKILL)
            child.wait(10)
            assert events.wait(2, timeout=10)
            assert events.samples[1] == ("/child", False)
            assert "/child" not in bus.alive_nodes()
            with pytest.raises(BusTimeout):
                bus.request("/child/set_mode", ModeRequest(mode="manual"), timeout=0.3)
        finally:
            if child.poll() is None:
                child.kill()


@pytest.mark.slow
@pytest.mark.parametrize("stuck_callback", [False, True], ids=["idle", "stuck-callback"])
def test_exit_without_close_never_hangs(stuck_callback: bool) -> None:
    code = textwrap.dedent(
        f"""
        import threading
        from anunnaki.bus import open_bus
        bus = open_bus("zenoh")
        other = open_bus("zenoh", connect=list(bus.endpoints))
        got = threading.Event()
        def callback(sample):
            got.set()
            if {stuck_callback}:
                threading.Event().wait()  # a node stuck in its callback forever
        bus.subscribe("/x", callback)
        bus.service("/s", lambda r: None)
        bus.liveliness_token("/n")
        pub = other.publisher("/x")
        assert pub.wait_for_subscribers(5)
        pub.put({{}})
        assert got.wait(5)
        other.request("/s", {{}}, timeout=5)
        print("exiting without close", flush=True)
        """
    )
    t0 = time.monotonic()
    result = run_python(code, timeout=30)
    elapsed = time.monotonic() - t0
    assert result.returncode == 0, result.stderr
    assert "exiting without close" in result.stdout
    assert elapsed < 10, f"interpreter took {elapsed:.1f} s to exit"
