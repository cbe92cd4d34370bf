#!/usr/bin/env bash
# Install Debian's Chromium for the dashboard's browser tests (Playwright drives it headless
# through executable_path; Playwright's own browser download is never used). Idempotent:
# nothing happens when the browser is already there.
#
#   scripts/setup-browser.sh             # as root: apt-get install chromium
#   ANUNNAKI_CHROMIUM=/opt/chrome/chrome scripts/setup-browser.sh   # use another binary
set -euo pipefail

CHROMIUM=${ANUNNAKI_CHROMIUM:-/usr/bin/chromium}

if [[ -x $CHROMIUM ]]; then
  exit 0
fi
if [[ $(id -u) -eq 0 ]] && command -v apt-get >/dev/null 2>&1; then
  echo "==> installing chromium (apt) for the dashboard's browser tests"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends chromium >/dev/null
  if [[ ! -x $CHROMIUM ]]; then
    echo "chromium was installed but $CHROMIUM is missing; set ANUNNAKI_CHROMIUM" >&2
    exit 1
  fi
  exit 0
fi
cat >&2 <<MSG
note: the dashboard's browser tests need Chromium at $CHROMIUM, and it is not installed.
  On Debian/Ubuntu, as root:   apt-get update && apt-get install -y chromium
  (or: sudo scripts/setup-browser.sh). Elsewhere, point ANUNNAKI_CHROMIUM at a Chromium
  or Chrome binary. Until then those tests are skipped (with ANUNNAKI_REQUIRE_BROWSER=1,
  as CI sets it, they fail); everything else works.
MSG
exit 0
