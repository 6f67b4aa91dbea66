#!/usr/bin/env bash
# Quickstart 1: set up and run the study server on SQLite with a demo study; prints the URLs to open.
source "$(dirname "${BASH_SOURCE[0]}")/_env.sh"
ensure_venv
mkdir -p "$ROOT/var"
exec "$VENV/bin/tableteach" serve --demo --database-url "sqlite:///$ROOT/var/tableteach.db" --data-dir "$ROOT/var/data" "$@"
