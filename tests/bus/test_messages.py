"""Message schemas, the registry and the wire codec."""

from __future__ import annotations

import json
import re
import struct
from typing import ClassVar

import pytest
from hypothesis import given
from hypothesis import strategies as st
from pydantic import ValidationError

from anunnaki.bus import (
    Envelope,
    MalformedMessage,
    decode_envelope,
    encode_envelope,
)
from anunnaki.messages import (
    MESSAGES,
    Clock,
    Generic,
    Image,
    Message,
    MessageError,
    ModeReply,
    ModeRequest,
    RunStop,
    ServiceReply,
)
from anunnaki.plugins import NAME_RULE

PNG = b"\x89PNG\r\n\x1a\n" + bytes(range(256))


def test_json_envelope_is_compact_and_as_documented() -> None:
    env = Envelope(Generic(data={"mode": "autonomous", "buzzer": False}), 12.5, 3, "rover")
    raw = encode_envelope(env)
    assert raw == (
        b'{"v":1,"type":"Generic","t":12.5,"seq":3,"sender":"rover",'
        b'"body":{"mode":"autonomous","buzzer":false}}'
    )
    assert decode_envelope(raw) == env


def test_image_travels_as_a_binary_frame_without_base64() -> None:
    img = Image(encoding="png", width=16, height=8, channels=4, data=PNG, frame_id="cam", seq=9)
    raw = encode_envelope(Envelope(img, 1.0, 0, "cam"))
    (n,) = struct.unpack(">I", raw[:4])
    header = json.loads(raw[4 : 4 + n])
    assert header["body"] == {
        "encoding": "png",
        "width": 16,
        "height": 8,
        "channels": 4,
        "frame_id": "cam",
        "seq": 9,
    }
    assert raw[4 + n :] == PNG
    assert len(raw) == 4 + n + len(PNG)  # no base64 bloat
    assert decode_envelope(raw).message == img


@pytest.mark.parametrize(
    "message",
    [
        Generic(),
        Clock(time=0.0),
        ModeRequest(mode="manual"),
        ModeReply(mode="manual", accepted=False, reason="moving"),
        ServiceReply(ok=False, error="boom"),
        RunStop(reason="r", caller="c"),
        Image(encoding="jpeg", width=1, height=1, channels=1, data=b"\xff\xd8\xff\xdb"),
    ],
    ids=lambda m: type(m).__name__,
)
def test_roundtrip(message: Message) -> None:
    raw = encode_envelope(Envelope(message, 0.25, 1, "s"))
    env = decode_envelope(raw)
    assert env.message == message
    assert env.type == type(message).__name__
    assert env.v == 1


json_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**53), 2**53)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=8),
    lambda children: (
        st.lists(children, max_size=3) | st.dictionaries(st.text(max_size=5), children, max_size=3)
    ),
    max_leaves=10,
)


@given(st.dictionaries(st.text(max_size=8), json_values, max_size=5))
def test_generic_roundtrips_any_json_object(data: dict) -> None:
    msg = Generic(data=data)
    assert decode_envelope(encode_envelope(Envelope(msg, 1.0, 0, "s"))).message == msg


