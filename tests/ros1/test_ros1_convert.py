"""Converters between ROS 1 messages and bus messages, on genpy-shaped doubles (no rospy)."""

from __future__ import annotations

import struct
import zlib
from typing import Any

import pytest

from anunnaki.messages import Image
from anunnaki.ros1 import (
    MESSAGE_TYPES,
    ConversionError,
    bus_image_to_compressed,
    compressed_to_image,
    fill_message,
    image_size,
    message_to_dict,
    raw_to_image,
    to_bus_fields,
    to_ros_fields,
)


class Time:
    """genpy.Time's shape: slots (with _slot_types, as genpy's), to_sec, from_sec."""

    __slots__ = ("nsecs", "secs")
    _slot_types = ("int32", "int32")

    def __init__(self, secs: int = 0, nsecs: int = 0) -> None:
        self.secs, self.nsecs = secs, nsecs

    def to_sec(self) -> float:
        return self.secs + self.nsecs / 1e9

    @classmethod
    def from_sec(cls, t: float) -> Time:
        return cls(int(t), round((t - int(t)) * 1e9))


def genpy_class(type_name: str) -> type:
    """A class shaped as genpy generates it, from the bridge's own type table."""
    fields = MESSAGE_TYPES[type_name]

    def init(self: Any) -> None:
        for name, type_ in fields:
            if type_ in MESSAGE_TYPES:
                value: Any = genpy_class(type_)()
            elif type_ == "time":
                value = Time()
            elif "[" in type_:
                value = b"" if type_ == "uint8[]" else []
            elif type_ == "string":
                value = ""
            elif type_ == "bool":
                value = False
            else:
                value = 0.0 if type_.startswith("float") else 0
            setattr(self, name, value)

    return type(
        type_name.replace("/", "_"),
        (),
        {
            "__slots__": [n for n, _ in fields],
            "_slot_types": [t for _, t in fields],
            "_type": type_name,
            "__init__": init,
        },
    )


def png_pixels(data: bytes) -> tuple[int, int, int, bytes]:
    """(width, height, colour type, unfiltered pixel bytes) of a PNG written with filter 0."""
    assert data.startswith(b"\x89PNG\r\n\x1a\n")
    width, height, depth, colour = struct.unpack(">IIBB", data[16:26])
    assert depth == 8
    idat = data.index(b"IDAT")
    (length,) = struct.unpack(">I", data[idat - 4 : idat])
    raw = zlib.decompress(data[idat + 4 : idat + 4 + length])
    channels = {0: 1, 2: 3, 6: 4}[colour]
    row = width * channels
    rows = [raw[y * (row + 1) : (y + 1) * (row + 1)] for y in range(height)]
    assert all(r[0] == 0 for r in rows)
    return width, height, colour, b"".join(r[1:] for r in rows)


def test_a_message_becomes_nested_plain_data_and_back() -> None:
    nav = genpy_class("sensor_msgs/NavSatFix")()
    nav.header.seq = 7
    nav.header.stamp = Time(12, 500_000_000)
    nav.latitude, nav.longitude = 59.33, 18.06
    nav.position_covariance = [0.0] * 9
    data = message_to_dict(nav)
    assert data["header"] == {"seq": 7, "stamp": 12.5, "frame_id": ""}
    assert data["status"] == {"status": 0, "service": 0}
    assert (data["latitude"], data["position_covariance"]) == (59.33, [0.0] * 9)
    back = fill_message(genpy_class("sensor_msgs/NavSatFix")(), data)
    assert message_to_dict(back) == data
    assert isinstance(back.header.stamp, Time) and back.header.stamp.to_sec() == 12.5


def test_field_mappings_pick_and_rename_both_ways() -> None:
    image_info = {"header": {"seq": 3, "stamp": 1.0, "frame_id": "cam"}, "width": 320}
    assert to_bus_fields(image_info, {"header.seq": "header.seq", "w": "width"}) == {
        "header": {"seq": 3},
        "w": 320,
    }
    assert to_bus_fields({"data": True}, {}) == {"data": True}
    twist = to_ros_fields(
        {"linear": 0.5, "angular": -0.1}, {"linear": "linear.x", "angular": "angular.z"}
    )
    assert twist == {"linear": {"x": 0.5}, "angular": {"z": -0.1}}
    msg = fill_message(genpy_class("geometry_msgs/Twist")(), twist)
    assert (msg.linear.x, msg.linear.y, msg.angular.z) == (0.5, 0.0, -0.1)
    with pytest.raises(ConversionError, match="the bus message has no field 'on'"):
        to_ros_fields({"off": True}, {"on": "data"})


