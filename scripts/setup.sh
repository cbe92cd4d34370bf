#!/usr/bin/env bash
# Set up a fresh machine for Anunnaki: a virtual environment in .venv with the package
# installed in editable mode and the extras of a profile.
#
#   scripts/setup.sh demo   # make demo, make demo-uav: what the demos import, nothing as root
#   scripts/setup.sh test   # make test (the default): every extra the suite tests, and, as
#                           # root, Debian's Chromium and ROS 1 for the browser and ROS 1 tests;
#                           # ROS 2 Jazzy in its own .venv-ros2 (no root) for the ROS 2 tests
#   ANUNNAKI_EXTRAS=all scripts/setup.sh        # these extras instead of the profile's
#
# Idempotent: nothing is installed when the extras asked for are already in .venv and
# pyproject.toml and constraints.txt have not changed since (the stamp .venv/.anunnaki-setup
# lists the extras installed); `make test` after `make demo` adds only what the tests need.
set -euo pipefail
cd "$(dirname "$0")/.."

# The profiles (tests/cli/test_make_demo.py checks the demo's against what it imports, and
# the README's wording against both).
DEMO_EXTRAS=vision,dashboard,plot,mail,oracle
TEST_EXTRAS=dev,bus,vision,dashboard,plot,enlil,ros,mail

PROFILE=${1:-test}
case $PROFILE in
  demo) EXTRAS=${ANUNNAKI_EXTRAS:-$DEMO_EXTRAS} ;;
  test)
    EXTRAS=${ANUNNAKI_EXTRAS:-$TEST_EXTRAS}
    # Chromium for the dashboard's browser tests (apt, as root; otherwise it says what to do).
    scripts/setup-browser.sh
    # Debian's ROS 1 Python packages for the ROS 1 bridge's tests (apt, as root; issue #14).
    scripts/setup-ros.sh
    # ROS 2 Jazzy from PyPI in a separate .venv-ros2 for the live ROS 2 tests (no root, about
    # 35 s the first time, nothing after; issue #31).
    scripts/setup-ros2.sh
    ;;
  *)
    echo "usage: scripts/setup.sh [demo|test] (got '$PROFILE')" >&2
    exit 2
    ;;
esac

PYTHON=${PYTHON:-python3}
VENV=.venv

if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))'; then
  echo "Anunnaki needs Python >= 3.11; $PYTHON is $("$PYTHON" --version 2>&1)" >&2
  exit 1
fi
if [[ ! -x $VENV/bin/python ]]; then
  echo "==> creating $VENV"
  "$PYTHON" -m venv "$VENV"
  "$VENV/bin/python" -m pip install --quiet --upgrade pip
fi

# The stamp: the hash of pyproject.toml and constraints.txt, then the extras installed.
stamp="$VENV/.anunnaki-setup"
hash=$(cat pyproject.toml constraints.txt | sha256sum | cut -c1-16)
have=""
if [[ -f $stamp ]]; then
  read -r stamped_hash stamped_extras < "$stamp" || true
  if [[ ${stamped_hash:-} == "$hash" ]]; then
    have=${stamped_extras:-}
  fi
fi
# Every extra asked for already there: nothing to do.
missing=$(comm -23 <(tr , '\n' <<< "$EXTRAS" | sort -u) <(tr , '\n' <<< "$have" | sort -u))
if [[ -f $stamp && -z $missing ]]; then
  exit 0
fi
# Install what is asked for with what is there (pip keeps them consistent).
want=$(tr , '\n' <<< "$EXTRAS,$have" | sed '/^$/d' | sort -u | paste -sd, -)
echo "==> installing anunnaki[$want] (torch, when asked for, is pinned by constraints.txt)"
# constraints.txt pins torch to the CPU build on disk; an unpinned torch would pull a 5 GB CUDA build.
# --no-compile: Python compiles a module when it is first imported; compiling all of torch,
# scipy and the rest at install doubled the demo profile's CPU time (73 s against 35 s) and
# tripled its time (374 s against 117 s; one measurement each at load 6-10, issue #34).
NO_ALBUMENTATIONS_UPDATE=1 "$VENV/bin/python" -m pip install --quiet --no-compile \
  -c constraints.txt -e ".[$want]"
echo "$hash $want" > "$stamp"
