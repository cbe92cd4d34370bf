#!/usr/bin/env bash
# Build the ROS 2 environment (issue #31): a SEPARATE virtual environment, .venv-ros2, with
# ROS 2 Jazzy's rclpy, Fast DDS and the message packages from PyPI (no root, about 35 s), and
# anunnaki installed in it too (editable, [ros] plus OpenCV for raw images), so the native
# bridge (python -m anunnaki.ros2) and the example's rclpy nodes run there; and, for the
# tests, the MCAP reference reader (mcap) and pyzeros (rmw_zenoh's wire format).
#
#   scripts/setup-ros2.sh            # builds or updates .venv-ros2 (idempotent)
#   ANUNNAKI_ROS2_VENV=DIR scripts/setup-ros2.sh
#
# Why a separate environment: the ROS wheels pull in lark-parser 0.12, which installs into
# the same lark/ folder as anunnaki's lark 1.3. Here lark-parser is removed once the ROS
# wheels are in and lark 1.3 is installed alone; the script then proves that both parsers
# work with it (anunnaki's goal grammar and ROS's IDL parser, rosidl_parser). The project's
# .venv never receives a ROS wheel.
#
# Every ROS 2 process must run inside a loopback-only network namespace, so that no DDS
# packet leaves the machine:  unshare -rn sh -c 'ip link set lo up && exec CMD'
# (the tests and `make test` do so; docs/ros.md, "ROS 2").
set -euo pipefail
cd "$(dirname "$0")/.."

VENV=${ANUNNAKI_ROS2_VENV:-.venv-ros2}
PYTHON=${PYTHON:-python3}
# Pinned: ROS 2 Jazzy as published on PyPI (ros-jazzy-*), the versions the tests ran with.
ROS_PACKAGES=(
  "ros-jazzy-rclpy[fastrtps]==7.1.6"
  "ros-jazzy-std-msgs==5.3.6"
  "ros-jazzy-sensor-msgs==5.3.6"
  "ros-jazzy-std-srvs==5.3.6"
  "ros-jazzy-geometry-msgs==5.3.6"
  "ros-jazzy-diagnostic-msgs==5.3.6"
  "ros-jazzy-lifecycle-msgs==2.0.3"
)
LARK="lark==1.3.1"
OPENCV="opencv-python-headless==5.1.0.95"
# the MCAP reference reader: the tests check that an exported rosbag2 is valid MCAP
MCAP="mcap==1.6.0"
# pyzeros: an independent implementation of rmw_zenoh's keys and attachments (the tests compare)
PYZEROS="pyzeros==0.1.0"

if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
  # the ros-jazzy-* wheels on PyPI are built for one CPython; 3.11 is the one tested here
  echo "note: the ROS 2 wheels are tested with Python 3.11; $PYTHON is $("$PYTHON" --version 2>&1)" >&2
fi

stamp="$VENV/.anunnaki-ros2-setup"
# the checkout's path is in the stamp too: the environment holds it (anunnaki is installed
# editable), so an environment copied from another checkout is installed again here rather
# than left importing the other checkout's code
hash=$( (cat "$0" pyproject.toml; pwd -P) | sha256sum | cut -c1-16)
if [[ -f $stamp && $(cat "$stamp") == "$hash" && -x $VENV/bin/python ]]; then
  exit 0
fi
if [[ ! -x $VENV/bin/python ]]; then
  echo "==> creating $VENV (ROS 2 Jazzy from PyPI, no root)"
  "$PYTHON" -m venv "$VENV"
fi
PIP=("$VENV/bin/python" -m pip --disable-pip-version-check)
"${PIP[@]}" install --quiet --no-compile "${ROS_PACKAGES[@]}"
# lark-parser 0.12 (ROS's IDL parser's) and lark 1.3 (anunnaki's) share the lark/ folder:
# remove the old one whole, then install the new one alone (no file of 0.12 is left behind).
if "${PIP[@]}" show lark-parser >/dev/null 2>&1; then
  "${PIP[@]}" uninstall --quiet -y lark-parser
fi
"${PIP[@]}" install --quiet --no-compile --force-reinstall --no-deps "$LARK"
"${PIP[@]}" install --quiet --no-compile -e ".[ros]" "$OPENCV" "$MCAP" "$PYZEROS" "$LARK"
# The proof that the order cannot break either side: lark is 1.3, anunnaki's grammar and
# ROS's IDL parser both parse with it, and rclpy loads its middleware and a Jazzy message.
"$VENV/bin/python" - <<'PY'
import lark
assert lark.__version__.startswith("1."), f"lark {lark.__version__} in the ROS 2 env"
from anunnaki.goals import compile_expression
compile_expression("a.x > 1 and b.y == 'z'")
from rosidl_parser.parser import parse_idl_string
parse_idl_string("module m { module msg { struct S { int32 x; }; }; };")
import rclpy
from sensor_msgs.msg import Range
assert "variance" in Range.get_fields_and_field_types(), "not Jazzy's sensor_msgs/Range"
import anunnaki.ros2._native  # noqa: F401
PY
# pyzeros's CDR code (cydr) compiles itself with Cython on first use, into $CYDR_CACHE_DIR:
# once here, inside the environment, not in a test run or the working folder
CYDR_CACHE_DIR="$VENV/.cydr_cache" "$VENV/bin/python" -c '
from pyzeros.builtin_msgs import Attachment
Attachment(sequence_number=1, source_timestamp=2).serialize()'
echo "$hash" > "$stamp"
echo "==> $VENV ready: ROS 2 Jazzy (rclpy, Fast DDS) and anunnaki, lark $("$VENV/bin/python" -c 'import lark; print(lark.__version__)')"
