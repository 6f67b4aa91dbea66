#!/usr/bin/env bash
# Regenerate constraints.txt from the project virtualenv after a deliberate upgrade.
source "$(dirname "${BASH_SOURCE[0]}")/_env.sh"
{ echo "# Pinned versions the project is tested with (pip constraints; regenerate with scripts/freeze.sh)."
  "$VENV/bin/python" -m pip freeze --exclude-editable | grep -vi '^tableteach'; } > "$ROOT/constraints.txt"
echo "wrote $ROOT/constraints.txt"
