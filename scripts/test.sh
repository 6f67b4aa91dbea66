#!/usr/bin/env bash
# Quickstart 2: set up (Python packages, Debian's Chromium, PostgreSQL and nginx) and run the whole test suite.
source "$(dirname "${BASH_SOURCE[0]}")/_env.sh"

# Debian packages the tests use: Chromium for the browser tests, PostgreSQL for the database tests (its client
# programs pg_dump/pg_restore for the backup tests), nginx and openssl for the reverse-proxy and HTTPS tests.
missing=()
[ -x /usr/bin/chromium ] || missing+=(chromium)
compgen -G "/usr/lib/postgresql/*/bin/initdb" >/dev/null || missing+=(postgresql)
[ -x /usr/sbin/nginx ] || missing+=(nginx-light)
command -v openssl >/dev/null || missing+=(openssl)  # the HTTPS proxy test makes a self-signed certificate
if [ ${#missing[@]} -gt 0 ]; then
  echo "==> installing Debian packages: ${missing[*]}"
  sudo=""
  [ "$(id -u)" = 0 ] || sudo="sudo"
  if [ -n "$sudo" ] && ! command -v sudo >/dev/null; then
    echo "warning: cannot install ${missing[*]} (not root, no sudo); their tests will be skipped" >&2
  else
    $sudo apt-get update -qq
    $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
  fi
fi
ensure_venv test
# axe-core (package.json, pinned by its lock file) for the accessibility checks of the browser tests.
if command -v npm >/dev/null && [ ! -f "$ROOT/node_modules/axe-core/axe.min.js" ]; then
  echo "==> npm ci (axe-core for the browser tests)"
  (cd "$ROOT" && npm ci --no-audit --no-fund --silent) || echo "warning: npm ci failed; the axe-core checks will be skipped" >&2
fi

cd "$ROOT"
set +e
echo "==> ruff check (lint; settings in pyproject.toml)"
"$VENV/bin/ruff" check .
lint=$?
echo "==> mypy (static types of backend/; settings in pyproject.toml)"
"$VENV/bin/mypy"
types=$?
# Worker processes (pytest-xdist): most tests wait on servers, browsers and robots rather than compute, so three
# workers on two cores take about half the time of one. TABLETEACH_TEST_WORKERS=0 runs in this process; a later
# -n on the command line wins.
"$VENV/bin/python" -m pytest -n "${TABLETEACH_TEST_WORKERS:-3}" --durations=15 "$@"
status=$?
set -e
if [ "$status" = 5 ]; then
  echo "error: pytest collected no tests; that is a failure here, not a pass" >&2
  exit 1
fi
if [ "$lint" != 0 ] && [ "$status" = 0 ]; then
  echo "error: the tests passed but ruff found problems (above)" >&2
  exit 1
fi
if [ "$types" != 0 ] && [ "$status" = 0 ]; then
  echo "error: the tests passed but mypy found type errors (above)" >&2
  exit 1
fi
exit "$status"