@pytest.mark.parametrize(
    ("type_name", "data", "error"),
    [
        ("std_msgs/Bool", {"data": "yes"}, "'data' is a bool, got 'yes'"),
        ("std_msgs/Int32", {"data": 1.5}, "'data' is a int32, got 1.5"),
        ("std_msgs/Float64", {"value": 1.0}, "std_msgs/Float64 has no field 'value'"),
        ("geometry_msgs/Twist", {"linear": 1.0}, "'linear' is a geometry_msgs/Vector3"),
        ("sensor_msgs/BatteryState", {"cell_voltage": 3.7}, "'cell_voltage' is an array"),
    ],
)
def test_a_value_of_the_wrong_kind_is_refused(
    type_name: str, data: dict[str, Any], error: str
) -> None:
    with pytest.raises(ConversionError, match=error.replace("(", r"\(").replace(")", r"\)")):
        fill_message(genpy_class(type_name)(), data)


def raw_image(
    encoding: str, width: int, height: int, pixel: bytes, *, pad: int = 0
) -> dict[str, Any]:
    step = width * len(pixel) + pad
    row = pixel * width + b"\xee" * pad
    return {
        "header": {"seq": 42, "stamp": 0.0, "frame_id": "camera"},
        "height": height,
        "width": width,
        "encoding": encoding,
        "is_bigendian": 0,
        "step": step,
        "data": row * height,
    }


@pytest.mark.parametrize(
    ("encoding", "pixel", "colour", "rgb"),
    [
        ("rgb8", b"\x01\x02\x03", 2, b"\x01\x02\x03"),
        ("bgr8", b"\x01\x02\x03", 2, b"\x03\x02\x01"),
        ("rgba8", b"\x01\x02\x03\x04", 6, b"\x01\x02\x03\x04"),
        ("bgra8", b"\x01\x02\x03\x04", 6, b"\x03\x02\x01\x04"),
        ("mono8", b"\x09", 0, b"\x09"),
    ],
)
def test_a_raw_image_becomes_a_lossless_png_frame(
    encoding: str, pixel: bytes, colour: int, rgb: bytes
) -> None:
    frame = raw_to_image(raw_image(encoding, 5, 4, pixel, pad=3))
    assert (frame.encoding, frame.width, frame.height, frame.seq, frame.frame_id) == (
        "png",
        5,
        4,
        42,
        "camera",
    )
    assert frame.channels == len(pixel)
    assert png_pixels(frame.data) == (5, 4, colour, rgb * 20)
    assert image_size(frame.data) == ("png", 5, 4, len(pixel))


def test_a_bad_raw_image_is_refused() -> None:
    with pytest.raises(ConversionError, match="encoding '16UC1' is not converted"):
        raw_to_image(raw_image("16UC1", 2, 2, b"\x00\x00"))
    short = raw_image("rgb8", 4, 4, b"\x00\x00\x00")
    short["data"] = short["data"][:-1]
    with pytest.raises(ConversionError, match="does not hold 4 rows of 12"):
        raw_to_image(short)


def test_a_compressed_image_keeps_its_bytes_and_reads_its_size() -> None:
    cv2 = pytest.importorskip("cv2")
    np = pytest.importorskip("numpy")
    jpeg = cv2.imencode(".jpg", np.zeros((24, 40, 3), np.uint8))[1].tobytes()
    frame = compressed_to_image(
        {"header": {"seq": 5, "frame_id": "c"}, "format": "jpeg", "data": jpeg}
    )
    assert (frame.encoding, frame.width, frame.height, frame.channels, frame.seq) == (
        "jpeg",
        40,
        24,
        3,
        5,
    )
    assert frame.data == jpeg
    back = bus_image_to_compressed(frame, 1.5)
    assert back == {
        "header": {"seq": 5, "stamp": 1.5, "frame_id": "c"},
        "format": "jpeg",
        "data": jpeg,
    }
    with pytest.raises(ConversionError, match="neither JPEG nor PNG"):
        compressed_to_image({"data": b"GIF89a"})
    assert isinstance(frame, Image)
