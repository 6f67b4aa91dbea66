"""Comparing participant states read at different times: without what depends on the moment of reading."""

from __future__ import annotations

from typing import Any

MOMENT_KEYS = ("last_activity_at", "idle", "replayed")  # idleness, and whether the read replayed a request
MOMENT_PROGRESS_KEYS = ("seconds_left", "minutes_left")  # the time-left estimate counts on from the last action


def comparable(state: dict[str, Any]) -> dict[str, Any]:
    """The state without the keys that change with the time it is read at."""
    out = {k: v for k, v in state.items() if k not in MOMENT_KEYS}
    if out.get("progress"):
        out["progress"] = {k: v for k, v in out["progress"].items() if k not in MOMENT_PROGRESS_KEYS}
    return out
