#!/usr/bin/env python3
"""The rover of the paper's Fig. 13 as plain rospy nodes: run it with Debian's python3.

    ROS_MASTER_URI=http://127.0.0.1:11311 python3 examples/rover/ros1/rover_robot.py

It publishes what a real rover's drivers would (10 Hz unless --rate says otherwise):

* ``/rover/controller/mode`` (std_msgs/String), ``/rover/controller/buzzer_on``,
  ``/rover/controller/bumper``, ``/rover/controller/lights`` (std_msgs/Bool): the
  controller state, which the bridge merges into the bus topic ``/rover/controller/state``;
* ``/camera/image_raw`` (sensor_msgs/Image, 320×240 ``rgb8``): a synthetic scene with a
  box that moves, dimmed after ``--dim-at`` seconds (the oracle's adverse light);
* ``/ultrasonic/range`` (sensor_msgs/Range, ULTRASOUND): 3 m, or 0.5 m between
  ``--near-from`` and ``--near-until``;

and offers the services ``/rover/controller/set_mode`` (``anunnaki_msgs/SetString``:
``autonomous`` or ``manual``) and ``/rover/controller/stop`` (std_srvs/Trigger), and takes
``/rover/controller/buzzer`` (std_msgs/Bool) commands. It prints one line per command.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import threading

try:
    import rospy
except ImportError:  # a virtual environment: Debian's ROS is appended, never put first
    sys.path.append("/usr/lib/python3/dist-packages")
    import rospy

import genpy.dynamic
from sensor_msgs.msg import Image, Range
from std_msgs.msg import Bool, String
from std_srvs.srv import Trigger, TriggerResponse

# anunnaki_msgs/SetString.srv (a real robot builds it in a catkin package of that name).
SET_STRING = "string data\n---\nbool success\nstring message\n"


def set_string_service():
    """The anunnaki_msgs/SetString service class, generated from its text."""
    request_text, response_text = SET_STRING.split("---\n")
    name = "anunnaki_msgs/SetString"
    req = genpy.dynamic.generate_dynamic(name + "Request", request_text)[name + "Request"]
    resp = genpy.dynamic.generate_dynamic(name + "Response", response_text)[name + "Response"]
    digest = (request_text.strip() + response_text.strip()).encode()

    class SetString:
        _type = name
        _md5sum = hashlib.md5(digest).hexdigest()
        _request_class = req
        _response_class = resp

    return SetString


class Rover:
    """The rover's state, its publishers and its services."""

    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self.lock = threading.Lock()
        self.mode = "autonomous"
        self.buzzer = False
        self.stopped = False
        self.seq = 0
        self.pubs = {
            "mode": rospy.Publisher("/rover/controller/mode", String, queue_size=4),
            "buzzer_on": rospy.Publisher("/rover/controller/buzzer_on", Bool, queue_size=4),
            "bumper": rospy.Publisher("/rover/controller/bumper", Bool, queue_size=4),
            "lights": rospy.Publisher("/rover/controller/lights", Bool, queue_size=4),
            "image": rospy.Publisher("/camera/image_raw", Image, queue_size=2),
            "range": rospy.Publisher("/ultrasonic/range", Range, queue_size=4),
        }
        srv = set_string_service()
        self.services = [
            rospy.Service("/rover/controller/set_mode", srv, self.set_mode),
            rospy.Service("/rover/controller/stop", Trigger, self.stop),
        ]
        self.sub = rospy.Subscriber("/rover/controller/buzzer", Bool, self.on_buzzer)
        self.srv = srv

    def set_mode(self, req):
        ok = req.data in ("autonomous", "manual")
        if ok:
            with self.lock:
                self.mode = req.data
        print(f"set_mode {req.data}: {'accepted' if ok else 'refused'}", flush=True)
        message = req.data if ok else f"unknown mode {req.data!r}"
        return self.srv._response_class(success=ok, message=message)

    def stop(self, _req):
        with self.lock:
            self.stopped = True
        print("stop", flush=True)
        return TriggerResponse(success=True, message="stopped")

    def on_buzzer(self, msg) -> None:
        with self.lock:
            self.buzzer = bool(msg.data)
        print(f"buzzer {msg.data}", flush=True)

    def image(self, t: float) -> Image:
        w, h = 320, 240
        light = 60 if self.args.dim_at is not None and t >= self.args.dim_at else 200
        x0 = int(40 + (t * 40) % (w - 120))
        row = bytes([light // 2, light // 2, light]) * w
        box = bytes([light, light // 4, light // 4]) * 60
        rows = [
            row[: x0 * 3] + box + row[(x0 + 60) * 3 :] if 90 <= y < 150 else row for y in range(h)
        ]
        msg = Image(height=h, width=w, encoding="rgb8", is_bigendian=0, step=w * 3)
        msg.data = b"".join(rows)
        msg.header.seq = self.seq
        msg.header.stamp = rospy.Time.now()
        msg.header.frame_id = "camera"
        return msg

    def tick(self, t: float) -> None:
        a = self.args
        with self.lock:
            mode, buzzer = self.mode, self.buzzer
        self.pubs["mode"].publish(String(data=mode))
        self.pubs["buzzer_on"].publish(Bool(data=buzzer))
        self.pubs["bumper"].publish(Bool(data=False))
        self.pubs["lights"].publish(Bool(data=True))
        near = a.near_from is not None and a.near_from <= t < (a.near_until or float("inf"))
        r = Range(radiation_type=Range.ULTRASOUND, field_of_view=0.5, min_range=0.02, max_range=4.0)
        r.range = 0.5 if near else 3.0
        r.header.stamp = rospy.Time.now()
        self.pubs["range"].publish(r)
        if not a.no_camera:
            self.pubs["image"].publish(self.image(t))
        self.seq += 1


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rate", type=float, default=10.0, help="publications per second")
    p.add_argument("--dim-at", type=float, default=None, help="dim the camera after T s")
    p.add_argument("--near-from", type=float, default=None, help="something near from T s")
    p.add_argument("--near-until", type=float, default=None, help="... until T s")
    p.add_argument("--no-camera", action="store_true", help="publish no images")
    args = p.parse_args(rospy.myargv()[1:])
    rospy.init_node("rover", anonymous=False)
    rover = Rover(args)
    print("rover ready", flush=True)
    rate = rospy.Rate(args.rate)
    start = rospy.get_time()
    while not rospy.is_shutdown():
        rover.tick(rospy.get_time() - start)
        try:
            rate.sleep()
        except rospy.ROSInterruptException:
            break
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
