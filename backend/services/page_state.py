"""What the participant page shows beyond the protocol's state: the consent form's sections, a failed quiz's
wrong answers and the answers given, and the calibrated time estimate. Added to state.state_view's answer."""

from __future__ import annotations

from typing import Any

from ..db import repository as repo
from ..db.tables import ParticipantRow, StudyRow
from .page_settings import consent_sections


def extend_state(out: dict[str, Any], s: Any, participant: ParticipantRow, study: StudyRow) -> None:
    """Add the page's extras to a participant's state (in place)."""
    out["consent"]["sections"] = consent_sections(study)
    out["consent"]["allow_anonymous"] = bool(study.allow_anonymous)
    if out.get("quiz") is not None:
        out["quiz"].update(_last_quiz(s, participant, study))


def _last_quiz(s: Any, participant: ParticipantRow, study: StudyRow) -> dict[str, Any]:
    """The last failed attempt's answers (kept on the page) and, when the study shows them, which were wrong."""
    if not participant.quiz_failures:
        return {"answers": {}, "wrong": None}
    attempts = repo.participant_events(s, participant_id=participant.id, kinds=("quiz",))
    last = attempts[-1].payload if attempts else {}
    return {"answers": dict(last.get("answers") or {}),
            "wrong": list(last.get("wrong") or []) if study.quiz_feedback else None}
