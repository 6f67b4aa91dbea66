"""What the participant page shows beyond the protocol's state: the consent form's sections, a failed quiz's
wrong answers and the answers given, and the calibrated time estimate. Added to state.state_view's answer."""

from __future__ import annotations

import math
from typing import Any
from urllib.parse import urlsplit

from ..db import repository as repo
from ..db.tables import ParticipantRow, StudyRow, utcnow
from . import time_estimate
from .context import aware
from .page_settings import consent_sections


def extend_state(out: dict[str, Any], s: Any, participant: ParticipantRow, study: StudyRow) -> None:
    """Add the page's extras to a participant's state (in place)."""
    out["consent"]["sections"] = consent_sections(study)
    out["consent"]["allow_anonymous"] = bool(study.allow_anonymous)
    if out.get("quiz") is not None:
        out["quiz"].update(_last_quiz(s, participant, study))
    _calibrated_progress(out, s, participant, study)
    out["idle"] = _idle(participant, study)
    back = _platform(study.completion_url) if participant.stage == "withdrawn" else None
    if out.get("completion") is not None and back:
        out["completion"]["return_url"] = back  # where a withdrawn participant goes back to
    out["consent"]["anonymous"] = participant.prolific_pid is None


def _idle(participant: ParticipantRow, study: StudyRow) -> dict[str, Any] | None:
    """The study's idle time-out and how long the participant has been idle (the page warns a minute before)."""
    if not study.timeout_minutes or participant.stage not in UNDER_WAY:
        return None
    last = aware(participant.last_activity_at) or utcnow()
    return {"timeout_seconds": study.timeout_minutes * 60, "idle_seconds": round((utcnow() - last).total_seconds(), 1)}


def _platform(completion_url: str | None) -> str | None:
    """The study platform's address (the completion redirect's origin): where a withdrawn participant goes back to."""
    if not completion_url:
        return None
    parts = urlsplit(completion_url)
    return f"{parts.scheme}://{parts.netloc}/" if parts.scheme in ("http", "https") and parts.netloc else None


def _last_quiz(s: Any, participant: ParticipantRow, study: StudyRow) -> dict[str, Any]:
    """The last failed attempt's answers (kept on the page) and, when the study shows them, which were wrong."""
    if not participant.quiz_failures:
        return {"answers": {}, "wrong": None}
    attempts = repo.participant_events(s, participant_id=participant.id, kinds=("quiz",))
    last = attempts[-1].payload if attempts else {}
    return {"answers": dict(last.get("answers") or {}),
            "wrong": list(last.get("wrong") or []) if study.quiz_feedback else None}


UNDER_WAY = ("consent", "instructions", "quiz", "task", "questionnaire")
TIMED_EVENTS = ("consent", "instructions_read", "quiz", "demonstration", "assessment", "execution_started",
                "execution_finished", "replay_watched")


def _calibrated_progress(out: dict[str, Any], s: Any, participant: ParticipantRow, study: StudyRow) -> None:
    """Replace the progress's time left by the calibrated estimate (time_estimate.py): seconds_left, minutes_left."""
    from .guidance import step_counts
    from .state import session_config, task_sequence  # state imports this module

    progress = out.get("progress")
    if progress is None:
        return
    if participant.stage not in UNDER_WAY:
        progress["seconds_left"] = 0
        return
    events = repo.event_times(s, participant_id=participant.id, kinds=TIMED_EVENTS)
    joined = aware(participant.created_at) or utcnow()
    line = time_estimate.timeline(events, joined)
    demos = line.demo_objects
    plan = time_estimate.screens(
        [step_counts(session_config(study, participant, i)) for i in task_sequence(study, participant)],
        quiz=bool(study.quiz), questionnaire=bool(study.questionnaire),
        demo_objects=sum(demos) / len(demos) if demos else time_estimate.DEMO_OBJECTS)
    before = 3 if study.quiz else 2
    stage = participant.stage
    done = {"consent": 0, "instructions": 1, "quiz": 2}.get(stage)
    if done is None:
        done = before + progress["done"]  # task steps done (the questionnaire counts after them)
    placed = len((out.get("demonstration") or {}).get("placed") or [])
    left = time_estimate.seconds_left(plan, done, line, (utcnow() - joined).total_seconds(),
                                      speed=float(study.robot_speed or 1.0), placed_here=placed)
    progress["seconds_left"] = round(left)
    progress["minutes_left"] = max(1, math.ceil(left / 60))
