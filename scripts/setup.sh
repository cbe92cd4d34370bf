#!/usr/bin/env bash
# Set up a fresh machine for Anunnaki: a virtual environment in .venv with the package
# installed in editable mode and the extras named in $ANUNNAKI_EXTRAS (default: what the
# demo and the test suite need). Idempotent: re-running after no change to pyproject.toml
# or constraints.txt installs nothing.
#
#   scripts/setup.sh            # demo + tests
#   ANUNNAKI_EXTRAS=all scripts/setup.sh
set -euo pipefail
cd "$(dirname "$0")/.."

# Chromium for the dashboard's browser tests (apt, as root; otherwise it says what to do).
scripts/setup-browser.sh

# Debian's ROS 1 Python packages for the ROS 1 bridge's tests (apt, as root; issue #14).
scripts/setup-ros.sh

PYTHON=${PYTHON:-python3}
EXTRAS=${ANUNNAKI_EXTRAS:-dev,bus,vision,dashboard,plot,enlil,ros}
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

stamp="$VENV/.anunnaki-setup"
want="$EXTRAS $(cat pyproject.toml constraints.txt | sha256sum | cut -c1-16)"
if [[ -f $stamp && "$(cat "$stamp")" == "$want" ]]; then
  exit 0
fi
echo "==> installing anunnaki[$EXTRAS] (torch, when asked for, is pinned by constraints.txt)"
# constraints.txt pins torch to the CPU build on disk; an unpinned torch would pull a 5 GB CUDA build.
NO_ALBUMENTATIONS_UPDATE=1 "$VENV/bin/python" -m pip install --quiet \
  -c constraints.txt -e ".[$EXTRAS]"
echo "$want" > "$stamp"
