"""Comparing participant states read at different times: without what depends on the moment of reading."""

from __future__ import annotations

from typing import Any

MOMENT_KEYS = ("last_activity_at", "idle", "replayed")  # idleness, and whether the read replayed a request
MOMENT_PROGRESS_KEYS = ("seconds_left", "minutes_left")  # the time-left estimate counts on from the last action


def comparable(state: dict[str, Any], *, versions: bool = True) -> dict[str, Any]:
    """The state without the keys that change with the time it is read at (and, with versions=False, without its
    entity tag, which names the rows' version counters: an upgrade that adds those counters starts them anew)."""
    out = {k: v for k, v in state.items() if k not in MOMENT_KEYS and (versions or k != "etag")}
    if out.get("progress"):
        out["progress"] = {k: v for k, v in out["progress"].items() if k not in MOMENT_PROGRESS_KEYS}
    return out
