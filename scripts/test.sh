#!/usr/bin/env bash
# Quickstart 2: set up (Python packages and Debian's Chromium) and run the whole test suite.
source "$(dirname "${BASH_SOURCE[0]}")/_env.sh"

if [ ! -x /usr/bin/chromium ]; then
  echo "==> installing Debian's chromium for the browser tests"
  if [ "$(id -u)" = 0 ]; then
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
  elif command -v sudo >/dev/null; then
    sudo apt-get update -qq && sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
  else
    echo "warning: cannot install chromium (not root, no sudo); browser tests will be skipped" >&2
  fi
fi
ensure_venv test

cd "$ROOT"
set +e
"$VENV/bin/python" -m pytest "$@"
status=$?
set -e
if [ "$status" = 5 ]; then
  echo "error: pytest collected no tests; that is a failure here, not a pass" >&2
  exit 1
fi
exit "$status"