@pytest.mark.parametrize(
    ("raw", "reason"),
    [
        (b"", "empty payload"),
        (b"\x00\x01", "too short"),
        (b"{nope", "not a JSON envelope"),
        (b"[]", "too short"),
        (b'"text"', "out of bounds"),
        (b"\xff\xfe\xfd\xfc", "out of bounds"),
        (b'{"v":1}', "bad envelope keys"),
        (b'{"v":1,"type":"Generic","t":1,"seq":0,"sender":"s","body":{},"x":1}', "unexpected"),
        (b'{"v":"1","type":"Generic","t":1,"seq":0,"sender":"s","body":{}}', "'v' must be"),
        (b'{"v":1,"type":3,"t":1,"seq":0,"sender":"s","body":{}}', "'type' must be"),
        (b'{"v":1,"type":"Generic","t":true,"seq":0,"sender":"s","body":{}}', "'t' must be"),
        (b'{"v":1,"type":"Generic","t":1,"seq":-1,"sender":"s","body":{}}', "'seq' must be"),
        (b'{"v":1,"type":"Generic","t":1,"seq":0,"sender":null,"body":{}}', "'sender' must"),
        (b'{"v":1,"type":"Generic","t":1,"seq":0,"sender":"s","body":[]}', "'body' must"),
        (b'{"v":1,"type":"Generic","t":Infinity,"seq":0,"sender":"s","body":{}}', "JSON"),
        (b'{"v":1,"type":"Nope","t":1,"seq":0,"sender":"s","body":{}}', "unknown message type"),
        (b'{"v":2,"type":"Clock","t":1,"seq":0,"sender":"s","body":{"time":1}}', "version 2"),
        (b'{"v":1,"type":"Clock","t":1,"seq":0,"sender":"s","body":{"time":-1}}', "time"),
        (b'{"v":1,"type":"Clock","t":1,"seq":0,"sender":"s","body":{"time":"1"}}', "time"),
        (b'{"v":1,"type":"Clock","t":1,"seq":0,"sender":"s","body":{}}', "time"),
        (b'{"v":1,"type":"Image","t":1,"seq":0,"sender":"s","body":{}}', "JSON envelope"),
        (
            b'{"v":1,"type":"ServiceReply","t":1,"seq":0,"sender":"s","body":{"ok":false}}',
            "must say what the error is",
        ),
    ],
)
def test_decoding_is_strict(raw: bytes, reason: str) -> None:
    with pytest.raises(MalformedMessage, match=reason):
        decode_envelope(raw)


def test_binary_frames_are_strict() -> None:
    header = json.dumps(
        {"v": 1, "type": "Image", "t": 1, "seq": 0, "sender": "s",
         "body": {"encoding": "png", "width": 1, "height": 1}}
    ).encode()  # fmt: skip
    frame = struct.pack(">I", len(header)) + header
    assert isinstance(decode_envelope(frame + PNG).message, Image)
    with pytest.raises(MalformedMessage, match="data"):
        decode_envelope(frame)  # no bytes
    with pytest.raises(MalformedMessage, match="png signature"):
        decode_envelope(frame + b"\xff\xd8\xff jpeg")
    generic = json.dumps(
        {"v": 1, "type": "Generic", "t": 1, "seq": 0, "sender": "s", "body": {}}
    ).encode()
    with pytest.raises(MalformedMessage, match="binary frame"):
        decode_envelope(struct.pack(">I", len(generic)) + generic + b"xx")


def test_schemas_validate_on_construction() -> None:
    with pytest.raises(ValidationError):
        Image(encoding="gif", width=1, height=1, data=PNG)  # type: ignore[arg-type]
    with pytest.raises(ValidationError):
        Image(encoding="png", width=0, height=1, data=PNG)
    with pytest.raises(ValidationError):
        Image(encoding="png", width=1, height=1, channels=2, data=PNG)  # type: ignore[arg-type]
    with pytest.raises(ValidationError):
        ServiceReply(ok=True, error="x")
    with pytest.raises(ValidationError):
        Clock(time=float("nan"))
    with pytest.raises(ValidationError):
        ModeRequest(mode="manual", extra=1)  # type: ignore[call-arg]
    with pytest.raises(ValidationError):
        RunStop(reason="", caller="c")
    msg = ModeRequest(mode="manual")
    with pytest.raises(ValidationError):
        msg.mode = "auto"  # frozen


def test_encoding_errors() -> None:
    with pytest.raises(MessageError, match=r"expected an anunnaki\.messages\.Message"):
        encode_envelope(Envelope({"a": 1}, 0, 0, "s"))  # type: ignore[arg-type]


