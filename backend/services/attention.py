"""Attention telemetry and presence from the participant page: the tab hidden, the window left, text pasted into
an answer (events, counted on the participant), and "I am still here" before an idle time-out."""

from __future__ import annotations

from typing import Any

from ..db import repository as repo
from ..errors import InvalidInput
from .context import Context, app_version, aware
from .state import UNDER_WAY, participant_and_study

SIGNALS = ("tab_hidden", "window_blur", "paste")
PRESENCE = "still_here"
MAX_SIGNALS = 1000  # per participant and kind: a page that sends more is not counted further


def record_signal(ctx: Context, token: str, *, kind: str, field: str | None = None) -> dict[str, int]:
    """Log one signal of the page (an event; `field` names the answer pasted into) and count it on the participant;
    the counts so far. A signal is not activity (it does not postpone an idle time-out); "still_here" is."""
    if kind not in (*SIGNALS, PRESENCE):
        raise InvalidInput(f"kind is {kind!r}; expected one of {', '.join((*SIGNALS, PRESENCE))}")
    with ctx.db.write() as s:
        participant, _study = participant_and_study(s, token)
        counts = dict(participant.attention_signals or {})
        if participant.stage not in UNDER_WAY or (kind != PRESENCE and counts.get(kind, 0) >= MAX_SIGNALS):
            return counts
        idle_since = aware(participant.last_activity_at)
        payload: dict[str, Any] = {"stage": participant.stage}
        if field:
            payload["field"] = field
        repo.append_event(s, participant=participant, kind=kind, payload=payload, app_version=app_version(),
                          task_index=participant.task_index if participant.stage == "task" else None)
        if kind != PRESENCE:
            counts[kind] = counts.get(kind, 0) + 1
            participant.attention_signals = counts
            if idle_since is not None:
                participant.last_activity_at = idle_since  # looking away is not taking part
        repo.commit(s)
        return counts
