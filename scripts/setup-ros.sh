#!/usr/bin/env bash
# Install Debian's ROS 1 Python packages (rospy, rosmaster and the message packages) for the
# ROS 1 bridge's tests (issue #14). Idempotent: nothing happens when rospy and rosmaster are
# already there. Debian's rospy lives in /usr/lib/python3/dist-packages; it is never put on
# PYTHONPATH (Debian's PyYAML would shadow the venv's).
#
#   scripts/setup-ros.sh             # as root: apt-get install python3-rospy ...
set -euo pipefail

PACKAGES=(python3-rospy python3-rosmaster python3-std-msgs python3-sensor-msgs
  python3-geometry-msgs python3-std-srvs python3-rosbag)

if command -v rosmaster >/dev/null 2>&1 \
  && /usr/bin/python3 -c 'import rospy, sensor_msgs.msg, std_srvs.srv' >/dev/null 2>&1; then
  exit 0
fi
if [[ $(id -u) -eq 0 ]] && command -v apt-get >/dev/null 2>&1; then
  echo "==> installing ROS 1 (apt: ${PACKAGES[*]}) for the ROS 1 bridge's tests"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${PACKAGES[@]}" >/dev/null
  exit 0
fi
cat >&2 <<MSG
note: the ROS 1 bridge's tests need Debian's ROS 1 Python packages, and they are not installed.
  On Debian, as root:   apt-get update && apt-get install -y ${PACKAGES[*]}
  (or: sudo scripts/setup-ros.sh). Until then those tests are skipped; everything else works.
MSG
exit 0