def test_registry() -> None:
    assert MESSAGES.factory("Image") is Image
    assert set(MESSAGES.names()) >= {
        "Generic", "Image", "Clock", "ModeRequest", "ModeReply", "ServiceReply", "RunStop",
        "Assessment", "Detections", "MonitorBatch", "AnalysisState", "ExecuteStatus",
        "PlanStart", "CycleDone",
    }  # fmt: skip
    with pytest.raises(MessageError) as info:
        MESSAGES.factory("Imag")
    assert "'Imag'" in str(info.value)
    assert "Image" in str(info.value)  # lists the known names
    assert MESSAGES.register(Image) is Image  # idempotent

    class Image2(Message):
        TYPE_NAME: ClassVar[str | None] = "Image"
        x: int

    with pytest.raises(MessageError, match="already registered"):
        MESSAGES.register(Image2)
    with pytest.raises(MessageError, match="not a subclass"):
        MESSAGES.register(dict)


def test_a_type_name_follows_the_one_name_rule_and_the_error_says_it() -> None:
    class Dotted(Message):
        TYPE_NAME: ClassVar[str | None] = "my.Dotted"

    with pytest.raises(MessageError, match=re.escape(NAME_RULE)) as info:
        MESSAGES.register(Dotted)
    assert "message type name must be an identifier" in str(info.value)
    assert "'my.Dotted'" in str(info.value)
    assert "my.Dotted" not in MESSAGES.names()


def test_a_new_registered_type_travels_and_versions_are_checked() -> None:
    @MESSAGES.register
    class Detection(Message):
        VERSION: ClassVar[int] = 2
        TYPE_NAME: ClassVar[str | None] = "TestDetection"
        label: str
        score: float

    raw = encode_envelope(Envelope(Detection(label="person", score=0.9), 0, 0, "lec"))
    assert json.loads(raw)["v"] == 2
    assert json.loads(raw)["type"] == "TestDetection"
    assert decode_envelope(raw).message == Detection(label="person", score=0.9)
    old = raw.replace(b'"v":2', b'"v":1')
    with pytest.raises(MalformedMessage, match="version 1 is not the known version 2"):
        decode_envelope(old)


def test_body_of_reads_messages_and_mappings_alike() -> None:
    from anunnaki.messages import Generic, RunStop, body_of

    assert body_of(Generic(data={"mode": "manual"})) == {"mode": "manual"}
    assert body_of({"a": 1}) == {"a": 1}
    assert body_of(RunStop(reason="r", caller="c"))["caller"] == "c"
    assert body_of(None) == {} and body_of("text") == {}


@pytest.mark.parametrize("encoding", ["png", "jpeg"])
def test_image_from_array_round_trips(encoding: str) -> None:
    np = pytest.importorskip("numpy")
    from anunnaki.messages import Image

    rgb = np.zeros((24, 32, 3), dtype=np.uint8)
    rgb[:, :16] = (200, 30, 10)
    img = Image.from_array(rgb, encoding=encoding, quality=95, seq=7)  # type: ignore[arg-type]
    assert (img.width, img.height, img.channels, img.seq) == (32, 24, 3, 7)
    back = img.to_array()
    assert back.shape == (24, 32, 3) and back.dtype == np.uint8
    err = np.abs(back.astype(int) - rgb.astype(int))
    if encoding == "png":
        assert err.max() == 0
    else:  # lossy, and chroma is subsampled across the colour edge: compare away from it
        assert err[:, :12].max() <= 6 and err[:, 20:].max() <= 6
    grey = Image.from_array(np.full((8, 8), 77, dtype=np.uint8), encoding="png")
    assert grey.channels == 1 and grey.to_array().shape == (8, 8, 3)
    with pytest.raises(ValueError, match=r"\(H, W\) or \(H, W, 3\) uint8"):
        Image.from_array(np.zeros((4, 4, 3), dtype=np.float32))
