"""The ROS-neutral converters both bridges share."""

from __future__ import annotations

from anunnaki.rosbridge import ros_reply


def test_a_ros_response_becomes_the_bus_reply() -> None:
    assert ros_reply({}).ok is True  # Empty: no success field
    done = ros_reply({"success": True, "message": "ok"})
    assert done.ok and done.error is None and done.body == {"success": True, "message": "ok"}
    assert ros_reply({"success": False, "message": "busy"}).error == "busy"
    assert ros_reply({"success": False, "message": ""}).error == "refused"
